"""Generators, NeuMERL and AugMERL on a GPU: each torch generator trains and samples there (its
state and sample arrays on the device, its samples finite and evaluating finite and
non-negative), the conformance kit's device checks pass (and catch what only a GPU shows),
the paper-size hyperdiffusion denoiser builds there and takes a few training steps, and the
datasets' GPU builds agree with their CPU builds within the tolerance their docstrings
state. Small sizes: the whole file is meant to run in about a minute on one GPU."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from brdfbench.plugins import registry
from brdfbench.device import on_host
from brdfbench.protocols.generator import TrainingData, WeightSet
from brdfbench.plugins.specs import GeneratorSpec
from brdfbench.testing import check_generator
from brdfbench.testing.adversarial import adversarial_pairs
from brdfbench.testing.generators import generator_checks, training_data
from brdfbench_generators.samples import TableSamples, WeightSamples
from device_plugins import PlacedGaussian  # tests/device_plugins.py

TORCH_GENERATORS = ("vae_brdf", "vae_nbrdf", "hyperdiffusion", "pca_brdf", "pca_nbrdf")
QUICK = {"vae_brdf": {"epochs": 2}, "vae_nbrdf": {"epochs": 5}, "hyperdiffusion": {"epochs": 3},
         "pca_brdf": {}, "pca_nbrdf": {}}
PAPER = Path(__file__).resolve().parents[2] / "conf" / "generator" / "hyperdiffusion_paper.yaml"


@pytest.fixture(scope="module")
def data():
    return training_data()


@pytest.mark.parametrize("name", TORCH_GENERATORS)
def test_each_generator_trains_and_samples_on_the_gpu(name, data, gpu):
    g = registry.get("generators", name).create(**QUICK[name]).to(gpu)
    g.fit(data, seed=3)
    assert g.device.type == "cuda"
    assert all(t.device.type == "cuda" for t in g.state_dict().values())
    samples = g.sample(3, seed=4)
    assert samples.array.device.type == "cuda" and bool(samples.finite.all())
    again = g.sample(3, seed=4)
    assert torch.equal(samples.array, again.array)  # a seed still fixes the draw
    wi, wo = adversarial_pairs(4096, torch.float32, seed=5)["uniform"]
    for i in range(len(samples)):
        item = samples[i]
        # weight samples are networks on the GPU; table samples are CPU tables
        assert item.device.type == ("cpu" if isinstance(samples, TableSamples) else "cuda")
        out = on_host(item.eval, item.device)(wi, wo)
        assert torch.isfinite(out).all() and (out >= 0).all()


@pytest.mark.parametrize("name", TORCH_GENERATORS)
def test_the_kits_device_checks_pass(name):
    checks = {c.name: c for c in generator_checks(name)}
    checks["devices_declared"]()
    checks["device_agreement"]()


def test_a_generator_moved_to_the_gpu_saves_and_loads_on_the_cpu(data, gpu, tmp_path):
    from brdfbench import modelio

    g = registry.get("generators", "vae_nbrdf").create(epochs=3).to(gpu).fit(data, seed=1)
    path = modelio.save_generator(g, "vae_nbrdf", tmp_path / "g.safetensors")
    _, loaded = modelio.load_generator(path)
    assert loaded.device.type == "cpu"
    a, b = g.sample(4, seed=2).array.cpu(), loaded.sample(4, seed=2).array
    torch.testing.assert_close(b, a, rtol=1e-4, atol=1e-5)


# -- what only a GPU shows: the kit's GPU check catches it ----------------------------------


GpuGaussian = PlacedGaussian


class SamplesOnTheCpu(GpuGaussian):
    """Declares "cuda" and moves its state, but hands its samples back on the CPU."""

    def _sample(self, n, condition, seed):
        out = super()._sample(n, condition, seed)
        return WeightSamples(out.array.cpu())


class TrainsWrongOnTheGpu(GpuGaussian):
    """Its GPU fit goes wrong (a NaN spread): the moved CPU generator agrees, the GPU-trained
    one samples non-finite weights."""

    def fit(self, data, *, seed=0, progress=False):
        super().fit(data, seed=seed)
        if self.device.type == "cuda":
            self.std = self.std * float("nan")
        return self


@pytest.mark.parametrize("cls, words", [(SamplesOnTheCpu, "sampled an array on cpu"),
                                         (TrainsWrongOnTheGpu, "trained on cuda")])
def test_the_kit_catches_what_only_a_gpu_shows(cls, words):
    spec = GeneratorSpec(name=f"gpu_broken_{cls.__name__.lower()}", description="test",
                         target=f"{__name__}:{cls.__name__}", learns_from="nbrdf")
    registry.register("generators", spec)
    try:
        report = check_generator(spec)
    finally:
        registry.unregister("generators", spec.name)
    assert report.outcomes["devices_declared"] == "passed", report.summary()
    assert report.outcomes["device_agreement"] == "failed", report.summary()
    assert words in report.details["device_agreement"], report.details["device_agreement"]


def test_a_correct_gpu_generator_passes_the_gpu_check():
    spec = GeneratorSpec(name="gpu_gaussian", description="test", target=f"{__name__}:GpuGaussian",
                         learns_from="nbrdf")
    registry.register("generators", spec)
    try:
        report = check_generator(spec)
    finally:
        registry.unregister("generators", spec.name)
    assert report.outcomes["device_agreement"] == "passed", report.summary()
    report.raise_on_failure()


# -- the paper-size hyperdiffusion ---------------------------------------------------------


def test_the_paper_size_denoiser_trains_and_samples_on_the_gpu(gpu, capsys):
    from brdfbench_generators.hyperdiffusion import HyperDiffusion

    params = yaml.safe_load(PAPER.read_text(encoding="utf-8"))["params"]
    g = HyperDiffusion(**{**params, "epochs": 2}).to(gpu)
    n = 1024  # 2 steps of batch 512 per epoch
    rng = np.random.default_rng(0)
    vectors = (rng.standard_normal((n, 675)) * rng.uniform(1e-3, 1.0, 675)).astype(np.float32)
    names = tuple(f"m{i}" for i in range(n))
    data = TrainingData(names=names, load=lambda name: None, dataset="random",
                        weight_source=lambda asked: WeightSet(names, vectors))
    torch.cuda.reset_peak_memory_stats(gpu)
    g.fit(data, seed=0)  # max_cpu_hours=2 is in the params: on the GPU it does not apply
    count = sum(q.numel() for q in g.model.parameters())
    assert count == g.n_parameters() and 87.0e6 < count < 87.6e6
    assert g.curve["steps"] == 4 and all(np.isfinite(g.curve["loss"]))
    samples = g.sample(4, seed=1)  # 100 DDIM steps of the 87 M model
    assert samples.array.device.type == "cuda" and bool(samples.finite.all())
    peak = torch.cuda.max_memory_allocated(gpu)
    with capsys.disabled():
        print(f"\npaper-size hyperdiffusion: {count:,} parameters; 4 training steps of batch 512 and "
              f"4 samples x 100 DDIM steps; peak GPU memory {peak / 2**30:.2f} GiB; "
              f"losses {g.curve['loss']}")


# -- the datasets' GPU builds ------------------------------------------------------------------


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    cache = tmp_path_factory.mktemp("synthetic-gpu")
    return {"size": "small", "cache_dir": str(cache)}


def test_neumerl_fits_on_the_gpu_cached_apart_and_close_to_the_cpu(base, tmp_path, gpu, capsys):
    from brdfbench.data import neumerl as N

    kw = dict(base_params=base, size=8, test_fraction=0.25, seed=0, cache_dir=str(tmp_path), epochs=3,
              n_samples=20_000, batch_size=1024, lr=1e-2, batch_materials=2)
    cpu, dev = N.neumerl_dataset(**kw), N.neumerl_dataset(**kw, device="cuda")
    assert dev.fingerprint == cpu.fingerprint and dev.weights.key != cpu.weights.key
    a, b = cpu.weights(cpu.materials), dev.weights(dev.materials)
    assert np.isfinite(b.vectors).all() and b.vectors.shape == a.vectors.shape
    info_a, info_b = N.neumerl_fit_info(cpu), N.neumerl_fit_info(dev)
    assert all("fitted_on" in info_b[m] and "fitted_on" not in info_a[m] for m in cpu.materials)
    rel = [abs(info_b[m]["fit_loss"] - info_a[m]["fit_loss"]) / info_a[m]["fit_loss"] for m in cpu.materials]
    gap = float(np.abs(a.vectors - b.vectors).max())
    with capsys.disabled():
        print(f"\nneumerl GPU vs CPU: fit losses within {max(rel):.2%}; vectors up to {gap:.3g} apart")
    assert max(rel) < 0.05
    again = N.neumerl_dataset(**kw, device="cuda").weights(dev.materials)  # read back from its own cache
    np.testing.assert_array_equal(again.vectors, b.vectors)


def test_augmerl_pca_on_the_gpu_agrees_with_the_cpus(base, tmp_path, gpu, capsys):
    from brdfbench.data import augmerl as A

    kw = dict(base_params=base, size=40, test_fraction=0.1, seed=3, cache_dir=str(tmp_path))
    cpu, dev = A.augmerl_dataset(**kw), A.augmerl_dataset(**kw, device="cuda")
    assert cpu.fingerprint == dev.fingerprint and cpu.loader.pca_path != dev.loader.pca_path
    sa, sb = A.augmerl_pca(cpu), A.augmerl_pca(dev)
    assert sa.comp.k == sb.comp.k
    eig = float(((sa.comp.eigvals - sb.comp.eigvals).abs() / sa.comp.eigvals.abs().max()).max())
    mixes = [m for m in cpu.materials if m.startswith("mix-")][:3]
    worst = 0.0
    for m in mixes:
        x, y = cpu.load(m).table, dev.load(m).table
        assert np.array_equal(x.valid, y.valid)
        v, w = x.values[:, x.valid], y.values[:, y.valid]
        worst = max(worst, float((np.abs(v - w) / np.maximum(np.abs(v), 1e-6)).max()))
    with capsys.disabled():
        print(f"\naugmerl GPU vs CPU PCA: eigenvalues within {eig:.2g} (of the largest); "
              f"mix tables within {worst:.2g} relative")
    assert eig < 1e-9 and worst < 1e-4
