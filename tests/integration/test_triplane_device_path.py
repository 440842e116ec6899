"""The triplane fitter's GPU path (Adam from a device schedule, losses accumulated on the
device) run on the CPU, so that CI checks its arithmetic against the CPU path; the options
of the published recipe (iterations, fresh cosine-weighted pairs, step decay); the CPU's
refusal of a recipe sized for a GPU; and moving models between devices."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch
import yaml

from brdfbench import coords, merl
from brdfbench.data.synthetic import generate_material
from brdfbench.errors import ConfigError
from brdfbench.protocols.representation import Material
from brdfbench_representations import triplane_fit as tf
from brdfbench_representations import triplane_model as tm
from brdfbench_representations.nbrdf_fit import draw_samples
from brdfbench_representations.triplane import CPU_LIMIT_S, Tripleplane, TriplaneGated

CONF = Path(__file__).resolve().parents[2] / "conf" / "representation"
SMALL = {"h_res": 8, "d_res": [6, 10], "channels": [3, 4], "hidden": [5]}
PLAIN = tm.Shape(h_res=8, d_res=(6, 10), channels=(3, 4), hidden=(5,))
GATED = tm.Shape(h_res=8, d_res=(6, 10), channels=(3, 4), hidden=(5,), latent=2, warps=2)
FIXED = tf.Recipe(epochs=2, n_samples=20_000, batch_size=1024)
#: The published recipe's options, shortened: 20 steps of 2048 fresh cosine-weighted pairs,
#: the rate decayed every 8 steps, 8 steps between loss readings.
FRESH = tf.Recipe(iterations=20, resample=True, sampling="cosine", batch_size=2048, n_samples=8 * 2048, lr=3e-3,
                  texture_lr=3e-3, schedule="step", lr_decay_every=8, loss="mixed", beta1=0.99, ema=0.005)


@pytest.fixture(scope="module")
def tables():
    return [generate_material(i, seed=0)[2] for i in (1, 4)]


def _both_paths(monkeypatch, tables, shape, recipe):
    cpu = tf.fit_batched(tables, [5, 6], shape, recipe, sample_seed=2)
    monkeypatch.setattr(tf, "_DEVICE_PATH_ON_CPU", True)
    dev = tf.fit_batched(tables, [5, 6], shape, recipe, sample_seed=2)
    monkeypatch.setattr(tf, "_DEVICE_PATH_ON_CPU", False)
    return cpu, dev


@pytest.mark.parametrize("shape,recipe", [
    (PLAIN, FIXED),
    (GATED, replace(FIXED, loss="mixed", ema=0.05, beta1=0.99)),
    (GATED, FRESH),
], ids=["log_l1", "mixed-ema-gated", "paper-options"])
def test_the_device_path_fits_as_the_cpu_path(monkeypatch, tables, shape, recipe):
    cpu, dev = _both_paths(monkeypatch, tables, shape, recipe)
    for a, b in zip(cpu, dev):
        # the same pairs in the same order; only the Adam update is reassociated (lr/c1 and 1/c2 as factors)
        assert len(a.curve) == len(b.curve)
        assert b.curve == pytest.approx(a.curve, rel=2e-3)
        assert a.tensors.keys() == b.tensors.keys()
        for k in a.tensors:
            assert torch.allclose(a.tensors[k], b.tensors[k], rtol=1e-2, atol=1e-3), k


@pytest.mark.parametrize("schedule", ["onecycle", "step"])
def test_the_adam_schedule_is_the_rates_with_bias_corrections(schedule):
    recipe = tf.Recipe(lr=0.02, texture_lr=0.05, beta1=0.99, schedule=schedule, lr_decay=0.5, lr_decay_every=30)
    table = tf.adam_schedule(recipe, 100, torch.device("cpu"))
    assert table.shape == (100, 2, 2) and table.dtype == torch.float32
    for step in (0, 9, 29, 30, 99):
        lr, texture_lr = recipe.rates(step, 100)
        c1, c2 = 1 - 0.99 ** (step + 1), 1 - tf.ADAM_BETA2 ** (step + 1)
        assert table[step, 0].tolist() == pytest.approx([lr / c1, 1 / c2], rel=1e-6)
        assert table[step, 1].tolist() == pytest.approx([texture_lr / c1, 1 / c2], rel=1e-6)
    if schedule == "step":
        assert recipe.rates(29, 100) == (0.02, 0.05) and recipe.rates(30, 100) == (0.01, 0.025)
        assert recipe.rates(99, 100) == pytest.approx((0.02 / 8, 0.05 / 8))


def test_iterations_replace_epochs_and_fresh_draws_change_every_step(monkeypatch, tables):
    steps = []
    monkeypatch.setattr(tf._Stack, "adam_step", lambda self, lr, texture_lr: steps.append((lr, texture_lr)))
    kept = draw_samples(12_345, "rusinkiewicz", 0).x.shape[0]  # the pairs of the draw above the horizon
    out = tf.fit_batched(tables[:1], [1], PLAIN, tf.Recipe(iterations=30, n_samples=12_345, batch_size=1024))
    assert len(steps) == 30 and len(out[0].curve) == math.ceil(30 / math.ceil(kept / 1024))
    steps.clear()
    out = tf.fit_batched(tables[:1], [1], PLAIN, replace(FRESH, iterations=21))
    assert len(steps) == 21 and len(out[0].curve) == 3  # readings after 8, 16 and 21 steps
    assert steps[7][0] == pytest.approx(3e-3) and steps[8][0] == pytest.approx(3e-3 * 0.9)
    gen = torch.Generator().manual_seed(0)
    a, b = tf.draw_pairs(64, "cosine", gen, torch.device("cpu")), tf.draw_pairs(64, "cosine", gen, torch.device("cpu"))
    assert not torch.equal(a.cells, b.cells)


@pytest.mark.parametrize("sampling", ["uniform", "cosine"])
def test_drawn_pairs_agree_with_the_reference_coordinates(sampling):
    n = 50_000
    pairs = tf.draw_pairs(n, sampling, torch.Generator().manual_seed(3), torch.device("cpu"))
    u = torch.rand(4, n, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    if sampling == "cosine":
        wi, wo = tf._cosine_direction(u[0], u[1]).T, tf._cosine_direction(u[2], u[3]).T
        hd = coords.to_half_diff(wi, wo)
        theta_h, theta_d, phi_d = hd.theta_h, hd.theta_d, hd.phi_d
        assert float(pairs.cos_i.mean()) == pytest.approx(2 / 3, abs=5e-3)  # E[cos θ] of a cosine-weighted draw
    else:
        theta_h, theta_d, phi_d = u[0] * (math.pi / 2), u[1] * (math.pi / 2), u[2] * (2 * math.pi)
        wi, wo = coords.from_half_diff(theta_h, torch.zeros_like(theta_h), theta_d, phi_d)
    above = coords.above_horizon(wi, wo)
    assert torch.equal(pairs.above > 0, above)
    assert torch.allclose(pairs.r_h, torch.sin(theta_h).float(), atol=1e-6)
    assert torch.allclose(pairs.r_d, torch.sin(theta_d).float(), atol=1e-6)
    dphi = (pairs.phi - torch.remainder(phi_d, math.pi).float()).abs()
    assert torch.minimum(dphi, math.pi - dphi).max() < 1e-5
    assert torch.allclose(pairs.cos_i[above], wi[above, 2].clamp(tf.COS_MIN, tf.COS_MAX).float(), atol=1e-6)
    cells = (merl.theta_half_index(theta_h) * merl.RES_THETA_D + merl.theta_diff_index(theta_d)) * merl.RES_PHI_D
    cells = cells + merl.phi_diff_index(phi_d)
    assert (pairs.cells == cells).float().mean() > 0.9999  # torch's arithmetic, the reader's numpy: edges may differ


def _paper_params() -> dict:
    config = yaml.safe_load((CONF / "triplane_gated_paper.yaml").read_text())
    assert config["name"] == "triplane_gated"
    return config["params"]


def test_the_published_recipe_is_refused_on_the_cpu_naming_the_setting_and_the_time():
    params = _paper_params()
    assert (params["batch_size"], params["iterations"], params["beta1"], params["ema"], params["loss"]) == (
        2**18, 100_000, 0.99, 0.005, "mixed")
    model = TriplaneGated(**params)
    assert model.cpu_seconds() > CPU_LIMIT_S
    with pytest.raises(ConfigError, match=r"allow_slow_cpu=true.*") as caught:
        model.fit_many([Material("unused", generate_material(0, seed=0)[2])])
    text = str(caught.value)
    assert "iterations=100,000" in text and "batch_size=262,144" in text and " h per material" in text
    assert "device=cuda" in text
    assert TriplaneGated(**{**params, "allow_slow_cpu": True}).fit_many([]) == []  # opted in: not refused
    assert Tripleplane().cpu_seconds() < CPU_LIMIT_S / 10 and TriplaneGated().cpu_seconds() < CPU_LIMIT_S / 10


def test_a_short_run_of_the_published_recipe_fits_on_the_cpu(tables):
    params = {**_paper_params(), **SMALL, "iterations": 24, "batch_size": 2048, "n_samples": 8 * 2048,
              "lr_decay_every": 8}
    target = Material("chrome", tables[0])
    model = TriplaneGated(**params).fit(target, seed=0)
    curve = model.fit_info["training_curve"]
    assert len(curve) == 3 and curve[-1] < curve[0]
    wi, wo = coords.from_half_diff(*(torch.full((4,), v, dtype=torch.float64) for v in (0.2, 0.0, 0.5, 1.0)))
    assert torch.isfinite(model.eval(wi, wo)).all()


def test_the_defaults_keep_the_recipe_and_its_params():
    for cls, name in ((Tripleplane, "tripleplane"), (TriplaneGated, "triplane_gated")):
        config = yaml.safe_load((CONF / f"{name}.yaml").read_text())["params"]
        model = cls(**config)
        assert model.recipe == tf.Recipe(**{k: v for k, v in config.items() if k in tf.Recipe.__dataclass_fields__},
                                         owner=name)
        assert (model.recipe.iterations, model.recipe.resample, model.recipe.sampling, model.recipe.schedule) == (
            None, False, "uniform", "onecycle")
        assert model.devices == frozenset({"cpu", "cuda"})


@pytest.mark.parametrize("key,value", [("iterations", 0), ("resample", "yes"), ("sampling", "peak"),
                                       ("schedule", "cosine"), ("lr_decay", 0.0), ("lr_decay", 1.5),
                                       ("lr_decay_every", 0), ("allow_slow_cpu", "yes")])
def test_bad_new_options_name_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        TriplaneGated(**{key: value})


def test_an_unfitted_model_moves_without_touching_a_device():
    model = Tripleplane(**SMALL).to("cuda:0")  # nothing held: no CUDA call, here or on a GPU host
    assert model.device == torch.device("cuda", 0) and model.tensors is None
    assert model.fit_batch_size == 128 and Tripleplane(batch_size=2**18).to("cuda:0").fit_batch_size == 16
    assert model.to("cpu").fit_batch_size == 16


def test_a_fitted_model_moves_and_evaluates_as_before(tables):
    model = Tripleplane(**SMALL, epochs=1, n_samples=10_000).fit(Material("chrome", tables[0]), seed=0)
    assert model.device.type == "cpu" and all(t.device.type == "cpu" for t in model.tensors.values())
    wi, wo = coords.from_half_diff(*(torch.rand(4, 500, generator=torch.Generator().manual_seed(1),
                                                dtype=torch.float64) * torch.tensor([1.5, 6.2, 1.5, 6.2])[:, None]))
    before = model.eval(wi, wo)
    assert torch.equal(model.to("cpu").eval(wi, wo), before)
