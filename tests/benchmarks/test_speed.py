"""Speed benchmarks (pytest-benchmark). Disabled in the default run; measure with:

    python -m pytest tests/benchmarks --benchmark-enable

Compare against a saved baseline with --benchmark-compare and gate regressions with
--benchmark-compare-fail=mean:20%.
"""

import pytest
import torch

from brdfbench import coords, merl
from brdfbench.harness import directions
from brdfbench.testing.kit import reference_material

N = 2**16


@pytest.fixture(scope="module")
def pairs():
    return tuple(t.float() for t in directions.random_pairs(N, 123, torch.float64))


def test_half_diff_fp32(benchmark, pairs):
    benchmark(coords.to_half_diff, *pairs)


@pytest.mark.parametrize("mode", ["nearest", "trilinear"])
def test_merl_lookup(benchmark, pairs, mode):
    table = reference_material().table
    benchmark(table.lookup, *pairs, mode)


@pytest.mark.parametrize("name", ["merl", "lambert"])
def test_representation_eval(benchmark, pairs, name):
    from brdfbench import registry

    model = registry.get("representations", name).create().fit(reference_material())
    benchmark(model.eval, *pairs)


def test_grid_directions_uncached(benchmark):
    benchmark.pedantic(merl.grid_directions.__wrapped__, rounds=3, iterations=1)
