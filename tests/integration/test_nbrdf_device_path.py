"""The NBRDF fitter's GPU path (scheduled Adam, per-step index gathers, on-device loss
accumulators, autograd), run on the CPU so that CI checks its arithmetic against the CPU
path (the hand-written forward and backward pass)."""

from __future__ import annotations

import pytest
import torch

from brdfbench.data.synthetic import generate_material
from brdfbench.nbrdf import network as net
from brdfbench_representations import nbrdf_fit
from brdfbench_representations.nbrdf_fit import Recipe, adam_schedule, fit_batched, learning_rate

RECIPE = Recipe(epochs=4, batch_size=1024, n_samples=30_000, patience=1, min_improvement=0.05)


@pytest.fixture(scope="module")
def tables():
    return [generate_material(i, seed=0)[2] for i in (1, 4, 9)]


def _inits(n):
    return [net.glorot_init((21, 21), torch.Generator().manual_seed(i)) for i in range(n)]


@pytest.mark.parametrize("loss", ["l1", "l1_or_l2", "l1_then_l2"])
def test_the_device_path_fits_as_the_cpu_path(tables, monkeypatch, loss):
    recipe = Recipe(**{**RECIPE.__dict__, "loss": loss})
    cpu = fit_batched(tables, _inits(3), recipe=recipe)
    monkeypatch.setattr(nbrdf_fit, "_DEVICE_PATH_ON_CPU", True)
    dev = fit_batched(tables, _inits(3), recipe=recipe, cuda_graphs=False)
    for a, b in zip(cpu, dev):
        # the same steps; only the Adam update is reassociated (lr/c1 and 1/c2 as factors)
        assert b.epochs == a.epochs and b.descended == a.descended and b.fitted == a.fitted
        assert b.loss == pytest.approx(a.loss, rel=2e-3)
        for k in a.weights:
            assert torch.allclose(a.weights[k], b.weights[k], rtol=1e-2, atol=1e-3), k


def test_the_adam_schedule_is_the_learning_rate_with_bias_corrections():
    recipe = Recipe(lr=0.02)
    table = adam_schedule(recipe, 100, torch.device("cpu"))
    assert table.shape == (100, 2) and table.dtype == torch.float32
    for step in (0, 9, 10, 99):
        assert float(table[step, 0]) == pytest.approx(learning_rate(recipe, step, 100) / (1 - 0.9 ** (step + 1)), rel=1e-6)
        assert float(table[step, 1]) == pytest.approx(1 / (1 - 0.999 ** (step + 1)), rel=1e-6)


def test_early_stops_on_the_device_path_drop_rows(tables, monkeypatch):
    monkeypatch.setattr(nbrdf_fit, "_DEVICE_PATH_ON_CPU", True)
    recipe = Recipe(epochs=6, batch_size=1024, lr=1e-2, n_samples=30_000, patience=1, min_improvement=0.9)
    active = []
    out = fit_batched(tables, _inits(3), recipe=recipe, cuda_graphs=False,
                      on_epoch=lambda epoch, loss: active.append(len(loss)))
    assert [o.epochs for o in out] == [4, 4, 4] and active == [3, 3, 3, 3]
