"""Pearson's χ² test of a sampler's `sample` against its own `pdf`, at one ωi.

The test is Mitsuba 3's `mitsuba.chi2.ChiSquareTest` over its `SphericalDomain`: a
histogram of 1e6 samples over (φ, −cos θ) cells (res/2 × res, res = 101), against each
cell's expected count; cells expected below 5 are pooled; the null hypothesis is
rejected at p < 1 − (1 − level)^(1/test_count) (Šidák over the family of tests). Samples
below the horizon weigh 0 (their density is 0). Two changes, both changes of what is
measured rather than of the statistic:

- the histogram is taken in a chart of the sphere chosen from pilot samples
  (`brdfbench.sampling.charts`): half vectors for microfacet samplers, ωo otherwise,
  zoomed about the lobe when it is narrow, so that a lobe of width 1e-3 rad spreads over
  thousands of cells instead of one; the pdf is carried along with the exact Jacobian;
- `AdaptiveChiSquareTest` replaces only `tabulate_pdf`, by the adaptive cubature of
  `brdfbench.sampling.cubature` (same cells and rule, refined where the pdf is not smooth).

Backends. `ChiSquareTest` needs a vectorised variant: `SphericalDomain.bounds()` builds a
`ScalarBoundingBox2f`, which scalar variants lack, and the histogram is a JIT scatter. It
runs under `llvm_ad_rgb`, but only after a subprocess has checked that drjit loads libLLVM
≥ LLVM_MIN_MAJOR (with LLVM 15/16 drjit aborts the whole process). Otherwise (or with
BRDFBENCH_CHI2_VARIANT=scalar_rgb) the histogram is built in torch on the same cells, with
the same cubature, and the statistic is `scalar_rgb`'s `mitsuba.math.chi2` (the same
pooling) with `mitsuba.math_py.rlgamma`, decided as ChiSquareTest decides. The caller's
Mitsuba variant is restored after each test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch

from . import Sampler
from .. import mitsuba_env
from ..mitsuba_env import LLVM_MIN_MAJOR, LLVM_VARIANT, SCALAR_VARIANT, mitsuba_variant  # noqa: F401 (re-exported)
from ..threads import torch_threads
from .charts import Chart, ChartChoice, chart_for
from .cubature import DOMAIN_EXTENT, DOMAIN_LO, domain_shape, tabulate_expected

Tensor = torch.Tensor

SIGNIFICANCE = 0.01
VARIANT_ENV = "BRDFBENCH_CHI2_VARIANT"
POOL_THRESHOLD = 5.0
#: Largest quantum/width (see `ChartChoice`) at which a χ² test is meaningful: beyond it,
#: samples sit on a lattice of the dtype whose aliasing against the cells, not the
#: sampler, decides the statistic. Measured (1e6 samples, res 101): fp32 cells up to
#: 1.5e-3 (GGX and Beckmann, α = 0.01, θi = 89.9°) pass; GGX VNDF at 0.012 and GGX at
#: 0.033 (α = 1e-3, θi = 89.9°) are rejected.
RESOLUTION_LIMIT = 2e-3


class Unresolvable(Exception):
    """The dtype cannot place samples finely enough, relative to the lobe, for a χ² test."""


def sidak_level(level: float, test_count: int) -> float:
    """Per-test level that keeps the family-wise error of `test_count` independent tests at `level`."""
    return 1.0 - (1.0 - level) ** (1.0 / max(1, test_count))


@dataclass(frozen=True)
class Chi2Result:
    passed: bool
    p_value: float
    level: float  # the Šidák-corrected per-test level the p-value was compared with
    variant: str
    chart: str
    messages: str

    def summary(self) -> str:
        verdict = "accepted" if self.passed else "REJECTED"
        return (
            f"χ² {verdict}: p={self.p_value:.3g} vs level {self.level:.3g} ({self.variant}, chart {self.chart})\n"
            + self.messages.strip()
        )


# --------------------------------------------------------------------------- backend


def chi2_variant() -> str:
    """`llvm_ad_rgb` where drjit loads LLVM ≥ 19, else `scalar_rgb`; BRDFBENCH_CHI2_VARIANT overrides."""
    return mitsuba_env.choose_variant(VARIANT_ENV, warn=False)




# --------------------------------------------------------------------------- the test


def chi2_test(
    sampler: Sampler,
    wi: Sequence[float],
    *,
    dtype: torch.dtype = torch.float64,
    sample_count: int = 1_000_000,
    res: int = 101,
    ires: int = 4,
    significance: float = SIGNIFICANCE,
    test_count: int = 1,
    seed: int = 0,
    chart: Chart | None = None,
    variant: str | None = None,
) -> Chi2Result:
    """χ² test of `sampler` at the incident direction `wi`, evaluated in `dtype`.

    `test_count` is the number of tests in the family the Šidák correction covers. The
    chart comes from `chart_for` on 8192 pilot samples unless given; raises `Unresolvable`
    when the dtype spaces samples coarser than RESOLUTION_LIMIT × the lobe's width.
    """
    with torch_threads(1):
        return _chi2_test(sampler, wi, dtype, sample_count, res, ires, significance, test_count, seed, chart, variant)


def _chi2_test(sampler, wi, dtype, sample_count, res, ires, significance, test_count, seed, chart, variant) -> Chi2Result:
    # ωi as the sampler sees it (rounded to dtype), so that the chart uses the same ωi
    wi_t = torch.as_tensor(wi, dtype=torch.float64).reshape(1, 3).to(dtype).to(torch.float64)
    if chart is None:
        choice = pilot_chart(sampler, wi_t[0].tolist(), dtype, seed=seed)
        if choice.resolution > RESOLUTION_LIMIT:
            raise Unresolvable(
                f"{dtype} places samples {choice.quantum:.2g} rad apart in the test's chart, "
                f"{choice.resolution:.2g} of the lobe's width {choice.width:.2g} rad (limit {RESOLUTION_LIMIT:g})"
            )
        chart = choice.chart
    sample_fn, pdf_fn = _warped(sampler, wi_t, dtype, chart)
    variant = variant or chi2_variant()
    level = sidak_level(significance, test_count)
    if variant == LLVM_VARIANT:
        passed, p, messages = _run_mitsuba(sample_fn, pdf_fn, sample_count, res, ires, significance, test_count, seed)
    else:
        passed, p, messages = _run_torch(sample_fn, pdf_fn, sample_count, res, ires, level, seed)
    return Chi2Result(passed, p, level, variant, chart.describe(), messages)


def integrate_pdf(sampler: Sampler, wi: Sequence[float], *, dtype: torch.dtype = torch.float64, res: int = 51, seed: int = 0) -> float:
    """∫ pdf(ωi, ωo) dωo over the sphere, by the adaptive cubature of the χ² test in its
    chart: 1 for a sampler that never leaves the hemisphere, P(ωo above the horizon) else."""
    with torch_threads(1):
        wi_t = torch.as_tensor(wi, dtype=torch.float64).reshape(1, 3).to(dtype).to(torch.float64)
        chart = pilot_chart(sampler, wi_t[0].tolist(), dtype, seed=seed).chart
        _, pdf_fn = _warped(sampler, wi_t, dtype, chart)
        scale = 1e8  # cell tolerance 0.05·√(scale·mass): relative 1.6e-4 on a cell of mass 1e-3
        expected, _ = tabulate_expected(pdf_fn, res, int(scale))
        return float(expected.sum()) / scale


def pilot_chart(sampler: Sampler, wi: Sequence[float], dtype: torch.dtype, *, seed: int = 0, n: int = 8192) -> ChartChoice:
    """`chart_for` from n pilot samples (independent of the test's own)."""
    g = torch.Generator().manual_seed(10_007 + seed)
    u = torch.rand(n, 2, generator=g, dtype=torch.float64).to(dtype)
    wi_t = torch.as_tensor(wi, dtype=torch.float64).reshape(1, 3)
    wo = sampler.sample(wi_t.expand(n, 3).to(dtype), u).to(torch.float64)
    ok = torch.isfinite(wo).all(-1) & (wo[:, 2] > 0)
    wo = wo[ok] / wo[ok].norm(dim=-1, keepdim=True)
    return chart_for(sampler.tags, wi_t[0].tolist(), wo, dtype)


def _warped(sampler: Sampler, wi: Tensor, dtype: torch.dtype, chart: Chart):
    """(sample_fn, pdf_fn) over y = chart(ωo), both on float64 tensors."""
    above = float(wi[0, 2]) > 0

    def sample_fn(u: Tensor) -> tuple[Tensor, Tensor]:
        n = u.shape[0]
        wo = sampler.sample(wi.expand(n, 3).to(dtype), u.to(dtype)).to(torch.float64)
        bad = ~torch.isfinite(wo).all(-1)
        if bad.any():
            i = int(torch.nonzero(bad)[0])
            raise AssertionError(f"sample returned {int(bad.sum())} non-finite directions, first u={u[i].tolist()} -> {wo[i].tolist()}")
        wo = wo / wo.norm(dim=-1, keepdim=True).clamp(min=1e-300)
        weight = ((wo[:, 2] > 0) & above).to(torch.float64)
        return chart.forward(wo), weight

    def pdf_fn(y: Tensor) -> Tensor:
        wo = chart.inverse(y)
        p = sampler.pdf(wi.expand(y.shape[0], 3).to(dtype), wo.to(dtype)).to(torch.float64)
        bad = ~torch.isfinite(p) | (p < 0)
        if bad.any():
            i = int(torch.nonzero(bad)[0])
            raise AssertionError(f"pdf returned {int(bad.sum())} non-finite or negative values, first wo={wo[i].tolist()} -> {float(p[i])}")
        return p * chart.jacobian(y)

    return sample_fn, pdf_fn


# --------------------------------------------------------------------------- backends


def _adaptive_test_class():
    """`ChiSquareTest` with only `tabulate_pdf` replaced by `tabulate_expected` (needs a variant set)."""
    import time

    import mitsuba as mi
    from mitsuba.chi2 import ChiSquareTest

    class AdaptiveChiSquareTest(ChiSquareTest):
        """Mitsuba's χ² test whose cell integrals refine where the pdf is not smooth."""

        def __init__(self, *args, torch_pdf: Callable, res: int = 101, tolerance: float = 0.05, **kwargs):
            super().__init__(*args, res=res, **kwargs)
            self._torch_pdf, self._res_arg, self._tolerance = torch_pdf, res, tolerance

        def tabulate_pdf(self):
            self.histogram_start = time.time()  # (sic: ChiSquareTest's names for the pdf timer)
            expected, evals = tabulate_expected(
                self._torch_pdf, self._res_arg, self.sample_count, ires=self.ires, tolerance=self._tolerance
            )
            self.pdf = mi.Float(expected.numpy())
            if float(expected.min()) < 0:
                self._log("Failure: Encountered a cell with a negative PDF value: %f" % (float(expected.min()) / self.sample_count))
                self.fail = True
            self.pdf_sum = mi.Float([float(expected.sum()) / self.sample_count])
            if self.pdf_sum[0] > 1.1:
                self._log("Failure: PDF integrates to a value greater than 1.0: %f" % self.pdf_sum[0])
                self.fail = True
            self._log("Adaptive tabulation: %i pdf evaluations" % evals)
            self.histogram_end = time.time()

    return AdaptiveChiSquareTest


def _run_mitsuba(sample_fn, pdf_fn, sample_count, res, ires, significance, test_count, seed):
    with mitsuba_variant(LLVM_VARIANT) as mi:
        from mitsuba.chi2 import SphericalDomain

        def sample_func(u):
            y, w = sample_fn(torch.from_numpy(np.array(u, dtype=np.float64).T.copy()))
            y = y.T.contiguous().numpy()
            return mi.Vector3f(y[0], y[1], y[2]), mi.Float(w.numpy())

        test = _adaptive_test_class()(
            domain=SphericalDomain(), sample_func=sample_func, pdf_func=None, torch_pdf=pdf_fn,
            sample_dim=2, sample_count=sample_count, res=res, ires=ires, seed=seed,
        )
        passed = bool(test.run(significance_level=significance, test_count=test_count, quiet=True))
        p = test.p_value
        p = math.nan if p is None else float(p[0]) if hasattr(p, "__len__") else float(p)
        return passed, p, test.messages


def _run_torch(sample_fn: Callable, pdf_fn: Callable, sample_count, res, ires, level, seed):
    """ChiSquareTest's histogram and decision on the same cells, in torch; statistic by scalar_rgb."""
    log: list[str] = []
    fail = False
    nx, ny = domain_shape(res)
    lo = torch.tensor(DOMAIN_LO, dtype=torch.float64)
    ext = torch.tensor(DOMAIN_EXTENT, dtype=torch.float64)
    cells = torch.tensor([nx, ny], dtype=torch.float64)

    g = torch.Generator().manual_seed(seed)
    y, weight = sample_fn(torch.rand(sample_count, 2, generator=g, dtype=torch.float64))
    xy = torch.stack((torch.atan2(y[:, 1], y[:, 0]), -y[:, 2]), dim=-1)
    idx = ((xy - lo) / ext * cells).clamp(min=torch.zeros(2, dtype=torch.float64), max=cells - 1).to(torch.int64)
    histogram = torch.bincount(idx[:, 0] + idx[:, 1] * nx, weights=weight, minlength=nx * ny)
    histogram_sum = float(histogram.sum()) / sample_count
    if histogram_sum > 1.1:
        log.append(f"Sample weights add up to a value greater than 1.0: {histogram_sum:f}")
        fail = True

    expected, evals = tabulate_expected(pdf_fn, res, sample_count, ires=ires)
    pdf_sum = float(expected.sum()) / sample_count
    if pdf_sum > 1.1:
        log.append(f"Failure: PDF integrates to a value greater than 1.0: {pdf_sum:f}")
        fail = True
    log.append(f"Adaptive tabulation: {evals} pdf evaluations")

    order = torch.argsort(expected)
    expected, observed = expected[order], histogram[order]
    with mitsuba_variant(SCALAR_VARIANT) as mi:
        import drjit as dr

        chi2val, dof, pooled_in, pooled_out = mi.math.chi2(
            dr.scalar.ArrayXf64(observed.numpy()), dr.scalar.ArrayXf64(expected.numpy()), POOL_THRESHOLD
        )
        p_value = 1.0 - float(mi.math_py.rlgamma(dof / 2, chi2val / 2)) if dof >= 1 else math.nan
    if dof < 1:
        log.append("Failure: The number of degrees of freedom is too low!")
        fail = True
    if bool(((expected == 0) & (observed != 0)).any()):
        log.append("Failure: Found samples in a cell with expected frequency 0. Rejecting the null hypothesis!")
        fail = True
    if pooled_in > 0:
        log.append(f"Pooled {pooled_in} low-valued cells into {pooled_out} cells to ensure sufficiently high expected cell frequencies")
    log.append(f"Histogram sum = {histogram_sum:f}, PDF sum = {pdf_sum:f}")
    log.append(f"Chi^2 statistic = {chi2val:f} (d.o.f = {dof})")
    passed = not fail and math.isfinite(p_value) and p_value >= level
    verdict = "Accepted" if passed else "***** Rejected *****"
    log.append(f"{verdict} the null hypothesis (p-value = {p_value:f}, significance level = {level:f})")
    return passed, p_value, "\n".join(log) + "\n"
