"""NBRDF and naive MLP: the batched fitter, dark materials, initialisation, the runner's batches."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import merl, modelio
from brdfbench.data.nbrdf_h5 import nbrdf_table
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.nbrdf import network as nw
from brdfbench.nbrdf.formats import Network, read_network, to_model, write_network
from brdfbench.nbrdf.network import MAX_LOG_VALUE
from brdfbench.protocols.representation import FIT_LOSS_KEY, Material
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.store.sqlite import ResultsStore
from brdfbench.testing import adversarial_pairs
from brdfbench_representations.nbrdf import NBRDF, NaiveMLP
from brdfbench_representations.nbrdf_fit import (
    REFERENCE_RECIPE, Recipe, draw_samples, fit_batched, learning_rate, predict_log,
)

#: A recipe small enough for unit tests (about 0.1 s per material-epoch less than the default).
TINY = Recipe(epochs=4, batch_size=1024, lr=1e-2, n_samples=30_000, patience=None)
TINY_PARAMS = dict(epochs=4, batch_size=1024, lr=1e-2, n_samples=30_000, patience=None)
#: The darkest materials of the published release (lowest mean BRDF over uniform pairs).
DARKEST = ("black-fabric", "black-obsidian", "specular-black-phenolic", "black-phenolic")


def _materials(small_dataset, n=3):
    return [small_dataset.load(name) for name in small_dataset.materials[:n]]


def _init(seed, hidden=(21, 21)):
    return nw.glorot_init(hidden, torch.Generator().manual_seed(seed))


def _assert_weights_close(a, b, **tol):
    assert list(a) == list(b)
    for k in a:
        torch.testing.assert_close(a[k], b[k], **tol)


# --------------------------------------------------------------------------- the output and its loss


@settings(max_examples=200, deadline=None)
@given(z=st.floats(-1e4, 1e4), cos=st.floats(1e-7, 1 - 2.0**-24))
def test_log_output_is_exact_and_finite(z, cos):
    """log(1 + expm1(z) c) computed in log space: finite everywhere, equal to the float64 formula."""
    zt = torch.tensor([[z]], dtype=torch.float32)
    c = torch.tensor([[cos]], dtype=torch.float32)
    z, cos = float(zt), float(c)
    pred = predict_log(zt, torch.log(c), torch.log1p(-c))
    assert torch.isfinite(pred).all()
    exact = math.log1p(math.expm1(z) * cos) if z < 700 else z + math.log(cos)  # beyond float64: log(e^z c)
    assert float(pred) == pytest.approx(exact, rel=1e-5, abs=1e-6)


def test_log_output_has_a_gradient_where_the_clamp_has_none():
    z = torch.tensor([[-3.0, -0.5, 2.0]], requires_grad=True)
    c = torch.full((1, 3), 0.5)
    for output, dead in (("log", False), ("clamped", True)):
        z.grad = None
        predict_log(z, c.log(), torch.log1p(-c), output).sum().backward()
        assert (z.grad[0, :2] == 0).all().item() is dead
        assert z.grad[0, 2] > 0


@settings(max_examples=100, deadline=None)
@given(z=st.floats(-1e30, 1e30))
def test_evaluation_never_overflows(z):
    value = nw.to_value(torch.tensor([[z] * 3], dtype=torch.float32), torch.tensor(merl.CHANNEL_SCALES, dtype=torch.float32))
    assert torch.isfinite(value).all() and (value >= 0).all()
    assert float(value[0, 0]) <= math.expm1(MAX_LOG_VALUE) * merl.CHANNEL_SCALES[0] * (1 + 1e-6)


def test_learning_rate_schedules():
    r = Recipe(lr=0.02)
    assert learning_rate(r, 0, 1000) == pytest.approx(0.02 / 25)
    assert learning_rate(r, 100, 1000) == pytest.approx(0.02)  # the end of the 10 % warm-up
    assert learning_rate(r, 999, 1000) < 0.02 / 1e3
    rates = [learning_rate(r, s, 1000) for s in range(100, 1000)]
    assert all(a >= b for a, b in zip(rates, rates[1:]))
    assert learning_rate(REFERENCE_RECIPE, 500, 1000) == 5e-4


def test_samples_are_above_the_horizon_and_on_the_grid():
    s = draw_samples(50_000, "rusinkiewicz", seed=3)
    assert 0.55 < s.x.shape[0] / 50_000 < 0.7  # about 62 % of uniform (θh, θd, φd) triples are valid
    assert (s.cos_i > 0).all() and s.x.dtype == torch.float32
    assert int(s.cells.min()) >= 0 and int(s.cells.max()) < math.prod(merl.SHAPE)
    assert torch.equal(draw_samples(50_000, "rusinkiewicz", seed=3).x, s.x)
    d = draw_samples(50_000, "directions", seed=3)
    assert torch.allclose(d.x[:, :3].norm(dim=1), torch.ones(d.x.shape[0]), atol=1e-6)


# --------------------------------------------------------------------------- batching


def test_batched_fit_equals_one_at_a_time(small_dataset):
    """Stacking materials changes the speed, not the result: each material's gradient is its own."""
    mats = _materials(small_dataset)
    inits = [_init(i) for i in range(len(mats))]
    together = fit_batched([m.table for m in mats], inits, recipe=TINY)
    for m, init, out in zip(mats, inits, together):
        alone = fit_batched([m.table], [init], recipe=TINY)[0]
        _assert_weights_close(out.weights, alone.weights, rtol=1e-4, atol=1e-5)
        assert out.loss == pytest.approx(alone.loss, rel=1e-4)
        assert out.epochs == TINY.epochs


def test_batch_mates_do_not_matter(small_dataset):
    a, b, c = _materials(small_dataset)
    with_b = fit_batched([a.table, b.table], [_init(0), _init(1)], recipe=TINY)[0]
    with_c = fit_batched([a.table, c.table], [_init(0), _init(2)], recipe=TINY)[0]
    _assert_weights_close(with_b.weights, with_c.weights, rtol=1e-4, atol=1e-5)


def test_training_lowers_the_loss(small_dataset):
    mats = _materials(small_dataset)
    losses = []
    fit_batched([m.table for m in mats], [_init(i) for i in range(3)], recipe=TINY,
                on_epoch=lambda epoch, loss: losses.append(loss.clone()))
    assert len(losses) == TINY.epochs
    assert (losses[-1] < 0.8 * losses[0]).all(), (losses[0], losses[-1])


def test_early_stop_drops_stalled_materials(small_dataset):
    mats = _materials(small_dataset)
    recipe = Recipe(epochs=6, batch_size=1024, lr=1e-2, n_samples=30_000, patience=1, min_improvement=0.9)
    active = []
    out = fit_batched([m.table for m in mats], [_init(i) for i in range(3)], recipe=recipe,
                      on_epoch=lambda epoch, loss: active.append(len(loss)))
    # No epoch improves by 90 %: everyone stops at the first chance, in the second half.
    assert [o.epochs for o in out] == [4, 4, 4] and active == [3, 3, 3, 3]
    never = fit_batched([mats[0].table], [_init(0)], recipe=Recipe(**{**recipe.__dict__, "patience": None}))
    assert never[0].epochs == 6


def test_fit_batched_rejects_mismatched_inits(small_dataset):
    mats = _materials(small_dataset, 2)
    with pytest.raises(ValueError, match="one initial weight dict per table"):
        fit_batched([m.table for m in mats], [_init(0)], recipe=TINY)
    with pytest.raises(ValueError, match="same layout"):
        fit_batched([m.table for m in mats], [_init(0), _init(1, hidden=(8, 8))], recipe=TINY)


# --------------------------------------------------------------------------- dark materials


def _dead_init():
    w = _init(0)
    w["b3"] = torch.full((3,), -5.0)  # every output starts at expm1(-5 + …) < 0: clamped to 0
    w["W3"] = w["W3"] * 0.01
    return w


def test_clamped_output_kills_a_network_started_below_zero(small_dataset):
    """The reference's relu(expm1(z)) has no gradient once all outputs are negative: nothing moves."""
    target = _materials(small_dataset, 1)[0].table
    recipe = Recipe(**{**TINY.__dict__, "output": "clamped"})
    losses = []
    out = fit_batched([target], [_dead_init()], recipe=recipe, on_epoch=lambda e, loss: losses.append(float(loss[0])))
    _assert_weights_close(out[0].weights, _dead_init(), rtol=0, atol=0)
    assert losses[0] == pytest.approx(losses[-1], rel=1e-6)


def test_log_output_revives_it(small_dataset):
    target = _materials(small_dataset, 1)[0].table
    losses = []
    fit_batched([target], [_dead_init()], recipe=TINY, on_epoch=lambda e, loss: losses.append(float(loss[0])))
    assert losses[-1] < 0.5 * losses[0]


@pytest.fixture(scope="module")
def release(nbrdf_release):
    return nbrdf_release


@pytest.mark.shared_data
def test_darkest_release_materials_do_not_die(release):
    """The default recipe fits the four darkest published materials: low loss, and light where they reflect."""
    targets = [release.load(name) for name in DARKEST]
    models = NBRDF().fit_many(targets, seed=0)
    pairs = adversarial_pairs(65_536, torch.float32, seed=1)["uniform"]
    for target, model in zip(targets, models):
        loss = model.fit_info[FIT_LOSS_KEY]
        assert loss < 0.004, (target.name, loss)
        truth = merl.lookup_nearest(target.table.values, *[p.double() for p in pairs]).mean(dim=0)
        fitted = model.eval(*pairs).double().mean(dim=0)
        ratio = fitted / truth
        assert ((ratio > 0.5) & (ratio < 2)).all(), (target.name, ratio)


@pytest.mark.slow
@pytest.mark.shared_data
def test_reference_recipe_kills_a_channel_the_default_keeps(release):
    """Reproduces the failure the default recipe avoids (~80 s): from this initialisation the
    published recipe's relu(expm1(z)) lets alum-bronze's blue channel go negative everywhere,
    where it has no gradient and stays dead; the default recipe from the same start does not."""
    target = release.load("alum-bronze")
    init = NBRDF()._random_init(target, 0)
    samples = draw_samples(REFERENCE_RECIPE.n_samples, "rusinkiewicz", seed=0)
    dead = {}
    for name, recipe in (("reference", REFERENCE_RECIPE), ("default", Recipe())):
        outcome = fit_batched([target.table], [init], recipe=recipe, samples=samples)[0]
        dead[name] = (nw.last_layer(outcome.weights, samples.x) <= 0).double().mean(dim=0)
    assert dead["reference"].max() == 1.0, dead  # a channel outputs 0 for every sample
    assert dead["default"].max() < 0.01, dead


# --------------------------------------------------------------------------- the representation


def test_fit_many_equals_fit(small_dataset):
    mats = _materials(small_dataset)
    many = NBRDF(**TINY_PARAMS, batch_materials=2).fit_many(mats, seed=5)
    for m, model in zip(mats, many):
        single = NBRDF(**TINY_PARAMS).fit(m, seed=5)
        _assert_weights_close(model.weights, single.weights, rtol=1e-4, atol=1e-5)
        assert model.fit_info["fitted_to"] == m.name and model.fit_info["epochs"] == TINY.epochs


@pytest.mark.parametrize("batch_materials", [1, 16])
def test_shared_initialisation_starts_everyone_from_the_first_fit(small_dataset, batch_materials):
    a, b, c = _materials(small_dataset)
    fitter = NBRDF(**TINY_PARAMS, init="shared", batch_materials=batch_materials)
    models = fitter.fit_many([a, b], seed=0) + fitter.fit_many([c], seed=0)  # the anchor outlives a call
    first = NBRDF(**TINY_PARAMS).fit(a, seed=0)
    _assert_weights_close(models[0].weights, first.weights, rtol=0, atol=0)
    for later, model in ((b, models[1]), (c, models[2])):
        from_first = fit_batched([later.table], [first.weights], recipe=TINY)[0]
        _assert_weights_close(model.weights, from_first.weights, rtol=1e-4, atol=1e-5)


def test_initialisation_from_a_file(small_dataset, tmp_path):
    a, b = _materials(small_dataset, 2)
    start = _init(11)
    path = write_network(Network(start), tmp_path / "start.npy")
    model = NBRDF(**TINY_PARAMS, init=str(path)).fit(b, seed=0)
    expected = fit_batched([b.table], [start], recipe=TINY)[0]
    _assert_weights_close(model.weights, expected.weights, rtol=1e-5, atol=1e-6)
    with pytest.raises(ConfigError, match="hidden sizes"):
        NBRDF(**TINY_PARAMS, hidden=[8, 8], init=str(write_network(Network(start), tmp_path / "start.pt"))).fit(a)
    with pytest.raises(ModelFileError, match="missing.npy"):
        NBRDF(**TINY_PARAMS, init=str(tmp_path / "missing.npy")).fit(a)


def _with_tensor(path, key, change):
    """Rewrite one tensor of a saved model file in place, header kept (a damaged file)."""
    import safetensors
    import safetensors.torch

    with safetensors.safe_open(str(path), framework="pt") as f:
        meta = f.metadata()
        tensors = {k: f.get_tensor(k).clone() for k in f.keys()}
    change(tensors[key])
    safetensors.torch.save_file(tensors, str(path), metadata=meta)
    return path


def _poisoned(tmp_path, kind):
    """A network file for `init` with one NaN or Inf, in the format `kind`."""
    weights = _init(12)
    if kind == "safetensors-scale":
        model = NBRDF()
        model.weights = weights
        path = modelio.save(model, "nbrdf", tmp_path / "scale.safetensors")
        return _with_tensor(path, "output_scale", lambda t: t.__setitem__(1, float("nan")))
    if kind == "safetensors":
        model = NBRDF()
        model.weights = weights
        path = modelio.save(model, "nbrdf", tmp_path / "weights.safetensors")
        return _with_tensor(path, "W2", lambda t: t.__setitem__((0, 0), float("inf")))
    path = write_network(Network(weights), tmp_path / f"start.{kind}")
    if kind == "npy":
        vector = np.load(path)
        vector[100] = np.nan
        np.save(path, vector)
    elif kind == "pt":
        state = torch.load(path, weights_only=True)
        state["fc3.bias"][2] = -float("inf")
        torch.save(state, path)
    return path


@pytest.mark.parametrize("kind", ["npy", "pt", "safetensors", "safetensors-scale"])
def test_an_init_network_with_nan_or_inf_is_refused_naming_the_file(small_dataset, tmp_path, kind):
    """Weights or an output scale that are not finite would train to NaN (or scale every
    value to NaN): refused before any fitting, with the file named."""
    path = _poisoned(tmp_path, kind)
    with pytest.raises(ModelFileError) as exc:
        NBRDF(**TINY_PARAMS, init=str(path)).fit(_materials(small_dataset, 1)[0])
    assert str(path) in str(exc.value) and ("NaN" in str(exc.value) or "non-finite" in str(exc.value))


def test_a_saved_output_scale_must_be_the_units_one(tmp_path):
    model = NBRDF()
    model.weights = _init(13)
    path = modelio.save(model, "nbrdf", tmp_path / "scaled.safetensors")
    _with_tensor(path, "output_scale", lambda t: t.mul_(2.0))
    with pytest.raises(ModelFileError, match=r"scaled\.safetensors.*'output_scale'.*raw_units=False"):
        modelio.load(path)


def test_a_fitted_model_keeps_its_training_params_and_fit_metadata(small_dataset, tmp_path):
    model = NBRDF(**TINY_PARAMS).fit(_materials(small_dataset, 1)[0])
    _, loaded = modelio.load(modelio.save(model, "nbrdf", tmp_path / "fitted.safetensors"))
    assert loaded.params == model.params and loaded.params["epochs"] == TINY_PARAMS["epochs"]
    assert loaded.metadata() == model.metadata() and FIT_LOSS_KEY in loaded.metadata()


def test_naive_mlp_fits_from_directions(small_dataset):
    target = _materials(small_dataset, 1)[0]
    model = NaiveMLP(**TINY_PARAMS).fit(target, seed=0)
    assert model.fit_info[FIT_LOSS_KEY] < 0.1
    wi, wo = adversarial_pairs(4096, torch.float32, seed=2)["uniform"]
    x = nw.encode(wi, wo, "directions")
    assert torch.equal(x, torch.cat((wi, wo), dim=1))
    assert torch.isfinite(model.eval(wi, wo)).all()


def test_declared_costs():
    model = NBRDF()
    assert model.nbytes == 4 * 675
    assert model.flops_per_eval == nw.RUSINKIEWICZ_FLOPS + nw.mlp_flops([21, 21])
    assert NaiveMLP(hidden=[32, 32]).nbytes == 4 * (6 * 32 + 32 + 32 * 32 + 32 + 32 * 3 + 3)


@pytest.mark.parametrize(
    "params, key",
    [
        ({"hidden": []}, "hidden"),
        ({"hidden": "wide"}, "hidden"),
        ({"hidden": [21, 0]}, "hidden"),
        ({"epochs": 0}, "epochs"),
        ({"batch_size": 2.5}, "batch_size"),
        ({"lr": -1.0}, "lr"),
        ({"lr": float("nan")}, "lr"),
        ({"schedule": "cyclic"}, "schedule"),
        ({"output": "softplus"}, "output"),
        ({"patience": 0}, "patience"),
        ({"batch_materials": 0}, "batch_materials"),
        ({"init": ""}, "init"),
    ],
)
def test_bad_parameters_name_the_key(params, key):
    with pytest.raises(ConfigError, match=key):
        NBRDF(**params)


# --------------------------------------------------------------------------- the published release


@pytest.mark.shared_data
def test_imported_release_network_reproduces_its_table(release):
    target = release.load("alum-bronze")
    model = to_model(read_network(target.source))
    wi, wo = merl.grid_directions()
    keep = torch.from_numpy(target.table.valid.reshape(-1))
    idx = torch.nonzero(keep).flatten()[::97]
    got = model.eval(wi[idx], wo[idx])  # float64 inputs, as the table's; the table ran the network in float32
    expected = torch.from_numpy(target.table.values.reshape(3, -1)[:, idx.numpy()].T)
    torch.testing.assert_close(got, expected, rtol=2e-4, atol=1e-6)


def test_refit_of_an_nbrdf_table_is_accurate():
    """A table generated by a 6-21-21-3 network is within the reach of the same architecture."""
    gen = _init(3)
    gen["b3"] = torch.tensor([-1.0, -1.2, -1.5])
    table = nbrdf_table({k: v.numpy() for k, v in gen.items()})
    target = Material(name="generated", table=table, category="test", source="test")
    model = NBRDF(epochs=6, n_samples=100_000, batch_size=1024, lr=1e-2, patience=None).fit(target, seed=0)
    assert model.fit_info[FIT_LOSS_KEY] < 0.01


# --------------------------------------------------------------------------- the runner's batches


def _run_cfg(tmp_path, synthetic_cache, isolate=True, **params):
    return RunConfig(
        representation="nbrdf", representation_params={**TINY_PARAMS, **params}, label="nbrdf", dataset="synthetic",
        dataset_params={"size": "small", "cache_dir": str(synthetic_cache)},
        harness=harness_config(n_random=4096, throughput_batch=1024), results_dir=tmp_path, isolate=isolate,
    )


def test_runner_fits_in_batches(tmp_path, synthetic_cache, capfd):
    counts = run(_run_cfg(tmp_path, synthetic_cache, batch_materials=4))
    log = capfd.readouterr().err  # `lines` progress: a line as each batch starts, no bar redrawn with \r
    assert log.count("nbrdf to 4 materials at once") == 1 and log.count("nbrdf to 2 materials at once") == 1
    assert "\r" not in log and "epoch/s" not in log
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert counts["done"] == 6 and counts["failed"] == 0
    batches = df[df.metric == "fit_batch"].set_index("material")["value"]
    assert sorted(batches.tolist()) == [2, 2, 4, 4, 4, 4]
    fit_time = df[df.metric == "fit_time"].set_index("material")["value"]
    for size in (2, 4):  # one amortised time per batch
        assert fit_time[batches[batches == size].index].nunique() == 1
    assert set(df[df.metric == "fit_loss"].value > 0) == {True}


def test_a_failed_batch_fails_its_materials_and_the_sweep_goes_on(tmp_path, synthetic_cache, monkeypatch):
    calls = []

    def flaky(self, targets, *, seed=0, progress=False):
        calls.append([t.name for t in targets])
        if len(calls) == 1:
            raise RuntimeError("out of patience")
        return original(self, targets, seed=seed, progress=progress)

    original = NBRDF.fit_many
    monkeypatch.setattr(NBRDF, "fit_many", flaky)  # in this process: the cells run in-process
    counts = run(_run_cfg(tmp_path, synthetic_cache, isolate=False, batch_materials=4))
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    failed = df[df.status == "failed"]
    assert (counts["done"], counts["failed"]) == (2, 4)
    assert set(failed.material) == set(calls[0]) and failed.message.str.contains("out of patience").all()


# --------------------------------------------------------------------------- training pairs


def test_peak_sampling_puts_pairs_at_the_specular_peak():
    uniform = draw_samples(200_000, "rusinkiewicz", seed=1)
    peak = draw_samples(200_000, "rusinkiewicz", seed=1, sampling="peak")
    near = [float((torch.asin(s.x[:, 0].clamp(max=1)) < 0.01).float().mean()) for s in (uniform, peak)]
    assert near[0] == pytest.approx(0.01, rel=0.2)  # of the pairs above the horizon
    assert near[1] > 5 * near[0]
    with pytest.raises(ConfigError, match="sampling"):
        Recipe(sampling="cosine")
