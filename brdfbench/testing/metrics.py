"""Conformance checks for metric plugins, in the style of `check_representation`.

    from brdfbench.testing import check_metric
    check_metric("my_metric").raise_on_failure()

The metric's `domain` (`brdfbench.protocols.metric`) says what the kit feeds it, as its
harness does: BRDF values (N, 3) with cos θi (`merl_grid`, `random_pairs`), HDR images
(`image`: radiance reaching past 1, so tone mapping clips; single images (H, W, 3) and
batches), distance matrices of two point sets (`set`), two sets of images (`image_set`).

Checks: the class and spec agree on unit and direction; the domain is one a harness
feeds; the class builds as its harness builds it; identical inputs score the ideal value
(0 for a lower-is-better streaming distance; for a higher-is-better one, the same value
whatever the content; for a set metric, no worse than a set drawn like R); the score is
monotone in the error (streaming) or ranks a set near R above one far from it (set);
finite on finite inputs (zeros, cos θi = 0, 1e4 and 1e-30 values, black and very bright
images; an image metric may refuse an all-black target with a clear error); chunks,
single images and merged states give one update's value within rounding; `reset`
forgets; `compute` before any update (or after a reset) is refused with a clear error;
the value is deterministic; a set metric takes sets of unequal sizes and leaves its
matrices unchanged. An `image_set` metric computes through a model of its own (FID's
InceptionV3), so `image_set_scores` runs with `full=True` only and is reported skipped
otherwise.
"""

from __future__ import annotations

import math
import unittest
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..plugins import registry
from ..errors import BrdfbenchError
from ..protocols.metric import DOMAINS, STREAMING
from ..plugins.specs import MetricSpec
from .checks import CheckSet
from .kit import Check, ConformanceReport

#: Relative difference a chunked, merged or per-image stream may have from one update (float64 rounding).
CHUNK_RTOL = 1e-9
#: |value| a lower-is-better streaming metric may have on identical inputs.
IDEAL_ATOL = 1e-12
CHUNKS = 7
#: Which checks apply to a domain: "scored" where the kit makes the inputs ("brdf" and
#: "image" streams, "set" distance matrices); "image_set" metrics compute through a model.
DOMAIN_TAGS = {"merl_grid": {"scored", "streaming", "brdf"}, "random_pairs": {"scored", "streaming", "brdf"},
               "image": {"scored", "streaming", "image"}, "set": {"scored", "set"}, "image_set": {"image_set"}}


def _data(n: int = 4096, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(n, 3, generator=g, dtype=torch.float64) * 10
    cos_i = torch.rand(n, generator=g, dtype=torch.float64)
    noise = torch.rand(n, 3, generator=g, dtype=torch.float64)
    return target, cos_i, noise


def _images(n: int = 8, size: int = 24, seed: int = 0):
    """Smooth HDR images with texture (radiance in [0, 1.5)) and a multiplicative noise field."""
    g = torch.Generator().manual_seed(seed)
    ramp = torch.linspace(0.1, 1.0, size, dtype=torch.float64)
    albedo = torch.rand(n, 1, 1, 3, generator=g, dtype=torch.float64)
    shade = (ramp[:, None] * ramp.flip(0)[None, :])[None, :, :, None] * albedo
    target = 1.5 * (0.7 * shade + 0.3 * torch.rand(n, size, size, 3, generator=g, dtype=torch.float64))
    noise = torch.rand(n, size, size, 3, generator=g, dtype=torch.float64)
    return target, None, noise


def _point_sets(n: int = 24, shift: float = 0.0, seed: int = 0, m: int | None = None):
    """Two point clouds in R⁴ (n and m points), the second shifted by `shift`, and their L1
    distance matrices R×R, S×S, R×S."""
    g = torch.Generator().manual_seed(seed)
    r = torch.randn(n, 4, generator=g, dtype=torch.float64)
    s = torch.randn(n if m is None else m, 4, generator=g, dtype=torch.float64) + shift
    d = lambda a, b: torch.cdist(a, b, p=1).numpy()  # noqa: E731
    return d(r, r), d(s, s), d(r, s)


@dataclass
class Context:
    spec: MetricSpec
    full: bool = False

    @property
    def cls(self) -> type:
        return self.spec.load()

    @property
    def domain(self) -> Any:
        return getattr(self.cls, "domain", None)

    def make(self):
        return self.cls()

    @property
    def better(self):
        return (lambda a, b: a > b) if self.spec.higher_is_better else (lambda a, b: a < b)

    def inputs(self, seed: int = 0):
        """(target, cos_i or None, noise) of the metric's streaming domain."""
        return _images(seed=seed) if self.domain == "image" else _data(seed=seed)

    def stream(self, pred, target, cos_i=None, chunks: int = 1, metric=None):
        """The value of a (fresh, unless given) metric updated with `pred` against `target` in `chunks` parts."""
        m = self.make() if metric is None else metric
        for part in range(chunks):
            s = slice(part * len(pred) // chunks, (part + 1) * len(pred) // chunks)
            self.update(m, pred[s], target[s], None if cos_i is None else cos_i[s])
        return m.compute()

    def update(self, m, pred, target, cos_i=None) -> None:
        if self.domain == "image":
            m.update(pred, target)
        else:
            m.update(pred, target, cos_i)

    def where(self, check: str) -> str:
        return f"metric {self.spec.name!r}, {check}"


CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


def _close(a: float, b: float, rtol: float = CHUNK_RTOL) -> bool:
    return abs(a - b) <= rtol * max(1.0, abs(a), abs(b))


@check()
def check_spec_agrees(ctx: Context) -> None:
    """The class's unit and direction are the spec's: reports read the spec, harnesses the class."""
    metric = ctx.make()
    w = ctx.where("spec_agrees")
    assert metric.unit == ctx.spec.unit, f"{w}: class unit {metric.unit!r} != spec unit {ctx.spec.unit!r}"
    assert isinstance(metric.higher_is_better, bool), (
        f"{w}: higher_is_better must be a bool, got {metric.higher_is_better!r}")
    assert metric.higher_is_better == ctx.spec.higher_is_better, (
        f"{w}: class says higher_is_better={metric.higher_is_better}, spec says {ctx.spec.higher_is_better}")


@check()
def check_domain_known(ctx: Context) -> None:
    """A domain a harness feeds, and the methods that domain calls."""
    w = ctx.where("domain_known")
    domain = ctx.domain
    assert domain in DOMAINS, f"{w}: domain {domain!r} is none a harness feeds; one of {', '.join(DOMAINS)}"
    needed = ("update", "compute", "reset") if domain in STREAMING else ("compute",)
    missing = [m for m in needed if not callable(getattr(ctx.cls, m, None))]
    assert not missing, f"{w}: a {domain!r} metric needs {', '.join(needed)}; {ctx.cls.__name__} lacks {', '.join(missing)}"


@check()
def check_constructs(ctx: Context) -> None:
    """Built without arguments, as the registry and the generation harness build it; an image
    metric also with `exposure=` (in stops), as the render harness builds it."""
    w = ctx.where("constructs")
    try:
        ctx.cls()
    except Exception as exc:  # noqa: BLE001 - any failure to build is the fault
        raise AssertionError(f"{w}: {ctx.cls.__name__}() raised {type(exc).__name__}: {exc}") from None
    if ctx.domain == "image":
        try:
            ctx.cls(exposure=0.0)
        except Exception as exc:  # noqa: BLE001
            raise AssertionError(f"{w}: {ctx.cls.__name__}(exposure=0.0), as the render harness builds it, raised "
                                 f"{type(exc).__name__}: {exc}") from None


@check("scored")
def check_ideal_on_identical(ctx: Context) -> None:
    """A lower-is-better streaming distance scores 0 on identical inputs; a higher-is-better
    one its ideal, the same value whatever the content; a set metric scores S = R no worse
    than a set drawn from R's distribution."""
    w = ctx.where("ideal_on_identical")
    if ctx.domain == "set":
        d_rr = _point_sets(seed=0)[0]
        same = float(ctx.make().compute(d_rr, d_rr.copy(), d_rr.copy()))
        near = float(ctx.make().compute(*_point_sets(shift=0.0)))
        assert not ctx.better(near, same), f"{w}: S = R scored {same}, a set drawn like R {near}"
        return
    target, cos_i, _ = ctx.inputs(seed=0)
    ideal = ctx.stream(target, target, cos_i)
    if not ctx.spec.higher_is_better:
        assert abs(ideal) <= IDEAL_ATOL, f"{w}: identical inputs score {ideal!r}, not 0"
        return
    other, cos_other, _ = ctx.inputs(seed=1)
    again = ctx.stream(2 * other, 2 * other, cos_other)
    assert _close(ideal, again), f"{w}: identical inputs score {ideal!r} on one set and {again!r} on another"


@check("streaming")
def check_monotone_in_error(ctx: Context) -> None:
    target, cos_i, noise = ctx.inputs()
    perfect = ctx.stream(target, target, cos_i)
    slightly = ctx.stream(target * (1 + 0.05 * noise), target, cos_i)
    badly = ctx.stream(target * (1 + 2 * noise), target, cos_i)
    assert ctx.better(perfect, slightly) and ctx.better(slightly, badly), (
        f"{ctx.where('monotone_in_error')}: not monotone in error: perfect={perfect}, 5% off={slightly}, "
        f"200% off={badly}")


@check("set")
def check_ranks_near_above_far(ctx: Context) -> None:
    """A set from R's distribution scores better than one far from it."""
    near, far = ctx.make().compute(*_point_sets(shift=0.0)), ctx.make().compute(*_point_sets(shift=6.0))
    assert ctx.better(near, far), (
        f"{ctx.where('ranks_near_above_far')}: a set from R's distribution scored {near}, a set far from it {far}")


def _hard_brdf_cases():
    """(what, pred, target, cos_i): values a model and a table both produce."""
    target, cos_i, noise = _data(n=512, seed=3)
    zero, ones = torch.zeros_like(target), torch.ones_like(cos_i)
    half = target.clone()
    half[::2] = 0
    return [
        ("zero prediction and target", zero, zero, cos_i),
        ("zero target", target, zero, cos_i),
        ("zero prediction", zero, target, cos_i),
        ("target zero in half the rows", target * (1 + noise), half, cos_i),
        ("cos_i = 0", target * (1 + noise), target, 0 * ones),
        ("cos_i = 1", target * (1 + noise), target, ones),
        ("values of 1e4", 1e4 * (1 + noise), 1e4 * torch.ones_like(target), cos_i),
        ("values of 1e-30", 1e-30 * (1 + noise), 1e-30 * torch.ones_like(target), cos_i),
    ]


def _hard_image_cases():
    """(what, pred, target, None, refusal allowed): black, half-black and very bright images."""
    target, _, noise = _images(n=3, size=16, seed=3)
    black = torch.zeros_like(target)
    half = target.clone()
    half[:, : target.shape[1] // 2] = 0
    return [
        ("black prediction", black, target, None, False),
        ("target black in half of each image", target * (1 + noise), half, None, False),
        ("radiance of 1e4", 1e4 * (1 + noise), target, None, False),
        ("black prediction and target", black, black, None, True),
    ]


@check("scored")
def check_finite_on_finite_inputs(ctx: Context) -> None:
    """Finite on zeros, cos θi = 0, 1e4 and 1e-30 values (BRDF values); on black, half-black
    and very bright images, where an all-black target (no data range) may be refused with a
    clear error, never scored NaN; on coincident points (every distance 0) and far sets."""
    w = ctx.where("finite_on_finite_inputs")
    if ctx.domain == "set":
        zeros = np.zeros((6, 6))
        cases = [("coincident points", (zeros, zeros.copy(), zeros.copy())),
                 ("sets 1e6 apart", _point_sets(shift=1e6)), ("identical sets", (_point_sets()[0],) * 3)]
        for what, mats in cases:
            value = ctx.make().compute(*(m.copy() for m in mats))
            assert math.isfinite(float(value)), f"{w}: {what} scores {value!r}"
        return
    if ctx.domain == "image":
        cases = _hard_image_cases()
    else:
        cases = [(what, pred, target, cos_i, False) for what, pred, target, cos_i in _hard_brdf_cases()]
    for what, pred, target, cos_i, may_refuse in cases:
        try:
            value = ctx.stream(pred, target, cos_i)
        except (ValueError, BrdfbenchError) as exc:
            if may_refuse and str(exc):
                continue
            raise AssertionError(f"{w}: {what} refused: {type(exc).__name__}: {exc}") from None
        assert isinstance(value, (int, float)) and math.isfinite(value), f"{w}: {what} scores {value!r}"


@check("streaming")
def check_chunking_invariant(ctx: Context) -> None:
    """Updating in chunks (and, for images, one image (H, W, 3) at a time, as the render
    harness does) gives one update's value within rounding."""
    w = ctx.where("chunking_invariant")
    target, cos_i, noise = ctx.inputs()
    pred = target * (1 + 2 * noise)
    whole = ctx.stream(pred, target, cos_i)
    chunked = ctx.stream(pred, target, cos_i, chunks=CHUNKS)
    assert _close(chunked, whole), f"{w}: {CHUNKS} chunks score {chunked!r}, one update {whole!r}"
    if ctx.domain == "image":
        m = ctx.make()
        for i in range(len(pred)):
            m.update(pred[i], target[i])
        single = m.compute()
        assert _close(single, whole), f"{w}: image by image (H, W, 3) scores {single!r}, one batch {whole!r}"


@check("streaming")
def check_merge_invariant(ctx: Context) -> None:
    """Two instances' merged states score as one instance that saw both halves."""
    if not callable(getattr(ctx.cls, "merge", None)):
        raise unittest.SkipTest(f"{ctx.cls.__name__} has no merge (brdfbench.protocols.metric.StreamingMean has one)")
    w = ctx.where("merge_invariant")
    target, cos_i, noise = ctx.inputs()
    pred = target * (1 + 2 * noise)
    whole = ctx.stream(pred, target, cos_i)
    half = len(pred) // 3
    a, b = ctx.make(), ctx.make()
    ctx.update(a, pred[:half], target[:half], None if cos_i is None else cos_i[:half])
    ctx.update(b, pred[half:], target[half:], None if cos_i is None else cos_i[half:])
    merged = a.merge(b)
    value = (a if merged is None else merged).compute()
    assert _close(value, whole), f"{w}: merged halves score {value!r}, one update {whole!r}"


@check("streaming")
def check_reset_forgets(ctx: Context) -> None:
    w = ctx.where("reset_forgets")
    target, cos_i, noise = ctx.inputs(seed=0)
    other, cos_other, _ = ctx.inputs(seed=1)
    m = ctx.make()
    ctx.update(m, target * (1 + 2 * noise), target, cos_i)
    m.reset()
    after = ctx.stream(other * 1.5, other, cos_other, metric=m)
    fresh = ctx.stream(other * 1.5, other, cos_other)
    assert _close(after, fresh), f"{w}: after reset() it scores {after!r}, a fresh instance {fresh!r}"


def _refused(ctx: Context, m, when: str) -> None:
    w = ctx.where("compute_before_update_refused")
    try:
        value = m.compute()
    except (ValueError, RuntimeError, BrdfbenchError) as exc:
        assert str(exc), f"{w}: compute() {when} raised {type(exc).__name__} with no message"
        return
    except Exception as exc:  # noqa: BLE001 - an accident (0/0), not a refusal
        raise AssertionError(f"{w}: compute() {when} raised {type(exc).__name__} ({exc}), not a clear ValueError "
                             "saying nothing was scored") from None
    raise AssertionError(f"{w}: compute() {when} returned {value!r}; it must raise a clear error (nothing was scored)")


@check("streaming")
def check_compute_before_update_refused(ctx: Context) -> None:
    """A figure of nothing is refused, not reported as 0 (a perfect score of a lower-is-better metric)."""
    _refused(ctx, ctx.make(), "before any update")
    target, cos_i, _ = ctx.inputs()
    m = ctx.make()
    ctx.update(m, target * 1.5, target, cos_i)
    m.reset()
    _refused(ctx, m, "after reset()")


@check("scored")
def check_deterministic(ctx: Context) -> None:
    w = ctx.where("deterministic")
    if ctx.domain == "set":
        a, b = ctx.make().compute(*_point_sets()), ctx.make().compute(*_point_sets())
        assert a == b, f"{w}: the same sets scored {a!r} then {b!r}"
        return
    target, cos_i, noise = ctx.inputs()
    pred = target * (1 + 2 * noise)
    a, b = ctx.stream(pred, target, cos_i), ctx.stream(pred, target, cos_i)
    assert a == b, f"{w}: the same inputs scored {a!r} then {b!r}"


@check("set")
def check_set_shapes_contract(ctx: Context) -> None:
    """`compute(d_rr, d_ss, d_rs)` takes float64 matrices (n_r, n_r), (n_s, n_s), (n_r, n_s) of
    unequal set sizes, returns a real number and leaves the matrices (shared by every set
    metric of a draw) unchanged."""
    w = ctx.where("set_shapes_contract")
    for n, m in ((24, 17), (5, 30)):
        mats = _point_sets(n=n, m=m, shift=0.5)
        kept = [x.copy() for x in mats]
        value = ctx.make().compute(*mats)
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise AssertionError(f"{w}: compute returned {type(value).__name__} {value!r}, not a number") from None
        assert math.isfinite(number), f"{w}: |R| = {n}, |S| = {m} scores {value!r}"
        for name, before, after in zip(("d_rr", "d_ss", "d_rs"), kept, mats):
            assert np.array_equal(before, after), f"{w}: compute changed its input {name} (|R| = {n}, |S| = {m})"


@check("image_set")
def check_image_set_scores(ctx: Context) -> None:
    """Two small image sets score a finite number, the same twice; S = R scores no worse
    than a set of other images. Full run only: the metric computes through a model of its own."""
    if not ctx.full:
        raise unittest.SkipTest(f"{ctx.cls.__name__} computes through a model of its own (e.g. FID's InceptionV3): "
                                "full=True (brdfbench check --full) runs it")
    w = ctx.where("image_set_scores")
    r, _, _ = _images(n=8, size=32, seed=0)
    s, _, _ = _images(n=8, size=32, seed=1)
    r, s = r.clamp(0, 1).float(), s.clamp(0, 1).float()
    a, b = float(ctx.make().compute(r, s)), float(ctx.make().compute(r, s))
    assert math.isfinite(a), f"{w}: two image sets score {a!r}"
    assert a == b, f"{w}: the same image sets scored {a!r} then {b!r}"
    same = float(ctx.make().compute(r, r.clone()))
    assert not ctx.better(a, same), f"{w}: S = R scored {same}, a set of other images {a}"


# --------------------------------------------------------------------------- running


def _resolve(spec_or_name: MetricSpec | str) -> MetricSpec:
    if isinstance(spec_or_name, MetricSpec):
        return spec_or_name
    return registry.get("metrics", spec_or_name)


def _domain_tags(spec: MetricSpec) -> set[str]:
    """The check tags of the metric's domain; none (only the generic checks) if it cannot load."""
    try:
        return DOMAIN_TAGS.get(getattr(spec.load(), "domain", None), set())
    except Exception:  # noqa: BLE001 - the generic checks report why it does not load
        return set()


def metric_checks(spec_or_name, *, full: bool = False) -> list[Check]:
    """The checks that apply to a metric's domain; `full` runs the `image_set` scoring too."""
    spec = _resolve(spec_or_name)
    ctx = Context(spec, full)
    tags = _domain_tags(spec)
    return [Check(spec.name, name, (lambda fn=fn: fn(ctx)), spec.xfail_checks.get(name))
            for name, (requires, fn) in CHECKS.items() if requires <= tags]


def check_metric(spec_or_name, *, full: bool = False) -> ConformanceReport:
    """Run every applicable check; failures are collected, not raised (see raise_on_failure)."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name)
    for c in metric_checks(spec, full=full):
        report.run(c)
    return report
