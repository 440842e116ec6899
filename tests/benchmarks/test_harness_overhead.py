"""The accuracy harness's own cost per cell (pytest-benchmark): one `merl` (nearest) cell, so
no fit and a cheap model, at the default harness: the full MERL grid, 2²⁰ random pairs,
metrics l1, l1_log, l1_log_cos, hdr_rmse, hdr_mae, then the throughput measurement in
batches of 2¹⁶; on synthetic materials.

    python -m pytest tests/benchmarks/test_harness_overhead.py --benchmark-enable

`test_first_cell` starts every round from cold caches, as a fresh worker's first cell,
which builds the direction geometry; `test_later_cell` scores a material after another
one built it. Each round gets a fresh copy of the material's table, so per-material work
(scaled values, validity) is always counted. `extra_info` splits the median into accuracy
and throughput seconds. Disabled (the default run) both are skipped: they time, and
tests/unit/test_accuracy_geometry.py checks what they run.
"""

from __future__ import annotations

import statistics
import time

import pytest

from brdfbench import merl
from brdfbench.plugins import registry
from brdfbench.data.synthetic import generate_material
from brdfbench.harness import directions
from brdfbench.harness.accuracy import accuracy_geometry, evaluate_accuracy
from brdfbench.harness.cost import evaluation_throughput
from brdfbench.protocols.representation import Material

METRICS = ("l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae")
N_RANDOM = 2**20
BATCH = 2**16


@pytest.fixture(scope="module")
def tables():
    return [generate_material(i, seed=0) for i in (1, 2)]


def _fresh(material) -> Material:
    name, category, table = material
    return Material(name, merl.MerlTable(table.raw), category)


def _clear_caches() -> None:
    for cached in (accuracy_geometry, directions.random_pairs, merl.grid_directions, merl.grid_above_horizon):
        cached.cache_clear()


def _run(benchmark, target_of, setup, n_random: int) -> None:
    """Time `rounds` cells of fresh copies of `target_of()`, each after `setup()`."""
    specs = [registry.get("metrics", name) for name in METRICS]
    split = []

    def cell(target):
        model = registry.get("representations", "merl").create().fit(target)
        t0 = time.perf_counter()
        evaluate_accuracy(model, target, specs, n_random=n_random)
        t1 = time.perf_counter()
        evaluation_throughput(model, batch=BATCH)
        split.append((t1 - t0, time.perf_counter() - t1))

    def prepared():
        setup()
        return (target_of(),), {}

    benchmark.pedantic(cell, setup=prepared, rounds=5, iterations=1)
    benchmark.extra_info.update(n_random=n_random, accuracy_s=statistics.median(a for a, _ in split),
                                throughput_s=statistics.median(t for _, t in split))


def test_first_cell(enabled, tables):
    _run(enabled, lambda: _fresh(tables[0]), _clear_caches, N_RANDOM)


def test_later_cell(enabled, tables):
    first = _fresh(tables[0])
    evaluate_accuracy(registry.get("representations", "merl").create().fit(first), first,
                      [registry.get("metrics", "l1"), registry.get("metrics", "hdr_mae")], n_random=N_RANDOM)
    _run(enabled, lambda: _fresh(tables[1]), lambda: None, N_RANDOM)
