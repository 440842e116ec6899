"""Shared fixtures of the pytest-benchmark files."""

import pytest


@pytest.fixture
def enabled(request):
    """The benchmark fixture, or a skip where benchmarks are disabled (before it is made)."""
    config = request.config
    if config.getoption("benchmark_disable") and not config.getoption("benchmark_enable"):
        pytest.skip("a timing: run with --benchmark-enable")
    return request.getfixturevalue("benchmark")
