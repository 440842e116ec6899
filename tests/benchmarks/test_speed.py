"""Speed benchmarks (pytest-benchmark). Disabled in the default run; measure with:

    python -m pytest tests/benchmarks --benchmark-enable

Compare against a saved baseline with --benchmark-compare and gate regressions with
--benchmark-compare-fail=mean:20%.
"""

import pytest
import torch

from brdfbench import coords, merl
from brdfbench.harness import directions
from brdfbench.testing.kit import reference_material, training_materials

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


def _fitted(name, **params):
    from brdfbench.plugins import registry

    model = registry.get("representations", name).create(**params)
    if model.needs_training:
        model.train(training_materials())
    return model.fit(reference_material())


@pytest.mark.parametrize("name", ["merl", "lambert", "cook_torrance", "ggx", "blinn_phong", "pca", "nbrdf", "naive_mlp"])
def test_representation_eval(benchmark, pairs, name):
    benchmark(_fitted(name).eval, *pairs)


@pytest.mark.parametrize("name", ["cook_torrance", "ggx", "blinn_phong"])
def test_analytic_fit(benchmark, name):
    from brdfbench.plugins import registry

    spec = registry.get("representations", name)
    target = reference_material()
    benchmark.pedantic(lambda: spec.create().fit(target), rounds=3, iterations=1, warmup_rounds=1)


def test_pca_projection(benchmark):
    model = _fitted("pca")
    target = reference_material()
    benchmark.pedantic(model.fit, args=(target,), rounds=3, iterations=1)


def test_grid_directions_uncached(benchmark):
    benchmark.pedantic(merl.grid_directions.__wrapped__, rounds=3, iterations=1)
