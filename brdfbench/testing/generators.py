"""Conformance checks for generator plugins, in the style of `check_representation`.

    from brdfbench.testing import check_generator
    check_generator("my_generator").raise_on_failure()

The kit fits the generator once (seed FIT_SEED) on a small training split it makes itself
(synthetic materials generated in memory; for generators that learn from NBRDF weights,
networks fitted to them with a short recipe and a shared initialisation, so the vectors
are aligned) and checks: the protocol, sample shapes and dtypes, determinism per seed,
that every sample is finite and evaluates finite and non-negative on the adversarial
direction pairs, a save/load round trip without pickle, clear errors for n ≤ 0 and for a
sample set larger than memory (refused before allocating), a fit that depends on its seed
alone, and declared costs. A spec's `kit_params` make the quick run; `full=True` uses
the generator's defaults.

Devices (`brdfbench.device.Placed`), for a generator that takes part in them (declares
`devices` other than the CPU alone, or overrides `to` / `_move`): `devices_declared` runs
anywhere (known device types, the CPU among them, a new generator on the CPU, `to` of an
undeclared type refused, `to("cpu")` of a fitted CPU generator a no-op); for one that
declares "cuda", `device_agreement` runs where a GPU is (skipped elsewhere, as
`kit.NoDevice`): the CPU-fitted generator moved there samples the CPU's array within
DEVICE_SAMPLE_RTOL for the same seed (every draw comes from the seed's CPU generator, so
only float rounding differs), and one trained there keeps its state there and samples
finite values that evaluate finite and non-negative.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from ..plugins import registry
from ..errors import BrdfbenchError, ConfigError
from ..protocols.generator import LEARNS_FROM, Generator, ResourceError, SampleSet, TrainingData, WeightSet
from ..protocols.representation import Material, Representation
from ..plugins.specs import GeneratorSpec
from . import roundtrip
from .adversarial import adversarial_pairs
from .checks import CheckSet
from .devices import assert_declared, gpu as gpu_device, NoDevice
from .kit import Check, ConformanceReport
from ..data.synthetic import generate_material
from ..device import on_host, Placed
from ..nbrdf.layouts import flatten

#: Seed of the kit's shared fit, so it is one side of the fit-determinism check.
FIT_SEED = 5
#: Synthetic materials the kit trains on (generated in memory).
TRAINING_INDICES = tuple(range(8))
N_SAMPLES = 4
#: A recipe that fits the kit's NBRDF training vectors in seconds (aligned: init=shared).
QUICK_NBRDF = {"epochs": 3, "n_samples": 60_000, "batch_size": 2048, "init": "shared", "patience": None}
#: The CPU-fitted generator moved to a GPU samples the CPU's array within this share of the
#: array's largest magnitude (the same draws; the products round differently, and a
#: diffusion sampler carries that through its steps).
DEVICE_SAMPLE_RTOL = 1e-3


@lru_cache(maxsize=1)
def _materials() -> tuple[Material, ...]:
    out = []
    for i in TRAINING_INDICES:
        name, category, table = generate_material(i, seed=0)
        out.append(Material(name, table, category, source="brdfbench.data.synthetic"))
    return tuple(out)


@lru_cache(maxsize=1)
def _weights() -> WeightSet:
    from ..nbrdf.formats import representation_for  # lazy: h5py

    materials = _materials()
    model = registry.get("representations", representation_for("rusinkiewicz")).create(**QUICK_NBRDF)
    fitted = model.fit_many(list(materials), seed=0)
    vectors = np.stack([flatten(m.network.weights) for m in fitted]).astype(np.float32)
    return WeightSet(tuple(m.name for m in materials), vectors, tuple(model.hidden))


def training_data() -> TrainingData:
    """The kit's training split: synthetic tables and their aligned NBRDF weight vectors."""
    materials = {m.name: m for m in _materials()}
    return TrainingData(
        names=tuple(materials), load=materials.__getitem__,
        categories={m.name: m.category for m in materials.values()},
        weight_source=lambda names: _weights(), dataset="brdfbench.testing",
    )


@dataclass
class Context:
    spec: GeneratorSpec
    params: dict
    _model: Generator | None = None

    def fresh(self) -> Generator:
        return self.spec.create(**self.params)

    @property
    def model(self) -> Generator:
        """The generator fitted once with FIT_SEED."""
        if self._model is None:
            self._model = self.fresh().fit(training_data(), seed=FIT_SEED)
        return self._model


CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


def _arrays_equal(a: SampleSet, b: SampleSet) -> bool:
    return a.array.shape == b.array.shape and torch.equal(a.array, b.array)


@check()
def check_protocol(ctx: Context) -> None:
    cls = ctx.spec.load()
    assert isinstance(cls, type) and issubclass(cls, Generator), (
        f"{ctx.spec.target} must be a subclass of brdfbench.protocols.generator.Generator")
    assert cls.learns_from in LEARNS_FROM, f"{cls.__name__}.learns_from={cls.learns_from!r}: one of {LEARNS_FROM}"
    assert ctx.spec.learns_from == cls.learns_from, (
        f"the spec says it learns from {ctx.spec.learns_from!r}, {cls.__name__}.learns_from is {cls.learns_from!r}")
    model = ctx.fresh()
    assert isinstance(model.params, dict), "params must be a dict of constructor arguments"
    assert not model.fitted, "a new generator must report fitted=False (its state_dict empty)"


@check()
def check_unfitted_sample_refused(ctx: Context) -> None:
    try:
        ctx.fresh().sample(2, seed=0)
    except (RuntimeError, BrdfbenchError):
        return
    raise AssertionError("sample() before fit() must raise a clear error")


@check()
def check_sample_shapes(ctx: Context) -> None:
    samples = ctx.model.sample(N_SAMPLES, seed=1)
    assert isinstance(samples, SampleSet), f"sample() returned a {type(samples).__name__}, expected a SampleSet"
    assert len(samples) == N_SAMPLES and samples.array.shape[0] == N_SAMPLES, (
        f"sample({N_SAMPLES}) gave {len(samples)} samples, array {tuple(samples.array.shape)}")
    assert samples.array.dtype.is_floating_point, f"sample array has dtype {samples.array.dtype}"
    registry.get("representations", samples.representation)  # the samples' plugin is registered
    for dtype in (torch.float32, torch.float64):
        wi, wo = adversarial_pairs(64, dtype, seed=1)["uniform"]
        for i in range(N_SAMPLES):
            item = samples[i]
            assert isinstance(item, Representation), f"sample {i} is a {type(item).__name__}, not a Representation"
            out = item.eval(wi, wo)
            assert out.shape == (wi.shape[0], 3) and out.dtype == dtype, (
                f"sample {i} evaluated to {tuple(out.shape)} {out.dtype} on {dtype} pairs")


@check()
def check_sample_deterministic(ctx: Context) -> None:
    model = ctx.model
    a, b, c = model.sample(N_SAMPLES, seed=11), model.sample(N_SAMPLES, seed=11), model.sample(N_SAMPLES, seed=12)
    assert _arrays_equal(a, b), "two sample() calls with one seed differ"
    wi, wo = adversarial_pairs(512, torch.float64, seed=2)["uniform"]
    assert torch.equal(a[0].eval(wi, wo), b[0].eval(wi, wo)), "the same sample evaluates differently twice"
    assert not _arrays_equal(a, c), "sample() with seeds 11 and 12 gave the same set: the seed is ignored"


@check()
def check_samples_finite_nonnegative(ctx: Context) -> None:
    samples = ctx.model.sample(N_SAMPLES, seed=3)
    bad = (~samples.finite).nonzero().flatten().tolist()
    assert not bad, f"samples {bad} have non-finite parameters"
    for dtype in (torch.float32, torch.float64):
        for family, (wi, wo) in adversarial_pairs(7000, dtype, seed=4).items():
            for i in range(N_SAMPLES):
                out = samples[i].eval(wi, wo)
                assert torch.isfinite(out).all(), f"sample {i}: non-finite value on {family} pairs ({dtype})"
                assert (out >= 0).all(), f"sample {i}: negative value on {family} pairs ({dtype})"


@check()
def check_save_load_roundtrip(ctx: Context) -> None:
    """Saved and loaded (`roundtrip`), the generator draws the same samples for a seed."""
    def same(model: Generator, loaded: Generator) -> None:
        a, b = model.sample(N_SAMPLES, seed=5), loaded.sample(N_SAMPLES, seed=5)
        assert _arrays_equal(a, b), "the loaded generator samples differently from the saved one"

    roundtrip.check_save_load_roundtrip(ctx.model, ctx.spec.name, "generator", same)


@check()
def check_bad_sizes_refused(ctx: Context) -> None:
    model = ctx.model
    for n in (0, -1, 2.5, True, "3"):
        try:
            model.sample(n, seed=0)
        except ConfigError:
            continue
        except Exception as exc:  # noqa: BLE001 - any other exception is not the clear error asked for
            raise AssertionError(f"sample(n={n!r}) raised {type(exc).__name__}: {exc}, expected a ConfigError") from None
        raise AssertionError(f"sample(n={n!r}) was accepted")
    huge = 10**12
    try:
        model.sample(huge, seed=0)
    except ResourceError:
        return
    except MemoryError:
        raise AssertionError(f"sample(n={huge}) ran out of memory instead of being refused up front "
                             "(sample_nbytes must estimate what sampling allocates)") from None
    raise AssertionError(f"sample(n={huge}) was accepted: sample_nbytes({huge}) = {model.sample_nbytes(huge)}")


@check()
def check_fit_deterministic(ctx: Context) -> None:
    other = ctx.fresh().fit(training_data(), seed=FIT_SEED)
    assert _arrays_equal(ctx.model.sample(N_SAMPLES, seed=6), other.sample(N_SAMPLES, seed=6)), (
        f"two fits with seed {FIT_SEED} sample differently")


@check()
def check_cost_declared(ctx: Context) -> None:
    model = ctx.model
    nbytes = model.nbytes
    assert isinstance(nbytes, int) and nbytes > 0, f"a fitted generator's nbytes must be a positive int, got {nbytes!r}"
    sizes = [model.sample_nbytes(n) for n in (1, 10, 1000)]
    assert all(isinstance(s, int) and s > 0 for s in sizes), f"sample_nbytes must be positive ints, got {sizes}"
    assert sizes == sorted(sizes), f"sample_nbytes must not shrink as n grows: {sizes} for n = 1, 10, 1000"


def _places(cls: type) -> bool:
    """Whether a generator class takes part in the device protocol: declares devices beyond
    the CPU, or overrides `to` or `_move` (one that does none of these runs on the CPU and
    inherits a `to` that refuses any other device: nothing to check)."""
    return (getattr(cls, "devices", frozenset({"cpu"})) != frozenset({"cpu"})
            or getattr(cls, "to", None) is not Placed.to or getattr(cls, "_move", None) is not Placed._move)


@check()
def check_devices_declared(ctx: Context) -> None:
    """`devices` names known device types, the CPU among them; a new generator is on the CPU;
    `to` refuses an undeclared type before any work; `to("cpu")` of a fitted CPU generator
    returns it and changes none of its samples."""
    assert_declared(ctx.spec.load(), ctx.fresh())
    fitted = ctx.model
    before = fitted.sample(N_SAMPLES, seed=21)
    assert fitted.to("cpu") is fitted, "to() must return the generator itself"
    assert fitted.device == torch.device("cpu"), f"to('cpu') left the generator on {fitted.device}"
    after = fitted.sample(N_SAMPLES, seed=21)
    assert after.array.device.type == "cpu", f"a CPU generator sampled an array on {after.array.device}"
    assert _arrays_equal(before, after), "to('cpu') changed a CPU generator's samples"


def _evaluates_finite_nonnegative(samples: SampleSet, where: str) -> None:
    bad = (~samples.finite).nonzero().flatten().tolist()
    assert not bad, f"{where}: samples {bad} have non-finite parameters"
    items = [samples[i] for i in range(len(samples))]  # built once (a table sample is a full table)
    for dtype in (torch.float32, torch.float64):
        for family, (wi, wo) in adversarial_pairs(2000, dtype, seed=22).items():
            for i, item in enumerate(items):
                out = on_host(item.eval, item.device)(wi, wo)
                assert torch.isfinite(out).all(), f"{where}: sample {i} non-finite on {family} pairs ({dtype})"
                assert (out >= 0).all(), f"{where}: sample {i} negative on {family} pairs ({dtype})"


@check()
def check_device_agreement(ctx: Context) -> None:
    """Where a generator declares "cuda" and a GPU is here: the CPU-fitted generator, rebuilt
    from its state and moved to the GPU, samples there the CPU's array within
    DEVICE_SAMPLE_RTOL (same seed); a generator trained on the GPU keeps its state there,
    samples there, and its samples are finite and evaluate finite and non-negative."""
    cls = ctx.spec.load()
    if "cuda" not in cls.devices:
        raise NoDevice(f"{cls.__name__} runs on the CPU only (devices = {sorted(cls.devices)})")
    gpu = gpu_device()
    cpu_model = ctx.model
    state = {k: v.detach().cpu().clone() for k, v in cpu_model.state_dict().items()}
    moved = cls.from_state(dict(cpu_model.params), state, cpu_model.metadata()).to(gpu)
    assert moved.device.type == "cuda", f"to({gpu}) left the generator on {moved.device}"
    a, b = cpu_model.sample(N_SAMPLES, seed=31), moved.sample(N_SAMPLES, seed=31)
    assert b.array.device.type == "cuda", f"a generator on {gpu} sampled an array on {b.array.device}"
    assert a.array.shape == b.array.shape, f"GPU samples have shape {tuple(b.array.shape)}, CPU {tuple(a.array.shape)}"
    x, y = a.array.double(), b.array.cpu().double()
    scale = float(x.abs().max()) or 1.0
    worst = float((x - y).abs().max())
    assert worst <= DEVICE_SAMPLE_RTOL * scale, (
        f"the generator moved to {gpu} samples differently from the CPU one: up to {worst:.3g} apart "
        f"(arrays up to {scale:.3g}; allowed {DEVICE_SAMPLE_RTOL:g} of that)")
    trained = ctx.fresh().to(gpu).fit(training_data(), seed=FIT_SEED)
    assert trained.device.type == "cuda", f"a generator trained on {gpu} reports device {trained.device}"
    off = sorted(k for k, v in trained.state_dict().items() if v.device.type != "cuda")
    assert not off, f"a generator trained on {gpu} holds {off[:5]} on the CPU"
    samples = trained.sample(N_SAMPLES, seed=32)
    assert samples.array.device.type == "cuda", f"a generator trained on {gpu} sampled an array on {samples.array.device}"
    _evaluates_finite_nonnegative(samples, f"trained on {gpu}")


def _resolve(spec_or_name) -> GeneratorSpec:
    if isinstance(spec_or_name, GeneratorSpec):
        return spec_or_name
    return registry.get("generators", spec_or_name)


def kit_params(spec: GeneratorSpec, params: dict | None = None, full: bool = False) -> dict:
    quick = {} if full else dict(spec.kit_params)
    return {**quick, **(params or {})}


def generator_checks(spec_or_name, *, params: dict | None = None, full: bool = False) -> list[Check]:
    """The checks that apply to a generator, sharing one fitted generator between them."""
    spec = _resolve(spec_or_name)
    ctx = Context(spec, kit_params(spec, params, full))
    cls = spec.load()
    places, on_gpu = _places(cls), "cuda" in getattr(cls, "devices", ())
    skipped = {"devices_declared"} if not places else set()
    if not on_gpu:  # a CPU-only generator: nothing to compare across devices
        skipped.add("device_agreement")
    return [Check(spec.name, name, (lambda fn=fn: fn(ctx)), spec.xfail_checks.get(name))
            for name, (requires, fn) in CHECKS.items() if requires <= spec.tags and name not in skipped]


def check_generator(spec_or_name, *, params: dict | None = None, full: bool = False) -> ConformanceReport:
    """Run every applicable check; failures are collected, not raised (see raise_on_failure)."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name, params=kit_params(spec, params, full))
    for c in generator_checks(spec, params=params, full=full):
        report.run(c)
    return report
