"""Shared fixtures: a small cached synthetic set, isolated results folders."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def synthetic_cache(tmp_path_factory) -> Path:
    """One cache folder for the whole session, so the small set is generated once."""
    return tmp_path_factory.mktemp("synthetic-cache")


@pytest.fixture(scope="session")
def small_dataset(synthetic_cache):
    from brdfbench.data.synthetic import synthetic_dataset

    return synthetic_dataset("small", seed=0, cache_dir=str(synthetic_cache))


@pytest.fixture(autouse=True)
def _isolated_cache(monkeypatch, synthetic_cache):
    monkeypatch.setenv("BRDFBENCH_CACHE", str(synthetic_cache))
    yield


def pytest_report_header(config):
    return f"brdfbench tests; torch threads={os.environ.get('OMP_NUM_THREADS', 'default')}"
