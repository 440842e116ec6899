"""NBRDF fitting speed: the batched fitter against one material at a time, same network and
loss, and the hand-written CPU engine against the autograd one it replaced.

    python -m pytest tests/benchmarks/test_nbrdf_speed.py --benchmark-enable            # CI size
    python -m pytest tests/benchmarks/test_nbrdf_speed.py --benchmark-enable -m slow    # the full comparison

Each benchmark records `per_material_s` (the call's time over its material count) and the
final training losses in its extra_info. The CI-size cases use a short recipe on four small
synthetic materials; the slow ones fit 16 published MERL networks' tables (or synthetic
materials where the release is absent) with the default recipe, and the published reference
recipe on alum-bronze for the loss it reaches. The engine comparison alternates the two
engines over several rounds in one call, so that a change of machine load hits both; it
records each engine's per-material seconds (median over rounds), their ratio and the load
average before and after. Speed is reported, never asserted.
"""

from __future__ import annotations

import os
import statistics
import time

import pytest
import torch

from brdfbench.data.nbrdf_release import find_release_dir, nbrdf_release_dataset
from brdfbench.data.synthetic import synthetic_dataset
from brdfbench.nbrdf import network as nw
from brdfbench_representations.nbrdf import NBRDF
from brdfbench_representations.nbrdf_fit import REFERENCE_RECIPE, Recipe, draw_samples, fit_batched

SHORT = Recipe(epochs=3, n_samples=100_000, patience=None)
FULL_MATERIALS = 16


def _inits(n, hidden=(21, 21)):
    return [nw.glorot_init(hidden, torch.Generator().manual_seed(i)) for i in range(n)]


def _fit(tables, recipe, batched, samples):
    inits = _inits(len(tables))
    if batched:
        return fit_batched(tables, inits, recipe=recipe, samples=samples)
    return [fit_batched([t], [w], recipe=recipe, samples=samples)[0] for t, w in zip(tables, inits)]


def _record(benchmark, outcomes, n):
    losses = [o.loss for o in outcomes]
    benchmark.extra_info.update(
        materials=n, median_loss=statistics.median(losses), max_loss=max(losses),
        epochs=[o.epochs for o in outcomes],
    )
    if benchmark.stats is not None:  # absent under --benchmark-disable
        benchmark.extra_info["per_material_s"] = benchmark.stats.stats.mean / n


@pytest.fixture(scope="module")
def small_tables(synthetic_cache):
    ds = synthetic_dataset("small", seed=0, cache_dir=str(synthetic_cache))
    return [ds.load(name).table for name in ds.materials[:4]]


@pytest.mark.parametrize("mode", ["batched", "looped"])
def test_fit_short_recipe(benchmark, small_tables, mode):
    samples = draw_samples(SHORT.n_samples, "rusinkiewicz", seed=0)
    outcomes = benchmark.pedantic(_fit, args=(small_tables, SHORT, mode == "batched", samples), rounds=1, iterations=1)
    _record(benchmark, outcomes, len(small_tables))


@pytest.fixture(scope="module")
def full_targets(synthetic_cache):
    root = find_release_dir()
    if root is not None:
        ds = nbrdf_release_dataset(str(root), limit=FULL_MATERIALS)
    else:
        ds = synthetic_dataset("default", seed=0, cache_dir=str(synthetic_cache))
    return [ds.load(name) for name in ds.materials[:FULL_MATERIALS]]


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["batched", "looped"])
def test_fit_default_recipe(benchmark, full_targets, mode):
    """Per-material time of the default recipe, 16 materials in one stack against 16 one-by-one fits."""
    recipe = Recipe()
    samples = draw_samples(recipe.n_samples, "rusinkiewicz", seed=0)
    tables = [t.table for t in full_targets]
    outcomes = benchmark.pedantic(_fit, args=(tables, recipe, mode == "batched", samples), rounds=1, iterations=1)
    _record(benchmark, outcomes, len(tables))
    benchmark.extra_info["losses"] = {t.name: round(o.loss, 6) for t, o in zip(full_targets, outcomes)}


@pytest.mark.slow
@pytest.mark.parametrize("recipe_name", ["default", "reference"])
def test_fit_one_material_by_recipe(benchmark, full_targets, recipe_name):
    """One material alone: the published reference recipe (~50-90 s) against the default recipe."""
    recipe = REFERENCE_RECIPE if recipe_name == "reference" else Recipe()
    target = full_targets[0]
    model = NBRDF()
    init = model._random_init(target, 0)
    samples = draw_samples(recipe.n_samples, "rusinkiewicz", seed=0)
    outcomes = benchmark.pedantic(lambda: fit_batched([target.table], [init], recipe=recipe, samples=samples),
                                  rounds=1, iterations=1)
    _record(benchmark, outcomes, 1)
    z = nw.last_layer(outcomes[0].weights, samples.x)
    benchmark.extra_info.update(material=target.name, zero_output_fraction=(z <= 0).float().mean(dim=0).tolist())


ENGINE_ROUNDS = 3


def _engines_interleaved(tables, recipe, samples, rounds):
    """Each engine's per-round seconds and last outcomes, the order alternating each round."""
    inits = _inits(len(tables))
    seconds, outcomes = {"autograd": [], "manual": []}, {}
    for r in range(rounds):
        for engine in ("autograd", "manual") if r % 2 == 0 else ("manual", "autograd"):
            start = time.perf_counter()
            outcomes[engine] = fit_batched(tables, inits, recipe=recipe, samples=samples, engine=engine)
            seconds[engine].append(time.perf_counter() - start)
    return seconds, outcomes


def _record_engines(benchmark, tables, recipe, samples, rounds):
    load_before = os.getloadavg()
    seconds, outcomes = benchmark.pedantic(_engines_interleaved, args=(tables, recipe, samples, rounds),
                                           rounds=1, iterations=1)
    n = len(tables)
    per = {e: statistics.median(s) / n for e, s in seconds.items()}
    benchmark.extra_info.update(
        materials=n, rounds=rounds, per_material_s_autograd=per["autograd"], per_material_s_manual=per["manual"],
        speedup=per["autograd"] / per["manual"], round_s=seconds, loadavg_before=load_before,
        loadavg_after=os.getloadavg(), cpu_threads=torch.get_num_threads(),
        mean_loss={e: statistics.mean(o.loss for o in out) for e, out in outcomes.items()},
        epochs={e: [o.epochs for o in out] for e, out in outcomes.items()},
    )


@pytest.fixture(scope="module")
def small_sixteen(small_tables):
    return (small_tables * 4)[:FULL_MATERIALS]


def test_engines_short_recipe(benchmark, small_sixteen):
    """The hand-written engine against autograd: 16 stacked materials, a short recipe."""
    samples = draw_samples(SHORT.n_samples, "rusinkiewicz", seed=0)
    _record_engines(benchmark, small_sixteen, SHORT, samples, ENGINE_ROUNDS)


@pytest.mark.slow
def test_engines_default_recipe(benchmark, full_targets):
    """The hand-written engine against autograd: 16 materials, the default recipe."""
    recipe = Recipe()
    samples = draw_samples(recipe.n_samples, "rusinkiewicz", seed=0)
    _record_engines(benchmark, [t.table for t in full_targets], recipe, samples, ENGINE_ROUNDS)
    benchmark.extra_info["materials_fitted"] = [t.name for t in full_targets]
