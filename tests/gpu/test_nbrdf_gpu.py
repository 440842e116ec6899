"""NBRDF and the naive MLP on a GPU: fits agree with the CPU's, CUDA graphs with eager steps,
and the same fitted model evaluates alike on both devices."""

from __future__ import annotations

import pytest
import torch

from brdfbench.data.synthetic import generate_material
from brdfbench.nbrdf import network as net
from brdfbench.protocols.representation import Material
from brdfbench.testing import check_representation
from brdfbench_representations.nbrdf import NBRDF, NaiveMLP
from brdfbench_representations.nbrdf_fit import Recipe, fit_batched

RECIPE = Recipe(epochs=6, n_samples=200_000)


@pytest.fixture(scope="module")
def materials():
    out = []
    for i in range(6):
        name, category, table = generate_material(i, seed=0)
        out.append(Material(name, table, category))
    return out


def _inits(n):
    return [net.glorot_init((21, 21), torch.Generator().manual_seed(i)) for i in range(n)]


def test_graphs_replay_the_eager_steps(materials, gpu):
    tables = [m.table for m in materials]
    graphed = fit_batched(tables, _inits(6), recipe=RECIPE, device=gpu, cuda_graphs=True)
    eager = fit_batched(tables, _inits(6), recipe=RECIPE, device=gpu, cuda_graphs=False)
    for a, b in zip(graphed, eager):
        assert a.weights["W1"].device.type == "cuda"
        assert a.epochs == b.epochs
        assert a.loss == pytest.approx(b.loss, rel=1e-4)


@pytest.mark.parametrize("loss", ["l1", "l1_or_l2"])
def test_gpu_fits_score_as_cpu_fits(materials, gpu, loss):
    recipe = Recipe(**{**RECIPE.__dict__, "loss": loss})
    tables = [m.table for m in materials]
    cpu = fit_batched(tables, _inits(6), recipe=recipe)
    dev = fit_batched(tables, _inits(6), recipe=recipe, device=gpu)
    for a, b in zip(cpu, dev):
        assert b.loss == pytest.approx(a.loss, rel=0.03, abs=2e-4)


@pytest.mark.parametrize("cls", [NBRDF, NaiveMLP])
def test_the_same_model_evaluates_alike_on_both_devices(materials, gpu, cls):
    model = cls(epochs=2, n_samples=50_000).fit(materials[1], seed=0)
    moved = cls.from_state(model.params, model.state_dict(), model.metadata()).to(gpu)
    g = torch.Generator().manual_seed(0)
    for dtype in (torch.float32, torch.float64):
        wi = torch.nn.functional.normalize(torch.randn(100_000, 3, generator=g, dtype=dtype), dim=1).abs()
        wo = torch.nn.functional.normalize(torch.randn(100_000, 3, generator=g, dtype=dtype), dim=1).abs()
        a = model.eval(wi, wo)
        b = moved.eval(wi.to(gpu), wo.to(gpu))
        assert b.device.type == "cuda" and b.dtype == dtype
        torch.testing.assert_close(b.cpu(), a, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("name", ["nbrdf", "naive_mlp"])
def test_conformance_with_the_device_checks(name):
    report = check_representation(name, n_pairs=50_000)
    assert report.outcomes["device_agreement"] == "passed", report.summary()
    report.raise_on_failure()
