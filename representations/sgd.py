"""Bagher, Soler and Holzschuch's Shifted Gamma Distribution model (SGD), as fitted to MERL.

M. M. Bagher, C. Soler and N. Holzschuch, "Accurate fitting of measured reflectances using
a Shifted Gamma micro-facet distribution", Computer Graphics Forum 31(4) (EGSR 2012). Every
shape coefficient is per RGB channel; per channel,

    f = k_d/π + ρ_s · D(θh) · G1(θi) G1(θo) · F(θd) / (π cosθi cosθo)

- D = K_ap · P22(tan²θh) / (π cos⁴θh), the shifted gamma distribution of slopes
  P22(x) = exp(−(α + x/α)) / (α + x/α)^p (the paper's α^(p−1) exp(−(α² + x)/α)/(α² + x)^p
  up to a constant), with K_ap = 1/(α Γ(1 − p, α)) normalising it: ∫ D cosθh dωh = 1;
- G1(θ) = 1 + Λ (1 − exp(c (θ − θ0)^k)) for θ > θ0, 1 below: the paper's fitted
  shadowing-masking of one direction, θ its polar angle; the published fits set c so that
  G1(π/2) = 0;
- F = F0 − F1 cosθd + (1 − F0)(1 − cosθd)^5: Schlick's approximation with the paper's
  linear correction;
- ρ_s (k_s here) and ρ_d (k_d) the specular and diffuse albedos.

The published parameters (BBM's `Bagher(albedo, alpha, p, eta, K, Lambda, c, k, theta0)`,
fits/ of "A BSDF Benchmark", P. Peers, github.com/bsdfbenchmark/bbm) mean exactly this;
checked against BBM's include/bsdfmodel/bagher.h, include/ndf/sgd.h and
include/maskingshadowing/uncorrelated.h, which evaluate them: its "eta" is not a complex
index but the pair of Fresnel rows [F0 (RGB), F1 (RGB)]; "K" the normalisation K_ap (every
published K equals 1/(α Γ(1 − p, α)) to 5e-6); D·G·F is divided by π cosθi cosθo (the
Cook-Torrance normalisation). The SGD plugin of ALTA (Inria's BRDF-fitting library) divides
by π alone; against the MERL materials (the NBRDF release's networks standing in for them)
the published fits score better with the 1/(cosθi cosθo), on 87 of the 100 materials even
with each material's specular scale re-optimised. Our own code, from the paper's equations.

All coefficients stay coefficients, K_ap and c too (a fit can move them off the paper's
constraints), so every published fit evaluates exactly. Departures, all outside what a
published fit means: G1 is clamped at 0 (the printed c, rounded to 6 digits, leaves G1 as
low as −2e-3 in the last 1e-4 rad above the horizon, where 1/cosθ would make that a large
negative lobe); F is clamped at 0 too (a reflectance: three published fabrics/paints,
blue-fabric, white-fabric2 and white-paint, let F0 − F1 dip to −0.073 at θd → 0, which
would subtract from the diffuse term there, and a negative lobe derails a fit's log loss);
α is floored at ALPHA_MIN = 1e-6 (the published α ≥ 1.6e-5), Λ at LAMBDA_MIN = 1e-30.

Stable forms, as in `analytic_terms.py` (finite and accurate in fp32 and fp64 over the
coefficient bounds):
- D = (K_ap/π²) exp(−s − p log s − 2 log cos²θh) with s = α + (sin²θh/cos²θh)/α, sin²θh
  from the half vector's components, s capped at S_MAX (where D underflows anyway): no
  tangent and no 1/cos⁴ overflow at grazing h, no α^p underflow for narrow lobes;
- G1 is evaluated about its zero E* = log(1 + 1/Λ) of E = c (θ − θ0)^k, as
  G1 = −(1 + Λ) expm1(E − E*), E − E* = E* expm1(w), w = log(c x_h^k/E*) + k log1p(−ψ/x_h),
  ψ = π/2 − θ = atan2(cosθ, sinθ), x_h = π/2 − θ0, the first term of w formed in fp64 on
  the host (the published c reaches 1.6e109, beyond fp32): every factor is relatively
  accurate, so the fp32 rounding of θ is not amplified by k (up to 856 published; the
  direct 1 − Λ expm1(c (θ − θ0)^k) loses k·ulp(θ)/(θ − θ0) ≈ 1e-4 of G1 near the horizon
  to it), and Λ up to 1.5e7 multiplies no cancelled difference; w and E − E* are capped
  at W_MAX (G1 is 0 long before), Λ floored at LAMBDA_MIN = 1e-30;
- G1(θi) G1(θo) and cosθi cosθo are formed as products first, so f(ωi, ωo) = f(ωo, ωi)
  bit for bit.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import torch

from brdfbench import reused

from .analytic import _COMMON_FLOPS, _KD, _KS, AnalyticBRDF, Coefficient
from .analytic_terms import ALPHA_MIN, HALF_WIDTH_PER_ALPHA, geometry
from .published_params import PublishedParams
from .sgd_terms import INV_PI, sgd_constants, sgd_lobe

Tensor = torch.Tensor

#: The float32 overflow threshold in log space, for the domain check of published fits.
LOG_FP32_MAX = math.log(float(torch.finfo(torch.float32).max))


def sgd_normalisation_half(alpha: float) -> float:
    """K_ap = 1/(α Γ(1 − p, α)) for p = 1/2, where Γ(1/2, α) = √π erfc(√α)."""
    return 1.0 / (alpha * math.sqrt(math.pi) * math.erfc(math.sqrt(alpha)))


def shadowing_c(lam: float, theta0: float, k: float) -> float:
    """The c for which G1(π/2) = 0, as the published fits choose it: log(1 + 1/Λ)/(π/2 − θ0)^k."""
    return math.exp(math.log(math.log1p(1.0 / lam)) - k * math.log(math.pi / 2 - theta0))


# Initial shape (`init_shape`) and defaults: p = 1/2 (the published median is 0.47),
# Schlick's F with F0 = 0.04, a shadowing that starts at θ0 = 0.2 and reaches 0 at the horizon.
_P_INIT = 0.5
_F0_INIT, _F1_INIT = 0.04, 0.0
_LAMBDA_INIT, _K_INIT, _THETA0_INIT = 3.0, 12.0, 0.2
_C_INIT = shadowing_c(_LAMBDA_INIT, _THETA0_INIT, _K_INIT)
_ALPHA_DEFAULT = 0.01

# Fit bounds: each holds every published value (the 100 lines of BBM's bagher_sgd.fit,
# scanned) with room; ranges published: α 1.6e-5 .. 0.854, p 4.6e-15 .. 1.78, K 3.46 ..
# 6.2e4, F0 7.5e-19 .. 8.48, F1 −1 .. 7.48, Λ 4.5e-8 .. 1.5e7, c 3.0e-8 .. 1.6e109,
# k 5.57 .. 856, θ0 −0.657 .. 1.208. p ≤ 2.5 keeps K_ap ≥ 1e-3 for α ≥ 1e-6.
COEFFS_SHAPE = (
    Coefficient("alpha", 3, _ALPHA_DEFAULT, ALPHA_MIN, 4.0, log=True),
    Coefficient("p", 3, _P_INIT, 0.0, 2.5),
    Coefficient("K_ap", 3, sgd_normalisation_half(_ALPHA_DEFAULT), 1e-4, 1e9, log=True),
    Coefficient("f0", 3, _F0_INIT, 0.0, 10.0),
    Coefficient("f1", 3, _F1_INIT, -10.0, 10.0),
    Coefficient("sh_lambda", 3, _LAMBDA_INIT, 1e-10, 1e9, log=True),
    Coefficient("sh_c", 3, _C_INIT, 1e-30, 1e150, log=True),
    Coefficient("sh_k", 3, _K_INIT, 0.1, 1e4, log=True),
    Coefficient("sh_theta0", 3, _THETA0_INIT, -math.pi / 2, math.pi / 2),
)

#: BBM's parameter -> our coefficient ("eta" holds two: its rows F0 and F1).
PUBLISHED_KEYS = {"albedo": "ks", "alpha": "alpha", "p": "p", "eta": ("f0", "f1"), "K": "K_ap",
                  "Lambda": "sh_lambda", "c": "sh_c", "k": "sh_k", "theta0": "sh_theta0"}


# --------------------------------------------------------------------------- the model


class SGD(AnalyticBRDF):
    """Bagher, Soler and Holzschuch's SGD microfacet model (CGF 31(4), EGSR 2012), per RGB channel.

    lobe = D · G1(θi) G1(θo) · F / (π cosθi cosθo): the shifted gamma distribution D with its
    normalisation K_ap, the fitted shadowing G1(θ) = 1 + Λ(1 − exp(c (θ − θ0)^k)), the
    corrected Schlick F = F0 − F1 cosθd + (1 − F0)(1 − cosθd)^5 (module docstring).
    Coefficients: kd, ks (the paper's ρ_s, BBM's "albedo"), alpha, p, K_ap, f0, f1,
    sh_lambda, sh_c, sh_k, sh_theta0, each RGB.
    """

    NAME = "sgd"
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ("Bagher",)
    COEFFS = (_KD, _KS, *COEFFS_SHAPE)
    # FLOPS (counted as in analytic.py; per-material constants hoisted; _COMMON_FLOPS holds the
    # half vector, cosθd, h_z², sin²θh and the RGB combine):
    #   θi, θo: √ and atan2 each 4; D, shared: tan²θh, log cos²θh, ×2 = 3; D per channel:
    #   ×1/α, +α, log, ×p, two subtractions, exp, ×K/π² = 8 (24); G1 per direction and
    #   channel: −θ0, log, ×k, +log c, exp, expm1, ×Λ, 1 − · = 8 (48), G1i·G1o 3; F shared:
    #   1 − cos, ^5 = 4, per channel: ×F1, −, ×(1 − F0), + = 4 (12); 1/(cosθi cosθo) 2;
    #   D·G, ·F, ·1/(cos cos) per channel 9.
    FLOPS = _COMMON_FLOPS + 4 + 3 + 24 + 48 + 3 + 4 + 12 + 2 + 9

    @classmethod
    def lobe(cls, g, c):
        return sgd_lobe(sgd_constants(c), g)

    def _eval(self, wi, wo):
        # The constants are formed in fp64 and rounded once to the input dtype (a published
        # c of 1e109 is not an fp32 number, its log is), then the lobe runs in that dtype.
        dtype = wi.dtype
        k = {name: v.to(dtype) for name, v in sgd_constants(self.shape_of(self.coeffs)).items()}
        lobe = sgd_lobe(k, reused.derived(geometry, wi, wo))
        out = self.combine(self.coeffs["kd"].to(dtype), self.coeffs["ks"].to(dtype), lobe)
        return out.clamp(0.0, torch.finfo(dtype).max)

    @classmethod
    def init_shape(cls, alpha):
        """α (and K_ap) such that D falls to half its peak where GGX of roughness `alpha`
        does (tanθ½ = 0.6436 α), with p = 1/2; Schlick's F0 = 0.04; a shadowing that is 1
        up to θ0 = 0.2 and 0 at the horizon."""
        t = (HALF_WIDTH_PER_ALPHA * alpha) ** 2  # tan²θ½

        def excess(log_a: float) -> float:  # log(D(θ½)/D(0)) + log 2: increasing in α
            a = math.exp(log_a)
            return -t / a - _P_INIT * math.log1p(t / (a * a)) + math.log(2.0)

        lo, hi = math.log(ALPHA_MIN), math.log(4.0)
        if excess(lo) >= 0:
            hi = lo
        elif excess(hi) <= 0:
            lo = hi
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if excess(mid) < 0 else (lo, mid)
        a = math.exp(0.5 * (lo + hi))
        return {"alpha": a, "p": _P_INIT, "K_ap": sgd_normalisation_half(a), "f0": _F0_INIT, "f1": _F1_INIT,
                "sh_lambda": _LAMBDA_INIT, "sh_c": _C_INIT, "sh_k": _K_INIT, "sh_theta0": _THETA0_INIT}

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """Coefficients of a published `Bagher` fit: albedo → ks, the rows of eta → f0 and f1,
        K → K_ap, Lambda, c, k, theta0 → sh_lambda, sh_c, sh_k, sh_theta0; the Lambertian
        albedo → kd. ValueError names a missing, unknown, misshapen or out-of-domain one."""
        pp = PublishedParams(cls, bbm_name, params)
        pp.expect(PUBLISHED_KEYS)
        out: dict[str, Any] = {"kd": pp.diffuse(diffuse)}
        eta = params["eta"]
        if not isinstance(eta, (list, tuple)) or len(eta) != 2:
            raise pp.fail(f"parameter 'eta' must be two rows [F0, F1] (each 1 or 3 values), got {eta!r}")
        out["f0"] = pp.rgb("eta[0] (F0)", eta[0], nonnegative=False)
        out["f1"] = pp.rgb("eta[1] (F1)", eta[1], nonnegative=False)
        for key in ("albedo", "alpha", "p", "K", "Lambda", "c", "k", "theta0"):
            out[PUBLISHED_KEYS[key]] = pp.rgb(key, nonnegative=False)

        pp.within("albedo", out["ks"], 0.0, math.inf, "a non-negative specular albedo")
        pp.within("alpha", out["alpha"], ALPHA_MIN, math.inf, f"alpha >= {ALPHA_MIN:g}")
        pp.within("p", out["p"], 0.0, math.inf, "p >= 0")
        pp.within("K", out["K_ap"], 0.0, math.inf, "a positive normalisation", lo_open=True)
        pp.within("Lambda", out["sh_lambda"], 0.0, math.inf, "Lambda >= 0")
        pp.within("c", out["sh_c"], 0.0, math.inf, "c >= 0")
        pp.within("k", out["sh_k"], 0.0, math.inf, "k > 0", lo_open=True)
        # D's peak (K/π²) exp(−α) α^(−p) must be an fp32 number: beyond it the lobe overflows.
        for a, p, kk in zip(out["alpha"], out["p"], out["K_ap"]):
            if math.log(kk * INV_PI * INV_PI) - a - p * math.log(a) > LOG_FP32_MAX:
                raise pp.fail(f"parameters 'K' = {params['K']!r}, 'alpha' = {params['alpha']!r}, "
                              f"'p' = {params['p']!r} are outside the model's domain (the lobe's peak "
                              f"K exp(-alpha) alpha^-p / pi^2 overflows float32)")
        return out

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        if type(self) is not SGD:
            return None
        from .sgd_kernel import SGDKernel  # lazy: drjit

        return SGDKernel(self)
