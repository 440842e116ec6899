"""Beckmann Cook-Torrance variants and Löw et al.'s two models, as their published MERL fits use them.

- `CookTorranceBeckmann`: Cook-Torrance as Ngan, Durand and Matusik fitted it ("Experimental
  Analysis of BRDF Models", EGSR 2005).
- `CookTorrance1982`: the original of Cook and Torrance ("A Reflectance Model for Computer
  Graphics", ACM TOG 1(1), 1982) with the dielectric Fresnel of an IoR, as Löw et al. fitted it.
- `LowSmooth` and `LowMicrofacet`: the smooth-surface (ABC) and microfacet models of Löw,
  Kronander, Ynnerman and Unger ("BRDF Models for Accurate and Efficient Rendering of Glossy
  Surfaces", ACM TOG 31(1), 2012).

All are f = k_d/π + k_s ⊙ lobe (`analytic.AnalyticBRDF`), with k_s the published RGB scale
(Ngan's and Löw's "albedo", Löw's "A") and k_d the Lambertian albedo of the published fit. The
conventions that make a published parameter mean what it meant (where a 1/π sits, what
"eta" is, the cosine the Fresnel term takes) were checked against BBM ("A BSDF Benchmark",
P. Peers, github.com/bsdfbenchmark/bbm: include/bsdfmodel/{ngan,cooktorrance,low,lowsmooth,
lowmicrofacet,microfacet}.h, include/ndf/{beckmann,low}.h, include/maskingshadowing/vgroove.h,
include/bbm/fresnel_{schlick,cook}.h), which evaluates these fits; this is our own code,
written from the papers' equations. Each convention also scored the published parameters
better than its alternatives against the nbrdf_release networks of the same MERL materials.

Shared terms, in the stable forms of `analytic_terms.py` (finite and accurate in fp32 and fp64
over the whole coefficient range, incl. Beckmann m = 1e-3 and B = 1e8):

- Beckmann D = exp(−tan²θh/m²)/(m² cos⁴θh) (Cook's 1982 form; ×1/π normalised) is evaluated as
  one exp(−(sin²θh/cos²θh)/m² − 2 log cos²θh)/m²: no tangent, no 1/cos⁴ overflow and no
  subnormal intermediate at grazing h; 0 where h_z = 0.
- V-groove masking-shadowing G = min(1, 2 cosθh cosθi/cosθd, 2 cosθh cosθo/cosθd) (Torrance and
  Sparrow 1967, Cook and Torrance 1982) enters only as G/(cosθi cosθo) =
  min(1/(cosθi cosθo), 2 cosθh/(cosθd max(cosθi, cosθo))): no 0/0 where ωi + ωo → 0, bounded
  by the COS_MIN clamp at grazing.
- 1 − cosθh = sin²θh/(1 + cosθh) (no cancellation near the peak), powers as
  exp(−C log1p(·)), the projected distance |ωi,xy + ωo,xy|² = 4 cos²θd sin²θh from the half
  vector's components (no cancellation near the mirror direction).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import torch

from .analytic import _COMMON_FLOPS, _KD, _KS, AnalyticBRDF, Coefficient
from .analytic_terms import BECKMANN_M_MIN, HALF_WIDTH_PER_ALPHA, Geometry, fresnel_dielectric, schlick_fresnel
from .published_params import PublishedParams

#: Löw et al.'s published A reaches ~5.7e3 (20 LowSmooth and 25 LowMicrofacetFit fits above 1e3): a wider k_s
_KS_WIDE = Coefficient("ks", 3, 1.0, 1e-8, 1e4, log=True)

Tensor = torch.Tensor

INV_PI = 1.0 / math.pi
#: Beckmann m below which the lobe would be evaluated at a floor (its peak 1/(π m²) stays
#: far from fp32 overflow); no published fit comes near it (smallest: 0.0018).
ROUGHNESS_MIN = BECKMANN_M_MIN

# Fit bounds: each holds every published value (BBM's fits/ files, scanned) with room.
_ROUGHNESS = Coefficient("roughness", 1, 0.3, 1e-3, 4.0, log=True)  # published 0.0018 .. 2.09
_F0 = Coefficient("eta", 1, 0.04, 1e-3, 1.0)  # Ngan's "eta" is F0: published 0.0017 .. 0.999
_IOR = Coefficient("eta", 1, 1.5, 1.01, 1e3, log=True)  # Löw's IoR: published 1.035 .. 99.9996
_B = Coefficient("B", 1, 1e3, 1e-3, 1e8, log=True)  # published 6.6 .. 8.1e6
_C = Coefficient("C", 1, 1.0, 1e-3, 100.0, log=True)  # published 0.014 .. 2.67
#: Domain of the published B, C, η of both ABC models (from_published): (lo, hi, lo_open, meaning)
_ABC_DOMAIN = {
    "B": (0.0, math.inf, False, "B >= 0"),
    "C": (0.0, math.inf, False, "C >= 0"),
    "eta": (0.0, math.inf, True, "an index of refraction > 0"),
}

# FLOPS (counted as in analytic.py, per-material constants hoisted; _COMMON_FLOPS holds the
# half vector, cosθd, h_z², sin²θh and the RGB combine):
#   Beckmann D: t = sin²/cos², t/m², log cos², ×2, −, exp, ×1/m² (or 1/(π m²)) = 7
#   V-groove G/(cos cos): √cos²θh, ×2, max, ×cosθd, ÷, cos·cos, 1/·, min = 8
#   Schlick F = 6
#   dielectric Fresnel: c², g², √, g−c, g+c, ÷, c(g+c), −1, c(g−c), +1, ÷, a², b², 1+b², ½a²· = 16
_BECKMANN_FLOPS = 7
_VGROOVE_FLOPS = 8
_SCHLICK_FLOPS = 6
_DIELECTRIC_FLOPS = 16


# --------------------------------------------------------------------------- terms


def beckmann_unnormalised(inv_m2: Tensor, g: Geometry) -> Tensor:
    """exp(−tan²θh/m²)/(m² cos⁴θh), Beckmann's distribution as Cook and Torrance (1982) write
    it (no 1/π: ∫ D cosθh dωh = π), evaluated as exp(−(sin²θh/cos²θh)/m² − 2 log cos²θh)/m²;
    0 where h_z = 0. `inv_m2` = 1/m²."""
    tiny = torch.finfo(g.cos2_h.dtype).tiny
    c2 = g.cos2_h.clamp(min=tiny)
    d = torch.exp(-((g.sin2_h / c2) * inv_m2) - 2.0 * torch.log(c2)) * inv_m2
    return torch.where(g.cos2_h > 0, d, torch.zeros_like(d))


def vgroove_over_cc(g: Geometry) -> Tensor:
    """V-groove G / (cosθi cosθo), G = min(1, 2 cosθh cosθi/cosθd, 2 cosθh cosθo/cosθd), as
    min(1/(cosθi cosθo), 2 cosθh/(cosθd max(cosθi, cosθo)))."""
    tiny = torch.finfo(g.cos_i.dtype).tiny
    two_hz = 2.0 * torch.sqrt(g.cos2_h)
    den = (torch.maximum(g.cos_i, g.cos_o) * g.cos_d).clamp(min=tiny)
    return torch.minimum(1.0 / (g.cos_i * g.cos_o), two_hz / den)


def abc_power(b: Tensor, c: Tensor, x: Tensor) -> Tensor:
    """(1 + b x)^(−c) = exp(−c log1p(b x)), for x ≥ 0."""
    return torch.exp(-c * torch.log1p(b * x))


def one_minus_cos_h(g: Geometry) -> Tensor:
    """1 − cosθh = sin²θh/(1 + cosθh), relatively accurate near the peak."""
    return g.sin2_h / (1.0 + torch.sqrt(g.cos2_h))


def quarter_dp2(g: Geometry) -> Tensor:
    """|ωi,xy + ωo,xy|²/4 = cos²θd sin²θh: Löw's squared projected deviation D_p² over 4,
    from the half vector's components (relatively accurate at the mirror direction)."""
    return (g.cos_d * g.cos_d) * g.sin2_h


# --------------------------------------------------------------------------- published parameters


def _published(cls, bbm_name: str, diffuse: Any, params: dict[str, Any], rgb: str,
               domain: dict[str, tuple[float, float, bool, str]]) -> dict[str, Any]:
    """kd, ks and the shape from a published fit: `rgb` names the RGB scale (→ ks); `domain`
    maps each scalar parameter (same name as its coefficient) to (lo, hi, lo_open, meaning)."""
    p = PublishedParams(cls, bbm_name, params)
    p.expect([rgb, *domain])
    out: dict[str, Any] = {"kd": p.diffuse(diffuse), "ks": p.rgb(rgb)}
    for key, (lo, hi, lo_open, meaning) in domain.items():
        out[key] = p.number(key)
        p.within(key, out[key], lo, hi, meaning, lo_open=lo_open)
    return out


# --------------------------------------------------------------------------- the models


class _MicrofacetModel(AnalyticBRDF):
    """A model of this module: `KERNEL` names its drjit twin in `microfacet_kernels`."""

    KERNEL: ClassVar[str] = ""

    def drjit_kernel(self):
        """The model in drjit operations, for the exact class that names KERNEL only (a
        subclass may change `lobe`); drjit is imported here, not with the representation."""
        if "KERNEL" not in type(self).__dict__:
            return None
        from . import microfacet_kernels  # lazy: drjit

        return getattr(microfacet_kernels, self.KERNEL)(self)


class CookTorranceBeckmann(_MicrofacetModel):
    """Cook-Torrance as fitted by Ngan, Durand and Matusik ("Experimental Analysis of BRDF
    Models", EGSR 2005).

    lobe = D·G·F / (π cosθi cosθo), D the normalised Beckmann distribution
    exp(−tan²θh/m²)/(π m² cos⁴θh), G the V-groove masking-shadowing, F Schlick's with F0 at
    cosθd. Coefficients: kd, ks (Ngan's RGB "albedo"), roughness (Beckmann m), eta (F0).

    Checked against BBM's NganCookTorrance (include/bsdfmodel/ngan.h): its "eta" is a
    reflectance F0 (the Schlick term's parameter type), not an IoR; "roughness" is m itself;
    D carries the 1/π and the model divides by π cosθi cosθo ("Cook" normalisation), so a
    smooth lobe reflects ≈ 4 F0/π of the light at normal incidence.
    """

    NAME = "cook_torrance_beckmann"
    KERNEL = "CookTorranceBeckmannKernel"
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ("NganCookTorrance",)
    COEFFS = (_KD, _KS, _ROUGHNESS, _F0)
    FLOPS = _COMMON_FLOPS + _BECKMANN_FLOPS + _VGROOVE_FLOPS + _SCHLICK_FLOPS + 2

    @classmethod
    def lobe(cls, g, c):
        m = c["roughness"].clamp(min=ROUGHNESS_MIN)
        inv_m2 = 1.0 / (m * m)
        d = beckmann_unnormalised(inv_m2, g) * (1.0 / math.pi**2)  # D/π: the normalised D's 1/π and Cook's 1/π
        return d * vgroove_over_cc(g) * schlick_fresnel(c["eta"], g.cos_d)

    @classmethod
    def init_shape(cls, alpha):
        return {"roughness": alpha, "eta": 0.04}  # Beckmann m ≈ GGX α for the peak's width

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """Coefficients of a published NganCookTorrance fit (albedo → ks, eta = F0 → eta)."""
        return _published(cls, bbm_name, diffuse, params, "albedo", {
            "roughness": (ROUGHNESS_MIN, math.inf, False, f"Beckmann m >= {ROUGHNESS_MIN:g}"),
            "eta": (0.0, 1.0, False, "a reflectance F0 in [0, 1]"),
        })


class CookTorrance1982(_MicrofacetModel):
    """The original Cook-Torrance model (Cook and Torrance, "A Reflectance Model for Computer
    Graphics", ACM TOG 1(1), 1982) as Löw et al. 2012 fitted it.

    lobe = F·D·G / (π cosθi cosθo) with the paper's Beckmann D = exp(−tan²θh/m²)/(m² cos⁴θh)
    (no 1/π), G the V-groove term and F the unpolarised dielectric Fresnel of the IoR η at
    cosθd. Coefficients: kd, ks (Löw's RGB "albedo"), roughness (m), eta (IoR).

    Checked against BBM's LowCookTorrance = CookTorrance (include/bsdfmodel/cooktorrance.h,
    low.h): Beckmann without the 1/π, Cook's π normalisation, Fresnel at (ωi·h + ωo·h)/2 =
    cosθd; a smooth lobe hence reflects ≈ 4 F(η) at normal incidence (unnormalised, as
    published).
    """

    NAME = "cook_torrance_1982"
    KERNEL = "CookTorrance1982Kernel"
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ("LowCookTorrance",)
    COEFFS = (_KD, _KS, _ROUGHNESS, _IOR)
    FLOPS = _COMMON_FLOPS + _BECKMANN_FLOPS + _VGROOVE_FLOPS + _DIELECTRIC_FLOPS + 2

    @classmethod
    def lobe(cls, g, c):
        m = c["roughness"].clamp(min=ROUGHNESS_MIN)
        inv_m2 = 1.0 / (m * m)
        d = beckmann_unnormalised(inv_m2, g) * INV_PI  # Cook's 1/π
        return d * vgroove_over_cc(g) * fresnel_dielectric(c["eta"], g.cos_d)

    @classmethod
    def init_shape(cls, alpha):
        return {"roughness": alpha, "eta": 1.5}

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """Coefficients of a published LowCookTorrance fit (albedo → ks)."""
        return _published(cls, bbm_name, diffuse, params, "albedo", {
            "roughness": (ROUGHNESS_MIN, math.inf, False, f"Beckmann m >= {ROUGHNESS_MIN:g}"),
            "eta": (0.0, math.inf, True, "an index of refraction > 0"),
        })


class LowSmooth(_MicrofacetModel):
    """The smooth-surface model of Löw, Kronander, Ynnerman and Unger ("BRDF Models for
    Accurate and Efficient Rendering of Glossy Surfaces", ACM TOG 31(1), 2012, §4).

    lobe = S(D_p)·Q with the ABC (K-correlation) spectrum S = (1 + B D_p²)^(−C) of the projected
    deviation D_p = |ωi,xy + ωo,xy| (the distance, in the tangent plane, between the mirror
    direction of ωi and ωo), and Q the dielectric Fresnel of the IoR η at the paper's
    projected cosθd = √(1 − |ωi,xy − ωo,xy|²/4); A → ks (RGB), and the shape B, C, eta.

    Checked against BBM's LowSmooth (include/bsdfmodel/lowsmooth.h): the published fits take
    the Rayleigh-Rice geometric factor as G = 1 (no cosθi cosθo) and this projected cosθd
    (not the true one: it exceeds it by (cosθi − cosθo)²/4 under the root), evaluated here as
    √((cos²θi + cos²θo)/2 + D_p²/4), free of cancellation.
    """

    NAME = "low_smooth"
    KERNEL = "LowSmoothKernel"
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ("LowSmooth",)
    COEFFS = (_KD, _KS_WIDE, _B, _C, _IOR)
    # D_p²/4 2; S: 4B·, log1p, ×(−C), exp 4; projected cos: cos²θi, cos²θo, +, ×½, +, min, √ 7;
    # Fresnel 16; S·Q 1
    FLOPS = _COMMON_FLOPS + 2 + 4 + 7 + _DIELECTRIC_FLOPS + 1

    @classmethod
    def lobe(cls, g, c):
        x = quarter_dp2(g)
        s = abc_power(4.0 * c["B"], c["C"], x)
        cos2 = 0.5 * (g.cos_i * g.cos_i + g.cos_o * g.cos_o) + x
        q = fresnel_dielectric(c["eta"], torch.sqrt(cos2.clamp(max=1.0)))
        return s * q

    @classmethod
    def init_shape(cls, alpha):
        # Half width of GGX(α) (tanθ½ = HALF_WIDTH_PER_ALPHA·α) with C = 1: near normal incidence D_p ≈ 2θh.
        return {"B": 1.0 / (4.0 * (HALF_WIDTH_PER_ALPHA * alpha) ** 2), "C": 1.0, "eta": 1.5}

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """Coefficients of a published LowSmooth fit (A → ks)."""
        return _published(cls, bbm_name, diffuse, params, "A", _ABC_DOMAIN)


class LowMicrofacet(_MicrofacetModel):
    """The microfacet model of Löw, Kronander, Ynnerman and Unger ("BRDF Models for Accurate
    and Efficient Rendering of Glossy Surfaces", ACM TOG 31(1), 2012, §5), as the fits of their
    supplemental material use it.

    lobe = S(h)·G·F / (π cosθi cosθo), with the ABC-like distribution S = (1 + B(1 − cosθh))^(−C)
    (unnormalised: A carries the scale), the V-groove G and the dielectric Fresnel of η at
    cosθd; A → ks (RGB), and the shape B, C, eta.

    Checked against BBM's LowMicrofacetFit (include/bsdfmodel/low.h, lowmicrofacet.h, ndf/low.h):
    the supplemental fits divide by π cosθi cosθo (Cook's normalisation), which the paper's
    eq. 15 does not; the published A only reproduces the fits with it. S = 0 where h_z = 0.
    """

    NAME = "low_microfacet"
    KERNEL = "LowMicrofacetKernel"
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ("LowMicrofacetFit",)
    COEFFS = (_KD, _KS_WIDE, _B, _C, _IOR)
    # 1 − cosθh: √ (shared with G), +1, ÷ 3; S: B·, log1p, ×(−C), exp 4; horizon select 1;
    # V-groove 7 (its √ counted above); Fresnel 16; S·G·F 2, ×1/π 1
    FLOPS = _COMMON_FLOPS + 3 + 4 + 1 + (_VGROOVE_FLOPS - 1) + _DIELECTRIC_FLOPS + 3

    @classmethod
    def lobe(cls, g, c):
        s = abc_power(c["B"], c["C"], one_minus_cos_h(g))
        s = torch.where(g.cos2_h > 0, s, torch.zeros_like(s))
        return s * vgroove_over_cc(g) * fresnel_dielectric(c["eta"], g.cos_d) * INV_PI

    @classmethod
    def init_shape(cls, alpha):
        # Half width of GGX(α) (tanθ½ = HALF_WIDTH_PER_ALPHA·α) with C = 1: 1 − cosθh ≈ θh²/2.
        return {"B": 2.0 / (HALF_WIDTH_PER_ALPHA * alpha) ** 2, "C": 1.0, "eta": 1.5}

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """Coefficients of a published LowMicrofacetFit fit (A → ks)."""
        return _published(cls, bbm_name, diffuse, params, "A", _ABC_DOMAIN)
