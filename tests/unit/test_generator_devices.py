"""Generators and the NeuMERL / AugMERL builds on the device a user has, checked on the CPU:
device declarations, `to("cpu")` a no-op, the paper-size hyperdiffusion config refused on the
CPU before any work, the device code paths (an epoch's draws at once, device-side loss sums)
equal to a step-by-step loop, the datasets' device keys, and the kit's device checks catching
broken generators. tests/gpu/test_generators_gpu.py runs the same on a GPU."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
import yaml

from brdfbench import device as devices
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.protocols.generator import Generator, TrainingData
from brdfbench.plugins.specs import GeneratorSpec
from brdfbench.testing import check_generator
from brdfbench.testing.generators import generator_checks, training_data
from brdfbench_generators import hyperdiffusion as hd
from brdfbench_generators import vae
from brdfbench_generators.pca import _median_reference, gram_pca
from brdfbench_generators.samples import WeightSamples
from device_plugins import PlacedGaussian  # tests/device_plugins.py

TORCH_GENERATORS = ("vae_brdf", "vae_nbrdf", "hyperdiffusion", "pca_brdf", "pca_nbrdf")
QUICK = {"vae_brdf": {"epochs": 2}, "vae_nbrdf": {"epochs": 3}, "hyperdiffusion": {"epochs": 2},
         "pca_brdf": {}, "pca_nbrdf": {}}
PAPER = Path(__file__).resolve().parents[2] / "conf" / "generator" / "hyperdiffusion_paper.yaml"
no_gpu = pytest.mark.skipif(devices.cuda_count() > 0, reason="checks what a machine without a GPU refuses")


@pytest.fixture(scope="module")
def data():
    return training_data()


# -- declarations ------------------------------------------------------------------------


@pytest.mark.parametrize("name", TORCH_GENERATORS)
def test_torch_generators_declare_the_gpu(name):
    cls = registry.get("generators", name).load()
    assert cls.devices == frozenset({"cpu", "cuda"})
    assert cls().device == torch.device("cpu")


def test_the_training_set_runs_on_the_cpu_only():
    # it holds names and hands out the dataset's own (CPU) tables: nothing to place
    cls = registry.get("generators", "training_set").load()
    assert cls.devices == frozenset({"cpu"})
    with pytest.raises(ConfigError, match="runs on cpu"):
        cls().to("cuda:0")


@pytest.mark.parametrize("name", TORCH_GENERATORS)
def test_to_cpu_is_a_no_op_on_a_fitted_generator(name, data):
    g = registry.get("generators", name).create(**QUICK[name]).fit(data, seed=1)
    state = {k: v.clone() for k, v in g.state_dict().items()}
    before = g.sample(3, seed=4)
    assert g.to("cpu") is g and g.device == torch.device("cpu")
    after = g.sample(3, seed=4)
    assert torch.equal(before.array, after.array) and after.array.device.type == "cpu"
    assert all(torch.equal(state[k], v) and v.device.type == "cpu" for k, v in g.state_dict().items())


def test_weight_samples_are_built_where_their_array_lives():
    vec = torch.zeros(2, 675)
    assert WeightSamples(vec)[0].device == torch.device("cpu")


# -- the paper-size hyperdiffusion config ----------------------------------------------------


def _paper_params() -> dict:
    doc = yaml.safe_load(PAPER.read_text(encoding="utf-8"))
    assert doc["name"] == "hyperdiffusion"
    return doc["params"]


def test_the_paper_config_is_the_published_size():
    p = _paper_params()
    assert (p["layers"], p["d_model"], p["heads"], p["chunk_size"]) == (12, 768, 12, 675)
    assert (p["epochs"], p["batch_size"], p["lr"], p["lr_final"]) == (700, 512, 5e-4, 5e-6)
    g = hd.HyperDiffusion(**p)
    assert len(g._segments()) == 1  # the 675 weights are one token, beside the context token
    assert 86e6 < g.n_parameters() < 88e6  # 87.3 M (the authors' code: 86.3 M)
    assert hd.T == 100 and (hd.BETA_START, hd.BETA_END) == (1e-4, 2e-2)


def test_the_paper_config_is_refused_on_the_cpu_before_any_work():
    touched = []

    def weights(names):
        touched.append(names)
        raise AssertionError("the weight vectors were asked for before the refusal")

    data = TrainingData(names=tuple(f"m{i}" for i in range(2160)), load=lambda name: None,
                        weight_source=weights, dataset="neumerl")
    g = hd.HyperDiffusion(**_paper_params())
    with pytest.raises(ConfigError) as err:
        g.fit(data, seed=0)
    text = str(err.value)
    assert "max_cpu_hours" in text and "generator.params.max_cpu_hours=null" in text and "device=cuda" in text
    assert "87.3 M-parameter" in text and "GiB" in text and "GFLOP/s" in text and " h " in text
    est = g.training_estimate(2160)
    assert est["steps"] == 700 * math.ceil(2160 / 512) and est["cpu_hours"] > 2
    assert not touched and g.model is None


def test_opting_in_or_a_gpu_lifts_the_refusal():
    p = _paper_params()
    hd.HyperDiffusion(**{**p, "max_cpu_hours": None})._check_cpu_budget(2160)  # opted in: no limit
    hd.HyperDiffusion(**{**p, "max_cpu_hours": 1e4})._check_cpu_budget(2160)  # a budget that covers it
    on_gpu = hd.HyperDiffusion(**p)
    on_gpu._device = torch.device("cuda", 0)  # what `to` records (no GPU needed to read the rule)
    on_gpu._check_cpu_budget(2160)


def test_the_default_config_has_no_cpu_limit_and_its_params_are_unchanged():
    g = hd.HyperDiffusion()
    assert g.params["max_cpu_hours"] is None
    assert 0.95e6 < g.n_parameters() < 1.05e6
    assert g.training_estimate(2160)["cpu_hours"] < 1
    with pytest.raises(ConfigError, match="max_cpu_hours"):
        hd.HyperDiffusion(max_cpu_hours=0)


# -- the device code paths, run with device = cpu ------------------------------------------


def test_hyperdiffusion_epoch_draws_are_a_step_by_step_loops_draws():
    g = hd.HyperDiffusion(condition_on="category")
    n, batch, width = 23, 10, 675
    gen = torch.Generator().manual_seed(3)
    perm, t, eps, drop = g._epoch_draws(n, batch, width, True, gen, torch.device("cpu"))
    ref = torch.Generator().manual_seed(3)
    assert torch.equal(perm, torch.randperm(n, generator=ref))
    for start in range(0, n, batch):
        b = min(batch, n - start)
        rows = slice(start, start + b)
        assert torch.equal(t[rows], torch.randint(0, hd.T, (b,), generator=ref))
        assert torch.equal(eps[rows], torch.randn((b, width), generator=ref))
        assert torch.equal(drop[rows], torch.rand(b, generator=ref) < g.params["p_uncond"])
    assert torch.equal(torch.rand(5, generator=gen), torch.rand(5, generator=ref))  # both streams at one place


def _reference_vae_epoch(net, opt, x, weight, total, recipe, g):
    """VAE training as it was written before the device path: draws and host reads per step."""
    net.train()
    sum_loss, sum_kl = 0.0, 0.0
    for rows in torch.randperm(x.shape[0], generator=g).split(recipe.batch_size):
        eps = torch.randn(rows.numel(), recipe.latent, generator=g)
        recon, kl = vae.loss_terms(net, x[rows], weight, total, eps)
        loss = recon + recipe.kl_weight * kl
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sum_loss += float(loss.detach()) * rows.numel()
        sum_kl += float(kl.detach()) * rows.numel()
    return sum_loss / x.shape[0], sum_kl / x.shape[0]


def test_the_vae_device_path_is_the_step_by_step_loop_bit_for_bit():
    recipe = vae.Recipe.checked("t", latent=8, hidden=16, layers=3, epochs=3, batch_size=5, lr=1e-3,
                                kl_weight=2e-3, patience=None, val_fraction=0.0)
    x = torch.randn(23, 12, generator=torch.Generator().manual_seed(0))
    weight = torch.ones(12)
    runs = []
    for epoch_fn in (vae.train_epoch, _reference_vae_epoch):
        net = vae.VAENet(12, recipe, vae.rng(0, 1))
        opt = torch.optim.Adam(net.parameters(), lr=recipe.lr)
        g = vae.rng(0, 2)
        curve = [epoch_fn(net, opt, x, weight, 12.0, recipe, g) for _ in range(recipe.epochs)]
        runs.append((curve, net.state_dict()))
    (curve_a, state_a), (curve_b, state_b) = runs
    assert curve_a == curve_b
    assert all(torch.equal(state_a[k], state_b[k]) for k in state_a)


def _reference_hd_train(model_gen, z, gen):
    """Hyperdiffusion's training loop as it was before the device path (unconditional):
    draws and a host read of the loss at each step."""
    g, p = model_gen, model_gen.params
    model, n = g.model, z.shape[0]
    batch = min(p["batch_size"], n)
    total = p["epochs"] * math.ceil(n / batch)
    ab = hd.alpha_bars(hd.beta_schedule()).to(torch.float32)
    opt = torch.optim.AdamW(model.parameters(), lr=p["lr"], weight_decay=p["weight_decay"])
    ema = [q.detach().clone() for q in model.parameters()]
    losses, step = [], 0
    model.train()
    for _ in range(p["epochs"]):
        perm, total_loss = torch.randperm(n, generator=gen), 0.0
        for start in range(0, n, batch):
            idx = perm[start:start + batch]
            x0 = z[idx]
            t = torch.randint(0, hd.T, (x0.shape[0],), generator=gen)
            eps = torch.randn(x0.shape, generator=gen)
            a = ab[t][:, None]
            loss = torch.nn.functional.mse_loss(model(a.sqrt() * x0 + (1 - a).sqrt() * eps, t, None), eps)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            for group in opt.param_groups:
                group["lr"] = hd._learning_rate(p["lr"], p["lr_final"], step, total)
            opt.step()
            hd._ema_update(ema, model.parameters(), min(p["ema"], (1 + step) / (10 + step)))
            step += 1
            total_loss += float(loss.detach()) * len(idx)
        losses.append(total_loss / n)
    with torch.no_grad():
        for q, e in zip(model.parameters(), ema):
            q.copy_(e)
    return [round(v, 6) for v in losses]


def test_the_hyperdiffusion_device_path_is_the_step_by_step_loop_bit_for_bit():
    params = dict(d_model=32, layers=2, heads=2, epochs=3, batch_size=7, prior="standard")
    z = torch.randn(17, 675, generator=torch.Generator().manual_seed(1))
    models = []
    for run in ("device path", "reference"):
        g = hd.HyperDiffusion(**params)
        g.model = g._build(0)
        gen = torch.Generator().manual_seed(9)
        hd.init_parameters(g.model, gen)
        if run == "device path":
            g._train(z, None, gen, False, 9)
            curve = g.curve["loss"]
        else:
            curve = _reference_hd_train(g, z, gen)
        models.append((curve, g.model.state_dict()))
    (curve_a, a), (curve_b, b) = models
    assert curve_a == curve_b
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_gram_pca_and_medians_on_an_explicit_cpu_device_are_the_defaults():
    x = torch.randn(6, 3000, generator=torch.Generator().manual_seed(2))
    x -= x.mean(dim=0)
    a, b = gram_pca(x, 4), gram_pca(x, 4, device="cpu")
    assert all(torch.equal(u, v) for u, v in zip(a[:3], b[:3])) and a[3] == b[3]
    vals = torch.rand(5, 3, 40, generator=torch.Generator().manual_seed(3))
    valid = torch.rand(5, 40, generator=torch.Generator().manual_seed(4)) > 0.3
    assert torch.equal(_median_reference(vals, valid), _median_reference(vals, valid, torch.device("cpu")))


def test_augmerl_gram_and_reconstruction_take_a_device():
    from brdfbench.data import _augmerl_pca as kpca

    centred = torch.randn(9, 70_000, generator=torch.Generator().manual_seed(5))
    assert torch.equal(kpca.base_gram(centred), kpca.base_gram(centred, "cpu"))
    beta = torch.randn(3, 9, dtype=torch.float64, generator=torch.Generator().manual_seed(6))
    mean = torch.randn(70_000)
    out = kpca.reconstruct(beta, centred, mean)
    assert out.device.type == "cpu" and out.shape == (3, 70_000)


# -- the datasets' device ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def neumerl_parts(synthetic_cache, tmp_path_factory):
    from brdfbench.data import neumerl as N

    cache = tmp_path_factory.mktemp("neumerl-devices")
    base = {"size": "small", "cache_dir": str(synthetic_cache)}
    kw = dict(base_params=base, size=8, test_fraction=0.25, seed=0, cache_dir=str(cache), epochs=2,
              n_samples=10_000, batch_size=1024, lr=1e-2, batch_materials=2)
    return N, kw


def test_neumerl_on_the_cpu_keeps_its_key_and_fingerprint(neumerl_parts):
    N, kw = neumerl_parts
    default, explicit = N.neumerl_dataset(**kw), N.neumerl_dataset(**kw, device="cpu")
    assert default.fingerprint == explicit.fingerprint
    assert default.weights.key == explicit.weights.key and default.weights.device == torch.device("cpu")
    assert default.loader.pca_key == explicit.loader.pca_key and "device" not in default.loader.identity


def test_a_gpus_neumerl_fits_and_augmerl_pca_are_cached_apart(neumerl_parts):
    # Built with a CUDA device object directly (nothing runs on it here): the keys a GPU uses.
    N, kw = neumerl_parts
    cpu = N.neumerl_dataset(**kw)
    gpu = torch.device("cuda", 0)
    weights = N.NeumerlWeights(cpu.weights.tables, cpu.weights.params, 2, 0, kw["cache_dir"], gpu)
    assert weights.key != cpu.weights.key and weights.folder != cpu.weights.folder
    assert weights.recipe == cpu.weights.recipe  # what a vector depends on, but the device
    assert weights.batch_materials >= 128  # the fitter stacks more materials on a GPU
    from brdfbench.data.augmerl import AugmerlLoader

    loader = cpu.loader
    on_gpu = AugmerlLoader(loader.base_name, loader.base, loader.recipes, loader.k, kw["cache_dir"], gpu)
    assert on_gpu.identity == {**loader.identity, "device": "cuda"} and on_gpu.pca_path != loader.pca_path


@no_gpu
def test_a_gpu_this_machine_lacks_is_refused_naming_the_key(neumerl_parts):
    N, kw = neumerl_parts
    with pytest.raises(ConfigError, match=r"dataset\.params\.device='cuda'"):
        N.neumerl_dataset(**kw, device="cuda")


# -- the kit's device checks on the CPU ------------------------------------------------------------


class CpuGaussian(PlacedGaussian):
    devices = frozenset({"cpu"})
    _move = Generator._move


class DeclaresAnUnknownDevice(PlacedGaussian):
    devices = frozenset({"cpu", "tpu"})


class OmitsTheCpu(PlacedGaussian):
    devices = frozenset({"cuda"})


class AcceptsAnyDevice(CpuGaussian):
    """CPU-only, but its `to` accepts a GPU it would never use."""

    def to(self, device):
        return self


class MovesBadly(PlacedGaussian):
    """Its `_move` rounds what it moves: `to("cpu")` changes a CPU generator's samples."""

    def _move(self, device):
        if self.mean is not None:
            self.mean = self.mean.float().to(device).double()


@pytest.fixture
def spec():
    added = []

    def make(cls):
        s = GeneratorSpec(name=f"dev_{cls.__name__.lower()}", description="test", target=f"{__name__}:{cls.__name__}",
                          learns_from="nbrdf")
        registry.register("generators", s)
        added.append(s.name)
        return s

    yield make
    for name in added:
        registry.unregister("generators", name)


def test_a_placed_generator_passes_and_its_gpu_check_skips_here(spec):
    report = check_generator(spec(PlacedGaussian))
    assert report.passed, report.summary()
    assert report.outcomes["devices_declared"] == "passed"
    if not devices.cuda_count():
        assert report.outcomes["device_agreement"] == "skipped"
        assert "no CUDA device" in report.details["device_agreement"]


def test_a_generator_outside_the_device_protocol_is_not_asked_about_devices(spec):
    names = {c.name for c in generator_checks(spec(CpuGaussian))}
    assert "devices_declared" not in names and "device_agreement" not in names
    names = {c.name for c in generator_checks("pca_nbrdf")}
    assert {"devices_declared", "device_agreement"} <= names


@pytest.mark.parametrize("cls, words", [
    (DeclaresAnUnknownDevice, "unknown device type(s) ['tpu']"),
    (OmitsTheCpu, "including 'cpu'"),
    (AcceptsAnyDevice, "was accepted but 'cuda' is not in its devices"),
    (MovesBadly, "to('cpu') changed a CPU generator's samples"),
])
def test_the_kit_catches_a_generator_broken_about_devices(spec, cls, words):
    report = check_generator(spec(cls))
    assert report.outcomes["devices_declared"] == "failed", report.summary()
    assert words in report.details["devices_declared"], report.details["devices_declared"]
