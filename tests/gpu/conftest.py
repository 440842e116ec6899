"""GPU tests: every test here is marked `gpu` and skips cleanly where torch sees no CUDA
device, so CI (CPU only) stays green. `.ci/gpu` runs them on a GPU host."""

from __future__ import annotations

import pytest
import torch


def pytest_collection_modifyitems(config, items):
    has_gpu = torch.cuda.is_available()
    for item in items:
        if "tests/gpu/" in str(item.fspath).replace("\\", "/"):
            item.add_marker(pytest.mark.gpu)
            if not has_gpu:
                item.add_marker(pytest.mark.skip(reason="no CUDA device: GPU tests run where torch sees one (.ci/gpu)"))


@pytest.fixture
def gpu() -> torch.device:
    """The first CUDA device (the tests here are skipped without one)."""
    return torch.device("cuda", 0)
