"""Conformance checks for importance-sampler plugins (the sampler twin of `kit.py`).

One line certifies a sampler, registered or not:

    from brdfbench.testing.samplers import check_sampler
    check_sampler("my_sampler").raise_on_failure()

In pytest, one test per check (a χ² check may raise `Unresolvable`: report it skipped):

    @pytest.mark.parametrize("check", sampler_checks("my_sampler"), ids=str)
    def test_conformance(check): check()

Fixed checks: the protocol; shapes and dtypes (fp32, fp64, empty batches); finite,
unit-length samples with finite densities, > 0 at the sampler's own samples above the
horizon, for hard ωi (normal, grazing to 89.999°, on and below the horizon) × u at the
unit square's edges (0, tiny, 1 − 2ε, 1 − ε) and random u; fp32 agreeing with fp64 on the
same inputs; `hemisphere` samplers: samples above the horizon and independent of ωi;
densities finite and ≥ 0 over `brdfbench.testing.adversarial_pairs`, and exactly 0 at or
below the horizon. Each runs for the given parameters and every roughness of the sweep.

The χ² sweep: one check per cell, `brdfbench.sampling.chi2.chi2_test` (Mitsuba's
`ChiSquareTest` on `SphericalDomain`, narrow lobes zoomed, microfacet samplers binned in
half vectors, adaptive cell integrals). Cells: roughness α ∈ ROUGHNESS_SWEEP = {1e-3,
0.01, 0.1, 0.5, 1} through the sampler's `roughness_params(α)` (the built-in exponent
samplers map α to the Beckmann-equivalent exponent n = 2/α² − 2, so n ≈ 2·10⁶ … 0; a
sampler without a roughness parameter is swept over θi only) × θi ∈ THETA_I_SWEEP_DEG =
{0, 30, 60, 80, 89.9}° (azimuth PHI_I = 1 rad) × the dtypes asked for; 1e6 samples, res
101. `sweep="quick"` runs QUICK_CELLS only (both corners at θi = 89.9°, α = 1e-3 at normal
incidence, one θi for each other α) with 2e5 samples, res 51. Multiple tests: family-wise
level SIGNIFICANCE = 0.01, Šidák-corrected, each test rejecting at
p < 1 − (1 − 0.01)^(1/m), m = `test_count` (default: the χ² checks this call builds; pass
the total when several samplers or sweeps share one family).

A cell where the dtype cannot resolve the lobe (fp32 at θi = 89.9°, α = 1e-3: samples
3 % of the lobe's width apart in h) raises `Unresolvable` instead of testing fp32
rounding; `check_sampler` reports it as skipped with the measured resolution, and fp32
there is covered by `float32_matches_float64`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import torch

from ..plugins import registry
from ..sampling import Sampler
from ..sampling.chi2 import SIGNIFICANCE, Unresolvable, chi2_test, torch_threads
from ..plugins.specs import SamplerSpec
from .adversarial import adversarial_pairs
from .checks import CheckSet
from .kit import Check, ConformanceReport

__all__ = ["Chi2Cell", "Unresolvable", "check_sampler", "chi2_cells", "sampler_checks"]

DTYPES = (torch.float32, torch.float64)
CHI2_DTYPES = (torch.float64, torch.float32)
ROUGHNESS_SWEEP = (1e-3, 0.01, 0.1, 0.5, 1.0)
THETA_I_SWEEP_DEG = (0.0, 30.0, 60.0, 80.0, 89.9)
PHI_I = 1.0
#: (α, θi in degrees) of the quick sweep; samplers without roughness run its θi values.
QUICK_CELLS = ((1e-3, 89.9), (1.0, 89.9), (1e-3, 0.0), (0.01, 80.0), (0.1, 60.0), (0.5, 30.0))
DEFAULT_PAIRS = 100_000
F32_DIRECTION_ULPS = 256
F32_PDF_RTOL = 1e-3
F32_PDF_ATOL = 1e-30  # densities below fp32's normal range may flush to 0
FULL_SAMPLES = 1_000_000
QUICK_SAMPLES = 200_000
FULL_RES = 101  # Mitsuba's default: 50 × 101 cells
QUICK_RES = 51
#: Hard incident polar angles (degrees): normal, grazing, on and below the horizon.
HARD_THETA_DEG = (0.0, 30.0, 60.0, 80.0, 89.0, 89.9, 89.99, 89.999, 90.0, 120.0, 180.0)
HARD_PHI = (0.0, 1.0, math.pi / 2, math.pi, -2.5)


@dataclass(frozen=True)
class Chi2Cell:
    """One χ² test of a sweep: parameters, θi, dtype."""

    params: dict
    label: str
    theta_deg: float
    dtype: torch.dtype

    @property
    def wi(self) -> tuple[float, float, float]:
        t = math.radians(self.theta_deg)
        return (math.sin(t) * math.cos(PHI_I), math.sin(t) * math.sin(PHI_I), math.cos(t))

    @property
    def name(self) -> str:
        return f"chi2[{self.label},theta_i={self.theta_deg:g},{str(self.dtype).removeprefix('torch.')}]"


@dataclass
class Context:
    spec: SamplerSpec
    params: dict
    n_pairs: int

    @property
    def cls(self) -> type:
        return self.spec.load()

    def create(self, **extra) -> Sampler:
        return self.spec.create(**{**self.params, **extra})

    def parameter_sets(self) -> list[dict]:
        """The given parameters, then each roughness of the sweep (if the sampler has one)."""
        sets = [dict(self.params)]
        for alpha in ROUGHNESS_SWEEP:
            extra = self.cls.roughness_params(alpha)
            if extra is not None:
                sets.append({**self.params, **extra})
        return sets


def chi2_cells(spec: SamplerSpec, params: dict, sweep: str = "full", dtypes: Sequence[torch.dtype] = CHI2_DTYPES) -> list[Chi2Cell]:
    """The χ² cells of a sweep ("full", "quick" or "none") for a sampler."""
    if sweep == "none":
        return []
    if sweep not in ("full", "quick"):
        raise ValueError(f"sweep={sweep!r} must be 'full', 'quick' or 'none'")
    cls = spec.load()
    has_roughness = cls.roughness_params(ROUGHNESS_SWEEP[0]) is not None
    if sweep == "full":
        pairs = [(a, t) for a in ROUGHNESS_SWEEP for t in THETA_I_SWEEP_DEG] if has_roughness else [(None, t) for t in THETA_I_SWEEP_DEG]
    else:
        pairs = list(QUICK_CELLS) if has_roughness else [(None, t) for t in sorted({t for _, t in QUICK_CELLS})]
    cells = []
    for dtype in dtypes:
        for alpha, theta in pairs:
            extra = cls.roughness_params(alpha) if alpha is not None else {}
            label = ",".join(f"{k}={v:.6g}" for k, v in extra.items()) or "default"
            cells.append(Chi2Cell({**params, **extra}, label, theta, dtype))
    return cells


# --------------------------------------------------------------------------- checks

CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


@check()
def check_protocol(ctx: Context) -> None:
    cls = ctx.cls
    assert isinstance(cls, type) and issubclass(cls, Sampler), f"{ctx.spec.target} must be a subclass of brdfbench.sampling.Sampler"
    missing = {"hemisphere", "microfacet"} & ctx.spec.tags - cls.tags
    assert not missing, f"spec tags {sorted(missing)} are not declared on {cls.__name__}.tags"
    sampler = ctx.create()
    assert isinstance(sampler.params, dict), "params must be a dict of constructor arguments"
    for alpha in ROUGHNESS_SWEEP:
        extra = cls.roughness_params(alpha)
        assert extra is None or isinstance(extra, dict), f"roughness_params({alpha}) must be a dict or None, got {extra!r}"


@check()
def check_shapes_and_dtypes(ctx: Context) -> None:
    sampler = ctx.create()
    g = torch.Generator().manual_seed(1)
    for dtype in DTYPES:
        for n in (64, 0):
            wi = _unit(torch.rand(n, 3, generator=g, dtype=torch.float64) - torch.tensor([0.5, 0.5, 0.0], dtype=torch.float64)).to(dtype)
            u = torch.rand(n, 2, generator=g, dtype=torch.float64).to(dtype)
            wo = sampler.sample(wi, u)
            assert wo.shape == (n, 3), f"sample returned shape {tuple(wo.shape)}, expected ({n}, 3)"
            assert wo.dtype == dtype, f"sample on {dtype} returned {wo.dtype}"
            p = sampler.pdf(wi, wo)
            assert p.shape == (n,), f"pdf returned shape {tuple(p.shape)}, expected ({n},)"
            assert p.dtype == dtype, f"pdf on {dtype} returned {p.dtype}"


@check()
def check_samples_finite_unit(ctx: Context) -> None:
    for params in ctx.parameter_sets():
        sampler = ctx.spec.create(**params)
        for dtype in DTYPES:
            wi, u = _hard_inputs(dtype, seed=2)
            wo = sampler.sample(wi, u)
            where = f"({params}, {dtype})"
            bad = ~torch.isfinite(wo).all(-1)
            assert not bad.any(), _fault(f"non-finite sample {where}", wi, u, wo, bad)
            tol = 64 * torch.finfo(dtype).eps
            off = (torch.linalg.vector_norm(wo.to(torch.float64), dim=-1) - 1).abs() > tol
            assert not off.any(), _fault(f"sample not unit length within {tol:.1e} {where}", wi, u, wo, off)
            p = sampler.pdf(wi, wo)
            bad = ~torch.isfinite(p) | (p < 0)
            assert not bad.any(), _fault(f"pdf of own sample non-finite or negative {where}", wi, u, p, bad)
            zero = (wi[:, 2] > 0) & (wo[:, 2] > 0) & (p == 0)
            assert not zero.any(), _fault(f"pdf 0 at its own sample above the horizon (infinite weight) {where}", wi, u, wo, zero)


@check()
def check_float32_matches_float64(ctx: Context) -> None:
    """fp32 and fp64 agree on the same inputs (ωi above the horizon, u incl. the edges):
    directions within F32_DIRECTION_ULPS ulps, densities (at the fp32 samples and at
    adversarial pairs) within F32_PDF_RTOL, relative. This covers fp32 where a χ² test
    cannot resolve the lobe (see `brdfbench.sampling.chi2.RESOLUTION_LIMIT`)."""
    tol = F32_DIRECTION_ULPS * torch.finfo(torch.float32).eps
    for params in ctx.parameter_sets():
        sampler = ctx.spec.create(**params)
        wi, u = _hard_inputs(torch.float32, seed=6)
        keep = wi[:, 2] > 0
        wi, u = wi[keep], u[keep]
        wo32 = sampler.sample(wi, u)
        wo64 = sampler.sample(wi.double(), u.double())
        off = (wo32.double() - wo64).abs().amax(-1) > tol
        assert not off.any(), _fault(f"fp32 sample differs from fp64 by > {tol:.1e} ({params})", wi, u, wo32 - wo64, off)
        pairs = [(wi, wo32)] + list(adversarial_pairs(max(7, ctx.n_pairs // 10), torch.float32, seed=7).values())
        for a, b in pairs:
            p32, p64 = sampler.pdf(a, b).double(), sampler.pdf(a.double(), b.double())
            off = (p32 - p64).abs() > F32_PDF_RTOL * p64.abs() + F32_PDF_ATOL
            what = f"fp32 pdf differs from fp64 by > {F32_PDF_RTOL:g} relative ({params})"
            assert not off.any(), _fault(what, a, b, torch.stack((p32, p64), -1), off)


@check("hemisphere")
def check_hemisphere(ctx: Context) -> None:
    for params in ctx.parameter_sets():
        sampler = ctx.spec.create(**params)
        for dtype in DTYPES:
            wi, u = _hard_inputs(dtype, seed=3)
            wo = sampler.sample(wi, u)
            below = wo[:, 2] <= 0
            assert not below.any(), _fault(f"hemisphere sample at or below the horizon ({params}, {dtype})", wi, u, wo, below)
            normal = torch.zeros_like(wi)
            normal[:, 2] = 1
            differs = (sampler.sample(normal, u) != wo).any(-1)
            assert not differs.any(), _fault(f"hemisphere sample depends on wi ({params}, {dtype})", wi, u, wo, differs)


@check()
def check_pdf_adversarial_finite_nonnegative(ctx: Context) -> None:
    for params in ctx.parameter_sets():
        sampler = ctx.spec.create(**params)
        for dtype in DTYPES:
            for family, (wi, wo) in adversarial_pairs(ctx.n_pairs, dtype, seed=4).items():
                p = sampler.pdf(wi, wo)
                assert p.shape == (wi.shape[0],) and p.dtype == dtype, f"pdf returned {tuple(p.shape)} {p.dtype}"
                bad = ~torch.isfinite(p) | (p < 0)
                assert not bad.any(), _fault(f"pdf non-finite or negative ({family}, {params}, {dtype})", wi, wo, p, bad)


@check()
def check_pdf_zero_below_horizon(ctx: Context) -> None:
    for params in ctx.parameter_sets():
        sampler = ctx.spec.create(**params)
        for dtype in DTYPES:
            wi, wo = adversarial_pairs(ctx.n_pairs, dtype, seed=5)["below_horizon"]
            p = sampler.pdf(wi, wo)
            nonzero = p != 0
            assert not nonzero.any(), _fault(f"pdf non-zero at or below the horizon ({params}, {dtype})", wi, wo, p, nonzero)


def _chi2_check(ctx: Context, cell: Chi2Cell, test_count: int, sample_count: int, res: int, seed: int) -> None:
    """One χ² cell; raises `Unresolvable` (reported as skipped) where the dtype cannot resolve the lobe."""
    result = chi2_test(
        ctx.spec.create(**cell.params), cell.wi, dtype=cell.dtype, sample_count=sample_count, res=res,
        significance=SIGNIFICANCE, test_count=test_count, seed=seed,
    )
    assert result.passed, f"{cell.name} of {ctx.spec.name!r}: {result.summary()}"


# --------------------------------------------------------------------------- helpers


def _unit(v: torch.Tensor) -> torch.Tensor:
    n = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    return v / torch.where(n > 0, n, torch.ones_like(n))


def _hard_inputs(dtype: torch.dtype, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Every hard ωi paired with u at the square's edges (0, 1 − ε, ...) and some random u."""
    t = torch.tensor([math.radians(x) for x in HARD_THETA_DEG], dtype=torch.float64)
    p = torch.tensor(HARD_PHI, dtype=torch.float64)
    tt, pp = torch.meshgrid(t, p, indexing="ij")
    st = torch.sin(tt)
    wi = torch.stack((st * torch.cos(pp), st * torch.sin(pp), torch.cos(tt)), dim=-1).reshape(-1, 3)
    wi[torch.isclose(tt.reshape(-1), torch.tensor(math.pi / 2, dtype=torch.float64)), 2] = 0.0  # exactly on the horizon
    wi = _unit(wi).to(dtype)
    one = torch.ones((), dtype=dtype)
    below_one = torch.nextafter(one, torch.zeros((), dtype=dtype))
    edges = torch.stack((torch.zeros((), dtype=dtype), torch.tensor(torch.finfo(dtype).tiny, dtype=dtype),
                         torch.tensor(0.5, dtype=dtype), below_one - torch.finfo(dtype).eps, below_one))
    ea, eb = torch.meshgrid(edges, edges, indexing="ij")
    g = torch.Generator().manual_seed(seed)
    u = torch.cat((torch.stack((ea.reshape(-1), eb.reshape(-1)), dim=-1), torch.rand(39, 2, generator=g, dtype=torch.float64).to(dtype)))
    u = u.minimum(below_one)
    return wi.repeat_interleave(u.shape[0], dim=0), u.repeat(wi.shape[0], 1)


def _fault(what: str, a, b, out, mask) -> str:
    i = int(torch.nonzero(mask)[0])
    return f"{what}: {int(mask.sum())} of {mask.numel()}, first at {a[i].tolist()}, {b[i].tolist()} -> {out[i].tolist()}"


# --------------------------------------------------------------------------- running


def _one_thread(fn, ctx):
    with torch_threads(1):  # small arrays: a second thread only hurts on a loaded machine
        fn(ctx)


def _resolve(spec_or_name: SamplerSpec | str) -> SamplerSpec:
    if isinstance(spec_or_name, SamplerSpec):
        return spec_or_name
    return registry.get("samplers", spec_or_name)


def _xfail(spec: SamplerSpec, name: str) -> str | None:
    """A declared expected failure, by exact check name or by its prefix before '['."""
    return spec.xfail_checks.get(name) or spec.xfail_checks.get(name.split("[")[0])


def sampler_checks(
    spec_or_name,
    *,
    params: dict | None = None,
    sweep: str = "full",
    dtypes: Sequence[torch.dtype] = CHI2_DTYPES,
    test_count: int | None = None,
    sample_count: int | None = None,
    res: int | None = None,
    n_pairs: int = DEFAULT_PAIRS,
) -> list[Check]:
    """The checks that apply to a sampler: the fixed ones, then one χ² check per sweep cell.

    `test_count`: the size of the family the Šidák correction covers (default: the χ²
    checks built here). `sample_count` and `res` per χ² test: 1e6 and 101 for the full
    sweep, 2e5 and 51 for the quick one. A χ² check raises `Unresolvable` where the dtype
    cannot resolve the lobe (fp32 at θi = 89.9°, α = 1e-3); `check_sampler` reports it as
    skipped, with the reason.
    """
    spec = _resolve(spec_or_name)
    ctx = Context(spec, dict(params or {}), n_pairs)
    checks = [
        Check(spec.name, name, (lambda fn=fn: _one_thread(fn, ctx)), _xfail(spec, name))
        for name, (requires, fn) in CHECKS.items()
        if requires <= spec.tags
    ]
    cells = chi2_cells(spec, ctx.params, sweep, dtypes)
    m = test_count if test_count is not None else max(1, len(cells))
    n = sample_count if sample_count is not None else (FULL_SAMPLES if sweep == "full" else QUICK_SAMPLES)
    r = res if res is not None else (FULL_RES if sweep == "full" else QUICK_RES)
    for i, cell in enumerate(cells):
        run = lambda cell=cell, i=i: _chi2_check(ctx, cell, m, n, r, seed=1 + i)  # noqa: E731
        checks.append(Check(spec.name, cell.name, run, _xfail(spec, cell.name)))
    return checks


def check_sampler(spec_or_name, **kwargs) -> ConformanceReport:
    """Run every applicable check (arguments as `sampler_checks`); failures are collected, not raised."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name)
    for c in sampler_checks(spec, **kwargs):
        report.run(c, skip=(Unresolvable,))
    return report
