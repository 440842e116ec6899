"""tripleplane and triplane_gated on a GPU: fits agree with the CPU's, the same fitted model
evaluates alike on both devices (and its Mitsuba kernel reads it from either), the steps of
an epoch never wait for the host, the conformance kit's device checks pass, and a short run
of the published recipe (conf/representation/triplane_gated_paper.yaml) fits."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from brdfbench.data.synthetic import generate_material
from brdfbench.protocols.representation import Material
from brdfbench.testing import check_representation
from brdfbench_representations import triplane_fit as tf
from brdfbench_representations import triplane_model as tm
from brdfbench_representations.triplane import Tripleplane, TriplaneGated

CONF = Path(__file__).resolve().parents[2] / "conf" / "representation"
PLAIN = tm.Shape(h_res=64, d_res=(32, 32), channels=(8, 8), hidden=(16,))
GATED = tm.Shape(h_res=64, d_res=(32, 32), channels=(8, 8), hidden=(16,), latent=1, warps=2)
RECIPE = tf.Recipe(epochs=3, n_samples=80_000)
SEEDS = [11, 12, 13, 14]


@pytest.fixture(scope="module")
def materials():
    out = []
    for i in (0, 1, 4, 9):
        name, category, table = generate_material(i, seed=0)
        out.append(Material(name, table, category))
    return out


def _pairs(n: int, dtype, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    wi = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=dtype), dim=1).abs()
    wo = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=dtype), dim=1).abs()
    return wi, wo


@pytest.mark.parametrize("shape,recipe", [(PLAIN, RECIPE), (GATED, replace(RECIPE, loss="mixed", ema=0.05, beta1=0.99))],
                         ids=["tripleplane-log_l1", "triplane_gated-mixed-ema"])
def test_gpu_fits_score_as_cpu_fits(materials, gpu, shape, recipe):
    tables = [m.table for m in materials]
    cpu = tf.fit_batched(tables, SEEDS, shape, recipe)
    dev = tf.fit_batched(tables, SEEDS, shape, recipe, device=gpu)
    for a, b in zip(cpu, dev):
        assert all(t.device.type == "cuda" for t in b.tensors.values())
        # the same pairs, order and starts; other summation orders and a reassociated Adam step
        assert b.loss == pytest.approx(a.loss, rel=0.03, abs=2e-4)


@pytest.mark.parametrize("cls", [Tripleplane, TriplaneGated])
def test_the_same_model_evaluates_alike_on_both_devices(materials, gpu, cls):
    model = cls(epochs=1, n_samples=50_000).fit(materials[1], seed=0)
    moved = cls.from_state(model.params, model.state_dict(), model.metadata()).to(gpu)
    assert all(t.device.type == "cuda" for t in moved.tensors.values())
    for dtype in (torch.float32, torch.float64):
        wi, wo = _pairs(100_000, dtype)
        a = model.eval(wi, wo)
        b = moved.eval(wi.to(gpu), wo.to(gpu))
        assert b.device.type == "cuda" and b.dtype == dtype
        torch.testing.assert_close(b.cpu(), a, rtol=1e-5, atol=1e-7)


def test_a_model_fitted_on_the_gpu_lives_there_and_moves_back(materials, gpu):
    fitted = TriplaneGated(epochs=1, n_samples=50_000).to(gpu).fit_many(materials[:2], seed=0)
    wi, wo = _pairs(20_000, torch.float32, seed=1)
    for model in fitted:
        assert model.device.type == "cuda" and all(t.device.type == "cuda" for t in model.tensors.values())
        on_gpu = model.eval(wi.to(gpu), wo.to(gpu)).cpu()
        kernel_from_gpu = _kernel_values(model, wi, wo)  # the kernel reads a GPU model's weights on the host
        model.to("cpu")  # as the pipeline does before a render harness
        assert all(t.device.type == "cpu" for t in model.tensors.values())
        torch.testing.assert_close(model.eval(wi, wo), on_gpu, rtol=1e-5, atol=1e-7)
        kernel = _kernel_values(model, wi, wo)
        if kernel is not None:
            torch.testing.assert_close(kernel, kernel_from_gpu, rtol=0, atol=0)
            torch.testing.assert_close(kernel, on_gpu, rtol=1e-4, atol=1e-6)


def _kernel_values(model, wi, wo):
    """The model's drjit kernel (Mitsuba's LLVM variant) at (wi, wo), or None where Mitsuba
    or its LLVM variant is not here."""
    try:
        from brdfbench import mitsuba_env

        if not mitsuba_env.llvm_usable():
            return None
        with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
            vec = lambda w: mi.Vector3f(*(w[:, i].numpy().copy() for i in range(3)))  # noqa: E731
            out = model.drjit_kernel().eval(vec(wi), vec(wo))
            return torch.from_numpy(np.stack([np.array(out[i]) for i in range(3)], axis=1))
    except ImportError:
        return None


def _syncs(gpu, tables, recipe) -> int:
    """Host synchronisations (torch's sync debug mode) of one fit."""
    torch.cuda.set_sync_debug_mode("warn")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            tf.fit_batched(tables, SEEDS[:len(tables)], GATED, recipe, device=gpu)
    finally:
        torch.cuda.set_sync_debug_mode("default")
    return sum("synchroniz" in str(w.message) for w in caught)


@pytest.mark.parametrize("fresh", [False, True], ids=["fixed-draw", "fresh-draws"])
def test_an_epoch_never_waits_for_the_host(materials, gpu, fresh):
    tables = [m.table for m in materials[:2]]
    if fresh:  # 30 steps per epoch
        recipe = tf.Recipe(resample=True, sampling="cosine", batch_size=1024, n_samples=30 * 1024, loss="mixed",
                           ema=0.005, beta1=0.99, schedule="step", lr_decay_every=20)
        short, long = replace(recipe, iterations=60), replace(recipe, iterations=120)
    else:  # about 25 steps per epoch
        recipe = tf.Recipe(batch_size=1024, n_samples=40_000, ema=0.01)
        short, long = replace(recipe, epochs=2), replace(recipe, epochs=4)
    _syncs(gpu, tables, short)  # warm caches (cuFFT plans, cuBLAS handles)
    extra = _syncs(gpu, tables, long) - _syncs(gpu, tables, short)
    # two more epochs of 25-30 steps: the shuffle's copy and the loss reading, not a wait per step
    assert extra <= 2 * 3, extra


@pytest.mark.parametrize("name", ["tripleplane", "triplane_gated"])
def test_conformance_with_the_device_checks(name):
    report = check_representation(name, n_pairs=50_000)
    assert report.outcomes["device_agreement"] == "passed", report.summary()
    report.raise_on_failure()


def test_a_short_run_of_the_published_recipe_fits_on_the_gpu(materials, gpu):
    config = yaml.safe_load((CONF / "triplane_gated_paper.yaml").read_text())
    params = {**config["params"], "iterations": 300, "n_samples": 100 * 2**18, "lr_decay_every": 100}
    assert params["batch_size"] == 2**18 and params["resample"] and params["sampling"] == "cosine"
    model = TriplaneGated(**params).to(gpu)
    fitted = model.fit_many(materials[:2], seed=0)
    for m in fitted:
        curve = m.fit_info["training_curve"]
        assert len(curve) == 3 and all(np.isfinite(curve)) and curve[-1] < curve[0], curve
        assert m.device.type == "cuda" and all(torch.isfinite(t).all() for t in m.tensors.values())
