"""Conformance checks for representation plugins and the machinery that runs them."""

from __future__ import annotations

import tempfile
import traceback
import unittest
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable

import torch

from .. import modelio
from ..plugins import registry
from ..protocols.representation import Material, Representation
from ..plugins.specs import RepresentationSpec
from . import roundtrip
from .adversarial import adversarial_pairs
from .checks import CheckSet
from .devices import assert_declared, DEVICE_EVAL_RTOL, DEVICE_FIT_ABS, DEVICE_FIT_REL, gpu as gpu_device, NoDevice
from ..data.synthetic import generate_material
from ..errors import BrdfbenchError
from ..pipeline import fit_pool
from ..threads import torch_threads

DTYPES = (torch.float32, torch.float64)
DEFAULT_PAIRS = 10**6
#: Seed of every fit the kit makes, so the shared model is also one side of the determinism check.
FIT_SEED = 7


@lru_cache(maxsize=1)
def reference_material() -> Material:
    """A measured-like target with a specular lobe, generated in memory (synthetic material 1)."""
    name, category, table = generate_material(1, seed=0)
    return Material(name=name, table=table, category=category, source="brdfbench.data.synthetic")


#: Synthetic materials a `needs_training` plugin trains on; the reference material is not among them.
TRAINING_INDICES = range(2, 8)


def training_materials():
    """The training split for plugins that need one, generated lazily (one table in memory at a time)."""
    for i in TRAINING_INDICES:
        name, category, table = generate_material(i, seed=0)
        yield Material(name=name, table=table, category=category, source="brdfbench.data.synthetic")


@dataclass
class Context:
    spec: RepresentationSpec
    params: dict
    n_pairs: int
    _model: Representation | None = None

    def fresh(self) -> Representation:
        """A new model; one that needs training comes trained on `training_materials()`."""
        model = self.spec.create(**self.params)
        if model.needs_training:
            model.train(training_materials(), seed=0)
        return model

    @property
    def model(self) -> Representation:
        """A model fitted once to the reference material with FIT_SEED (or unfitted, if not fittable)."""
        if self._model is None:
            model = self.fresh()
            if "fittable" in self.spec.tags:
                model.fit(reference_material(), seed=FIT_SEED)
            self._model = model
        return self._model


# --------------------------------------------------------------------------- checks

CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


@check()
def check_protocol(ctx: Context) -> None:
    cls = ctx.spec.load()
    assert isinstance(cls, type) and issubclass(cls, Representation), (
        f"{ctx.spec.target} must be a subclass of brdfbench.protocols.representation.Representation"
    )
    missing = {"fittable", "reciprocal", "isotropic", "needs_training"} & ctx.spec.tags - cls.tags
    assert not missing, f"spec tags {sorted(missing)} are not declared on {cls.__name__}.tags"
    assert cls.needs_training == ("needs_training" in ctx.spec.tags), (
        f"{cls.__name__}.needs_training={cls.needs_training} disagrees with the spec's 'needs_training' tag"
    )
    model = ctx.spec.create(**ctx.params)  # constructed only: training is not what this checks
    assert isinstance(model.params, dict), "params must be a dict of constructor arguments"


@check()
def check_eval_shapes_and_dtypes(ctx: Context) -> None:
    model = ctx.model
    for dtype in DTYPES:
        pairs = adversarial_pairs(64, dtype, seed=1)["uniform"]
        out = model.eval(*pairs)
        assert out.shape == (pairs[0].shape[0], 3), f"eval returned shape {tuple(out.shape)}, expected (N, 3)"
        assert out.dtype == dtype, f"eval on {dtype} returned {out.dtype}"
        empty = model.eval(torch.zeros(0, 3, dtype=dtype), torch.zeros(0, 3, dtype=dtype))
        assert empty.shape == (0, 3), f"eval on no pairs returned shape {tuple(empty.shape)}"


@check()
def check_adversarial_finite_nonnegative(ctx: Context) -> None:
    model = ctx.model
    for dtype in DTYPES:
        for family, (wi, wo) in adversarial_pairs(ctx.n_pairs, dtype, seed=2).items():
            out = model.eval(wi, wo)
            bad = ~torch.isfinite(out).all(dim=1)
            assert not bad.any(), _first_fault(f"non-finite value ({family}, {dtype})", wi, wo, out, bad)
            neg = (out < 0).any(dim=1)
            assert not neg.any(), _first_fault(f"negative value ({family}, {dtype})", wi, wo, out, neg)


@check()
def check_zero_below_horizon(ctx: Context) -> None:
    wi, wo = adversarial_pairs(ctx.n_pairs, torch.float64, seed=3)["below_horizon"]
    out = ctx.model.eval(wi, wo)
    nonzero = (out != 0).any(dim=1)
    assert not nonzero.any(), _first_fault("non-zero value at or below the horizon", wi, wo, out, nonzero)


@check("reciprocal")
def check_reciprocity(ctx: Context) -> None:
    wi, wo = adversarial_pairs(20_000, torch.float64, seed=4)["uniform"]
    a, b = ctx.model.eval(wi, wo), ctx.model.eval(wo, wi)
    bad = ~torch.isclose(a, b, rtol=1e-5, atol=1e-8).all(dim=1)
    assert not bad.any(), _first_fault("f(wi, wo) != f(wo, wi)", wi, wo, a - b, bad)


@check("isotropic")
def check_isotropy(ctx: Context) -> None:
    wi, wo = adversarial_pairs(20_000, torch.float64, seed=5)["uniform"]
    angle = torch.tensor(0.7318, dtype=torch.float64)
    c, s = torch.cos(angle), torch.sin(angle)
    rot = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    a, b = ctx.model.eval(wi, wo), ctx.model.eval(wi @ rot.T, wo @ rot.T)
    bad = ~torch.isclose(a, b, rtol=1e-5, atol=1e-8).all(dim=1)
    # Tabulated lookups may land in a neighbouring cell when a pair sits on a cell boundary.
    allowed = 1e-3 * wi.shape[0] if "tabulated" in ctx.spec.tags else 0
    assert bad.sum() <= allowed, _first_fault("value changes under a rotation about the normal", wi, wo, a - b, bad)


@check("fittable")
def check_fit_deterministic(ctx: Context) -> None:
    """A fresh fit with FIT_SEED must equal the shared model, fitted the same way earlier
    (the fit the other checks need serves as one of the two)."""
    a = ctx.model
    b = ctx.fresh().fit(reference_material(), seed=FIT_SEED)
    wi, wo = adversarial_pairs(4096, torch.float64, seed=6)["uniform"]
    va, vb = a.eval(wi, wo), b.eval(wi, wo)
    assert torch.equal(va, vb), f"two fits with seed {FIT_SEED} differ by up to {float((va - vb).abs().max()):.3g}"


@check()
def check_save_load_roundtrip(ctx: Context) -> None:
    """Saved and loaded (`roundtrip`), the model evaluates bit for bit as before, in each dtype."""
    def same(model: Representation, loaded: Representation) -> None:
        for dtype in DTYPES:
            wi, wo = adversarial_pairs(4096, dtype, seed=8)["uniform"]
            a, b = model.eval(wi, wo), loaded.eval(wi, wo)
            assert torch.equal(a, b), f"loaded model differs by up to {float((a - b).abs().max()):.3g} ({dtype})"

    roundtrip.check_save_load_roundtrip(ctx.model, ctx.spec.name, "model", same)


def _broken_states(state: dict[str, torch.Tensor]):
    """(what, tensors) pairs: the fitted state with one floating-point tensor spoilt, each way
    a file from elsewhere may be: a NaN, an infinity, one value too many on the last axis."""
    for name, t in state.items():
        if not isinstance(t, torch.Tensor) or not t.dtype.is_floating_point or t.numel() == 0:
            continue
        flat = t.detach().to("cpu").contiguous()
        for what, value in (("a NaN", float("nan")), ("+Inf", float("inf"))):
            spoilt = flat.clone().reshape(-1)
            spoilt[spoilt.numel() // 2] = value
            yield f"tensor {name!r} holding {what}", {**state, name: spoilt.reshape(flat.shape)}
        shape = (*flat.shape[:-1], flat.shape[-1] + 1) if flat.ndim else (2,)
        grown = torch.cat([flat.reshape(-1), flat.reshape(-1)[:1]]) if flat.ndim <= 1 else \
            torch.cat([flat, flat[..., :1]], dim=-1)
        yield f"tensor {name!r} of shape {tuple(shape)} (saved: {tuple(flat.shape)})", {**state, name: grown.reshape(shape)}


@check()
def check_load_refuses_broken_state(ctx: Context) -> None:
    """A model file is data from anywhere: `from_state` must refuse NaN, infinite and misshapen
    tensors (brdfbench.state_checks.expect_tensor does it), and the refusal must name the file."""
    from safetensors.torch import load_file, save_file
    from safetensors import safe_open

    with tempfile.TemporaryDirectory() as tmp:
        good = modelio.save(ctx.model, ctx.spec.name, Path(tmp) / "model.safetensors")
        with safe_open(str(good), framework="pt") as f:
            header = f.metadata()
        state = load_file(str(good))
        cases = list(_broken_states(state))
        if not cases:
            raise unittest.SkipTest("the fitted model saves no floating-point tensor")
        for i, (what, tensors) in enumerate(cases):
            path = Path(tmp) / f"broken-{i}.safetensors"
            save_file({k: v.contiguous() for k, v in tensors.items()}, str(path), metadata=header)
            try:
                modelio.load(path)
            except Exception as exc:  # noqa: BLE001 - any refusal, as long as it is a clear one

                assert isinstance(exc, BrdfbenchError), (
                    f"a file with {what} raised {type(exc).__name__} ({exc}), not a ModelFileError naming the file")
                assert str(path) in str(exc), f"the refusal of a file with {what} does not name the file: {exc}"
            else:
                raise AssertionError(f"a file with {what} was loaded; from_state must check the tensors it is given "
                                     "(brdfbench.state_checks.expect_tensor)")


def _log_error(model: Representation, wi: torch.Tensor, wo: torch.Tensor, ref: torch.Tensor) -> float:
    """Mean |log(1 + f cos θi) − log(1 + ref cos θi)| of a model at host pairs."""
    device = model.device
    f = model.eval(wi.to(device), wo.to(device)).cpu()
    cos = wi[:, 2:3]
    return float((torch.log1p(f * cos) - torch.log1p(ref * cos)).abs().mean())


@check()
def check_devices_declared(ctx: Context) -> None:
    """`devices` names known device types, the CPU among them; `to` refuses an undeclared
    type before any work, and `to("cpu")` of a fitted CPU model changes nothing."""
    assert_declared(ctx.spec.load(), ctx.spec.create(**ctx.params))
    fitted = ctx.model
    wi, wo = adversarial_pairs(4096, torch.float64, seed=11)["uniform"]
    before = fitted.eval(wi, wo)
    assert fitted.to("cpu") is fitted, "to() must return the model itself"
    after = fitted.eval(wi, wo)
    assert torch.equal(before, after), f"to('cpu') changed a CPU model's values by up to {float((before - after).abs().max()):.3g}"


@check()
def check_device_agreement(ctx: Context) -> None:
    """Where a plugin declares "cuda" (and a GPU is here): the CPU-fitted model moved to the
    GPU evaluates GPU inputs there, in their dtype, within DEVICE_EVAL_RTOL of its CPU
    values; a model fitted (and trained) on the GPU scores the reference material as the
    CPU fit does, within DEVICE_FIT_REL."""
    cls = ctx.spec.load()
    if "cuda" not in cls.devices:
        raise NoDevice(f"{cls.__name__} runs on the CPU only (devices = {sorted(cls.devices)})")
    gpu = gpu_device()
    cpu_model = ctx.model
    moved = cls.from_state(dict(cpu_model.params), {k: v.detach().cpu().clone() for k, v in cpu_model.state_dict().items()},
                           cpu_model.metadata()).to(gpu)
    assert moved.device.type == "cuda", f"to({gpu}) left the model on {moved.device}"
    for dtype in DTYPES:
        wi, wo = adversarial_pairs(20_000, dtype, seed=12)["uniform"]
        a = cpu_model.eval(wi, wo)
        b = moved.eval(wi.to(gpu), wo.to(gpu))
        assert b.device.type == "cuda", f"eval of {gpu} inputs returned values on {b.device}"
        assert b.dtype == dtype, f"eval on {dtype} ({gpu}) returned {b.dtype}"
        b = b.cpu()
        scale = float(a.abs().max()) or 1.0
        bad = ~torch.isclose(a, b, rtol=DEVICE_EVAL_RTOL, atol=DEVICE_EVAL_RTOL * 1e-3 * scale).all(dim=1)
        assert not bad.any(), _first_fault(f"GPU evaluation differs from the CPU one ({dtype})", wi, wo, b - a, bad)
    if "fittable" not in ctx.spec.tags:
        return
    model = ctx.spec.create(**ctx.params).to(gpu)
    if model.needs_training:
        model.train(training_materials(), seed=0)
    fitted = model.fit(reference_material(), seed=FIT_SEED)
    assert fitted.device.type == "cuda", f"a model fitted on {gpu} reports device {fitted.device}"
    table = reference_material().table
    wi, wo = adversarial_pairs(50_000, torch.float64, seed=13)["uniform"]
    ref = table.lookup(wi, wo)
    keep = (ref >= 0).all(dim=1)
    wi, wo, ref = wi[keep].float(), wo[keep].float(), ref[keep].float()
    on_cpu, on_gpu = _log_error(cpu_model, wi, wo, ref), _log_error(fitted, wi, wo, ref)
    assert abs(on_gpu - on_cpu) <= DEVICE_FIT_REL * on_cpu + DEVICE_FIT_ABS, (
        f"the GPU fit scores {on_gpu:.4g} (mean log error on the reference material), the CPU fit {on_cpu:.4g}")


@check("fittable")
def check_fit_in_a_helper(ctx: Context) -> None:
    """Where the class declares `fits_in_parallel`: its fit in a fresh single-threaded helper
    process (as the runner makes it, `fit_workers`) evaluates bit for bit as the shared model
    fitted here, with this process on two torch threads: a fit that depends on the caller's
    thread count or process state must not declare it."""
    cls = ctx.spec.load()
    if not getattr(cls, "fits_in_parallel", False):
        raise unittest.SkipTest(f"{cls.__name__} does not fit side by side (fits_in_parallel is not set)")
    if cls.needs_training:
        raise unittest.SkipTest(f"{cls.__name__} trains on a split: its fits are never side by side")
    with torch_threads(2):
        here = ctx.fresh().fit(reference_material(), seed=FIT_SEED)
    [(ok, there)], _ = fit_pool.fit_parallel(ctx.spec.create(**ctx.params), [reference_material()], FIT_SEED, 1)
    if not ok:
        raise AssertionError(f"the fit failed in a helper process: {type(there).__name__}: {there}")
    wi, wo = adversarial_pairs(4096, torch.float64, seed=14)["uniform"]
    a, b = here.eval(wi, wo), there.eval(wi, wo)
    assert torch.equal(a, b), (f"the fit in a helper process differs from the fit here by up to "
                               f"{float((a - b).abs().max()):.3g}: fits_in_parallel would change the figures")


@check()
def check_cost_declared(ctx: Context) -> None:
    nbytes = ctx.model.nbytes
    assert isinstance(nbytes, int) and nbytes >= 0, f"nbytes must be a non-negative int, got {nbytes!r}"
    flops = ctx.model.flops_per_eval
    assert flops is None or (isinstance(flops, int) and flops > 0), f"flops_per_eval must be None or a positive int, got {flops!r}"


def _first_fault(what: str, wi, wo, out, mask) -> str:
    i = int(torch.nonzero(mask)[0])
    return (
        f"{what}: {int(mask.sum())} of {mask.numel()} pairs, first wi={wi[i].tolist()} "
        f"wo={wo[i].tolist()} -> {out[i].tolist()}"
    )


# --------------------------------------------------------------------------- running


@dataclass(frozen=True)
class Check:
    """One check bound to one plugin; call it to run (raises on failure)."""

    spec_name: str
    name: str
    run: Callable[[], None]
    xfail_reason: str | None = None

    def __call__(self) -> None:
        self.run()

    def __str__(self) -> str:
        return f"{self.spec_name}-{self.name}"


@dataclass
class ConformanceReport:
    plugin: str
    outcomes: dict[str, str] = field(default_factory=dict)  # check -> passed/failed/xfailed/xpassed
    details: dict[str, str] = field(default_factory=dict)
    params: dict = field(default_factory=dict)  # the constructor arguments the checks used

    @property
    def passed(self) -> bool:
        return not any(v in ("failed", "xpassed") for v in self.outcomes.values())

    def summary(self) -> str:
        lines = [f"conformance of {self.plugin!r}" + (f" with {self.params}" if self.params else "") + ":"]
        for name, outcome in self.outcomes.items():
            lines.append(f"  {outcome:8s} {name}")
            if name in self.details:
                lines.append("           " + self.details[name].replace("\n", "\n           "))
        counts = {k: list(self.outcomes.values()).count(k) for k in ("passed", "failed", "xfailed", "xpassed", "skipped")}
        lines.append(", ".join(f"{v} {k}" for k, v in counts.items() if v) or "no checks ran")
        return "\n".join(lines)

    def run(self, check: Check, skip: tuple[type[BaseException], ...] = ()) -> None:
        """Run one check and record its outcome; an exception of a `skip` type marks it skipped."""
        try:
            check()
        except unittest.SkipTest as exc:  # a device the check needs is not here
            self.outcomes[check.name] = "skipped"
            self.details[check.name] = str(exc)
        except skip as exc:
            self.outcomes[check.name] = "skipped"
            self.details[check.name] = f"not resolvable: {exc}"
        except Exception as exc:  # noqa: BLE001 - a check reports any fault of the plugin
            self.outcomes[check.name] = "xfailed" if check.xfail_reason else "failed"
            detail = str(exc) if isinstance(exc, AssertionError) else "".join(traceback.format_exception_only(type(exc), exc))
            self.details[check.name] = (f"expected: {check.xfail_reason}; " if check.xfail_reason else "") + detail.strip()
        else:
            self.outcomes[check.name] = "xpassed" if check.xfail_reason else "passed"
            if check.xfail_reason:
                self.details[check.name] = f"declared expected failure ({check.xfail_reason}) but it passed"

    def raise_on_failure(self) -> "ConformanceReport":
        if not self.passed:
            raise AssertionError(self.summary())
        return self


def _resolve(spec_or_name: RepresentationSpec | str) -> RepresentationSpec:
    if isinstance(spec_or_name, RepresentationSpec):
        return spec_or_name
    return registry.get("representations", spec_or_name)


def kit_params(spec: RepresentationSpec, params: dict | None = None, full: bool = False) -> dict:
    """The constructor arguments the kit uses: the spec's quick `kit_params` unless `full`,
    overridden by `params`."""
    quick = {} if full else dict(getattr(spec, "kit_params", {}))
    return {**quick, **(params or {})}


def representation_checks(spec_or_name, *, params: dict | None = None, n_pairs: int = DEFAULT_PAIRS,
                          full: bool = False) -> list[Check]:
    """The checks that apply to a representation, sharing one fitted model between them; see
    `kit_params` for what `params` and `full` select."""
    spec = _resolve(spec_or_name)
    ctx = Context(spec, kit_params(spec, params, full), n_pairs)
    on_gpu = "cuda" in getattr(spec.load(), "devices", ())
    return [
        Check(spec.name, name, (lambda fn=fn: fn(ctx)), spec.xfail_checks.get(name))
        for name, (requires, fn) in CHECKS.items()
        if requires <= spec.tags and (on_gpu or name != "device_agreement")  # CPU-only plugins: nothing to compare
    ]


def check_representation(spec_or_name, *, params: dict | None = None, n_pairs: int = DEFAULT_PAIRS,
                         full: bool = False) -> ConformanceReport:
    """Run every applicable check; failures are collected, not raised (see raise_on_failure)."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name, params=kit_params(spec, params, full))
    for c in representation_checks(spec, params=params, n_pairs=n_pairs, full=full):
        report.run(c)
    return report

