"""The analytic models of Ngan, Durand and Matusik, "Experimental Analysis of BRDF Models"
(EGSR 2005), as they fitted them to MERL: Ward, Ward-Dür, the (modified) Phong lobe their
paper calls Blinn-Phong, one Lafortune lobe, and the Ashikhmin-Shirley specular term (with
Schlick's Fresnel, and with the dielectric Fresnel of an IoR as Löw et al. 2012 fitted it).

Each is f = k_d/π + k_s ⊙ lobe with the paper's own parameterisation, so that a published
parameter (/work/shared/reference/published_fits, BBM's notation) means what it meant in
the fit: `from_published` maps a BBM model's parameters onto the coefficients exactly. The
constant factors (π placement, 4 vs 8, what a scaled model's "albedo" multiplies) were
checked against BBM's headers (include/bsdfmodel/ngan.h, ward.h, wardduer.h, phong.h,
lafortune.h, ashikhminshirley.h, scaledmodel.h, low.h; include/bbm/fresnel_schlick.h,
fresnel_cook.h; github.com/bsdfbenchmark/bbm); the implementation is written here from the
papers' equations.

Numerics follow analytic_terms.py: every power is exp(n·log1p(−x)) with x computed from
non-negative parts (never 1 − cos), sin²θh from the half vector's components, cosines
clamped ≥ COS_MIN, so that fp32 stays accurate for exponents up to 1e6 and α down to 1e-3.
The per-material constants are one classmethod (`constants`) that the drjit kernels
(`ngan_kernels.py`) reuse, so the two paths agree to fp32 rounding.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import torch

from .analytic import _KD, _KS, AnalyticBRDF, Coefficient
from .analytic_terms import ALPHA_MIN, COS_MIN, Geometry, fresnel_dielectric, schlick_fresnel
from .published_params import PublishedParams

Tensor = torch.Tensor

# FLOPS, counted as in analytic.py (each add, multiply, divide, sqrt, exp, log or select one
# operation; per-material constants hoisted): half vector 12, h_z² and sin²θh 4 (sin²θh
# alone 3), cosθd 1, the RGB combine k_d/π + k_s·lobe 6.
_HALF, _H2, _S2H, _CD, _COMBINE = 12, 4, 3, 1, 6
#: 1 − cos α = 2 cos²θd sin²θh + (cosθi − cosθo)²/2
_GAP_FLOPS = 7
#: norm · exp(n · log1p(−y)), 0 where y ≥ 1
_POWER_FLOPS = 5


# --------------------------------------------------------------------------- shared terms


def mirror_gap(g: Geometry) -> Tensor:
    """1 − cos α, α the angle between ωo and the mirror direction (−ωi_x, −ωi_y, ωi_z) of ωi.

    1 − cos α = |R − ωo|²/2 with R − ωo = −(ωi_xy + ωo_xy, ωo_z − ωi_z) and
    ωi_xy + ωo_xy = 2 cosθd h_xy, so 1 − cos α = 2 cos²θd sin²θh + (cosθi − cosθo)²/2:
    a sum of non-negative terms, relatively accurate in fp32 right at the mirror peak where
    cosθi cosθo − dot_xy would cancel. Exactly symmetric in ωi, ωo."""
    dc = g.cos_i - g.cos_o
    return 2.0 * (g.cos_d * g.cos_d) * g.sin2_h + 0.5 * (dc * dc)


def cos_power(n: Tensor, norm: Tensor, y: Tensor) -> Tensor:
    """norm · (1 − y)^n for y ≥ 0, as norm · exp(n · log1p(−y)); 0 where y ≥ 1 (a cosine ≤ 0)."""
    eps = torch.finfo(y.dtype).eps
    lobe = norm * torch.exp(n * torch.log1p(-y.clamp(max=1.0 - eps)))
    return torch.where(y < 1.0, lobe, torch.zeros_like(lobe))


def cos_power_h(n: Tensor, g: Geometry) -> Tensor:
    """cos^n θh as exp(n · ½ log cos²θh); 0 where h_z = 0. log cos²θh is log1p(−sin²θh)
    near the normal (accurate for huge n) and log(h_z²) towards the horizon, where sin²θh
    rounds to 1 in fp32 while h_z² keeps its relative accuracy (it matters for tiny n,
    published down to 2e-3). Both branches stay finite, so autograd is too."""
    tiny = torch.finfo(g.sin2_h.dtype).tiny
    near = g.sin2_h < 0.5
    log_c2 = torch.where(near, torch.log1p(-g.sin2_h.clamp(max=0.5)), torch.log(g.cos2_h.clamp(min=tiny)))
    p = torch.exp(n * (0.5 * log_c2))
    return torch.where(g.cos2_h > 0, p, torch.zeros_like(p))


# --------------------------------------------------------------------------- the base


class NganBRDF(AnalyticBRDF):
    """An analytic model with published fits: PUBLISHED_AS names the BBM models whose
    parameters it evaluates exactly, PUBLISHED_PARAMS maps their parameter names onto
    coefficients (the RGB "albedo" is always k_s), `constants` forms the per-material
    scalars of the lobe (in torch, shared with the drjit kernel)."""

    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ()
    PUBLISHED_PARAMS: ClassVar[dict[str, str]] = {}

    @classmethod
    def constants(cls, c: dict[str, Tensor]) -> dict[str, Tensor]:
        """Per-material scalars of the lobe from the shape coefficients (0-d tensors)."""
        raise NotImplementedError

    @classmethod
    def validate_shape(cls, bbm_name: str, shape: dict[str, float]) -> None:
        """Raise ValueError where the shape coefficients together leave the model's domain."""

    @classmethod
    def from_published(cls, bbm_name: str, diffuse: list[float], params: dict[str, Any]) -> dict[str, Any]:
        """`set_coefficients` keywords for a published fit: k_d = the Lambertian albedo
        `diffuse` (f_d = albedo/π, as BBM's Lambertian), k_s and the shape from `params`
        (BBM's parameter names). A missing, unknown, misshapen or out-of-domain parameter
        raises ValueError naming it; shape values must lie within the fit bounds (COEFFS
        are wide enough for every published value)."""
        p = PublishedParams(cls, bbm_name, params)
        p.expect(cls.PUBLISHED_PARAMS)
        out: dict[str, Any] = {"kd": p.diffuse(diffuse)}
        spec = {c.name: c for c in cls.COEFFS}
        shape: dict[str, float] = {}
        for key, name in cls.PUBLISHED_PARAMS.items():
            if name == "ks":
                out["ks"] = p.rgb(key)
                continue
            c = spec[name]
            shape[name] = p.number(key)
            p.within(key, shape[name], c.lower, c.upper, f"[{c.lower:g}, {c.upper:g}]")
        cls.validate_shape(bbm_name, shape)
        return {**out, **shape}

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        from . import ngan_kernels  # lazy: drjit

        exact = type(self).__module__ == __name__  # a subclass elsewhere may change `lobe`
        kernel = ngan_kernels.KERNELS.get(self.NAME) if exact else None
        return None if kernel is None else kernel(self)


# --------------------------------------------------------------------------- Ward


class Ward(NganBRDF):
    """Ward, "Measuring and modeling anisotropic reflection" (SIGGRAPH 1992), isotropic:

    lobe = exp(−tan²θh / α²) / (4π α² √(cosθi cosθo)),

    the 1/(4πα²) normalisation Ward gives (the lobe's albedo → 1 as α → 0; it is not exactly
    energy conserving). As Ngan et al. fitted it (BBM's NganWard: ward.h, isotropic), k_s
    is the published "albedo" and α its "roughness". tan²θh = sin²θh / cos²θh from the half
    vector's components. Coefficients: kd, ks (RGB), alpha.
    """

    NAME = "ward"
    PUBLISHED_AS = ("NganWard",)
    PUBLISHED_PARAMS = {"albedo": "ks", "roughness": "alpha"}
    COEFFS = (_KD, _KS, Coefficient("alpha", 1, 0.1, 1e-3, 1.0, log=True))
    # tan² 1, ·(1/α²) 1, exp 1, ·norm 1, cosθi cosθo 1, sqrt 1, divide 1
    FLOPS = _HALF + _H2 + 7 + _COMBINE

    @classmethod
    def constants(cls, c):
        alpha = c["alpha"].clamp(min=ALPHA_MIN)
        a2 = alpha * alpha
        return {"neg_inv_a2": -1.0 / a2, "norm": 1.0 / (4.0 * math.pi * a2)}

    @classmethod
    def _peak(cls, g: Geometry, p: dict[str, Tensor]) -> Tensor:
        tan2 = g.sin2_h / g.cos2_h.clamp(min=torch.finfo(g.cos2_h.dtype).tiny)
        return p["norm"] * torch.exp(tan2 * p["neg_inv_a2"])

    @classmethod
    def lobe(cls, g, c):
        return cls._peak(g, cls.constants(c)) / torch.sqrt(g.cos_i * g.cos_o)

    @classmethod
    def init_shape(cls, alpha):
        return {"alpha": alpha}  # Ward's α is a Beckmann-like rms slope: ≈ GGX α at the peak


class WardDuer(Ward):
    """Ward with Dür's normalisation, "An improved normalization for the Ward reflectance
    model" (JGT 2006), isotropic:

    lobe = exp(−tan²θh / α²) / (4π α² cosθi cosθo),

    i.e. 1/(cosθi cosθo) in place of Ward's 1/√(cosθi cosθo) (BBM's NganWardDuer:
    wardduer.h); k_s is the published "albedo", α its "roughness". Coefficients: kd, ks, alpha.
    """

    NAME = "ward_duer"
    PUBLISHED_AS = ("NganWardDuer",)
    FLOPS = _HALF + _H2 + 6 + _COMBINE

    @classmethod
    def lobe(cls, g, c):
        return cls._peak(g, cls.constants(c)) / (g.cos_i * g.cos_o)


# --------------------------------------------------------------------------- Phong


class Phong(NganBRDF):
    """The modified Phong lobe of Lafortune and Willems, "Using the modified Phong
    reflectance model for physically based rendering" (tech. report CW197, KU Leuven, 1994):

    lobe = (n + 2)/(2π) cos^n α, α the angle between ωo and the mirror direction of ωi,

    cos α = cosθi cosθo − dot_xy, clamped at 0. The normalisation makes the albedo at normal
    incidence exactly 1 (and ≤ 1 elsewhere), so k_s ≤ 1 conserves energy.

    Ngan et al.'s paper names this fit "Blinn-Phong"; BBM evaluates its "NganBlinnPhong"
    fits (albedo → k_s, sharpness → n) with exactly this reflection-vector form (ngan.h
    aliases it to phong.h), which is what this class follows; the convention is to be
    confirmed against measured data. cos^n α = exp(n·log1p(−(1 − cos α))) with 1 − cos α
    from non-negative parts (`mirror_gap`): accurate for the published n up to 1.2e5.
    Coefficients: kd, ks (RGB), exponent.
    """

    NAME = "phong"
    PUBLISHED_AS = ("NganBlinnPhong",)
    PUBLISHED_PARAMS = {"albedo": "ks", "sharpness": "exponent"}
    COEFFS = (_KD, _KS, Coefficient("exponent", 1, 50.0, 1e-2, 1e6, log=True))
    FLOPS = _HALF + _CD + _S2H + _GAP_FLOPS + _POWER_FLOPS + _COMBINE

    @classmethod
    def constants(cls, c):
        n = c["exponent"].clamp(min=0.0)
        return {"n": n, "norm": (n + 2.0) / (2.0 * math.pi)}

    @classmethod
    def lobe(cls, g, c):
        p = cls.constants(c)
        return cos_power(p["n"], p["norm"], mirror_gap(g))

    @classmethod
    def init_shape(cls, alpha):
        # Blinn-Phong's Beckmann-equivalent m = 2/α² − 2 in θh; α_mirror ≈ 2θh, so n ≈ m/4.
        return {"exponent": 0.5 / (alpha * alpha) - 0.5}


class BlinnPhongNgan(NganBRDF):
    """Blinn's half-vector lobe with the normalisation Ngan et al. print for their
    "Blinn-Phong" fits:

    lobe = (n + 2)/(2π) cos^n θh.

    BBM evaluates the NganBlinnPhong fits as the mirror-direction lobe (`phong`); their
    paper names the model Blinn-Phong, and scored on the published networks of the same
    materials the half-vector reading fits better (lower l1_log_cos on 66 of the 86), so
    `published_fit` offers both (`representation.params.model=blinn_phong_ngan`). Unlike
    `blinn_phong`'s (n + 8)/(8π) this normalisation does not conserve energy exactly; it is
    kept so that the published k_s means what it meant. Coefficients: kd, ks (RGB), exponent.
    """

    NAME = "blinn_phong_ngan"
    PUBLISHED_AS = ("NganBlinnPhong",)
    PUBLISHED_PARAMS = {"albedo": "ks", "sharpness": "exponent"}
    COEFFS = (_KD, _KS, Coefficient("exponent", 1, 50.0, 1e-2, 1e6, log=True))
    # cos^n θh 4, ·norm 1
    FLOPS = _HALF + _H2 + 5 + _COMBINE

    @classmethod
    def constants(cls, c):
        return Phong.constants(c)  # the same n and (n + 2)/(2π): only the lobe's angle differs

    @classmethod
    def lobe(cls, g, c):
        p = cls.constants(c)
        return p["norm"] * cos_power_h(p["n"], g)

    @classmethod
    def init_shape(cls, alpha):
        return {"exponent": 2.0 / (alpha * alpha) - 2.0}  # the Beckmann-equivalent exponent in θh


# --------------------------------------------------------------------------- Lafortune


def lafortune_terms(g: Geometry) -> dict[str, Tensor]:
    """The per-pair parts of a generalised cosine lobe, shared by all its lobes: 1 − cos α
    (`mirror_gap`), 1 − ωi·ωo = 2 sin²θd, 1 − cosθi cosθo (from non-negative parts) and
    cosθi cosθo."""
    dc = g.cos_i - g.cos_o
    cc = g.cos_i * g.cos_o
    return {"gap": mirror_gap(g), "one_minus_dot": 2.0 * g.sin2_d,
            "one_minus_cc": 0.5 * ((dc * dc) + (g.sin2_i + g.sin2_o)), "cc": cc}


def lafortune_lobe(p: dict[str, Tensor], t: dict[str, Tensor]) -> Tensor:
    """One normalised lobe (n + 2)/(2π) (1 − y)^n from its constants (`Lafortune.constants`)
    and the shared terms (`lafortune_terms`)."""
    y = (p["w_forward"] * t["gap"] + p["w_retro"] * t["one_minus_dot"]
         + p["w_normal"] * t["one_minus_cc"] + p["w_cc"] * t["cc"])
    return cos_power(p["n"], p["norm"], y)



class Lafortune(NganBRDF):
    """One isotropic generalised cosine lobe of Lafortune, Foo, Torrance and Greenberg,
    "Non-linear approximation of reflectance functions" (SIGGRAPH 1997), with
    C_x = C_y = C_xy, times the normalisation Ngan et al. applied (BBM's NganLafortune,
    ngan.h):

    lobe = (n + 2) / (2π max(C_xy², C_z²)^(n/2)) · max(0, C_xy dot_xy + C_z cosθi cosθo)^n.

    The published fits have one lobe, so this class has one. C_xy is signed (the usual
    forward lobe has C_xy < 0: C_xy = −C_z is exactly `Phong`), so its bounds are. The
    normalisation makes the lobe depend only on the direction of (C_xy, C_z): with
    a = C_xy/m, b = C_z/m, m = max(|C_xy|, |C_z|), lobe = (n+2)/(2π) (1 − y)^n with

    y = max(−a, 0)·(1 − cos α) + max(a, 0)·(1 − ωi·ωo) + (1 − |a|)(1 − cosθi cosθo) + (1 − b) cosθi cosθo,

    every term non-negative, 1 − cos α from `mirror_gap` and 1 − cosθi cosθo =
    ((cosθi − cosθo)² + sin²θi + sin²θo)/2: no overflow of m^n or of the unnormalised
    power (0.577^4060 underflows even in fp64), and fp32-accurate lobes, forward and
    retro-reflective alike (1 − ωi·ωo = 2 sin²θd with sin²θd = |ωi − ωo|²/4, which keeps
    its relative accuracy next to ωi = ωo).

    The max makes the lobe very sensitive to |C_xy| ≠ |C_z|: the published pair rounded
    to three digits, C_xy = −0.578, C_z = 0.577 (n = 3980), is Phong times
    (1 − 0.0017 cosθi cosθo)^n, 1e-3 of it at normal incidence.
    Coefficients: kd, ks (RGB), cxy, cz, exponent.
    """

    NAME = "lafortune"
    PUBLISHED_AS = ("NganLafortune",)
    PUBLISHED_PARAMS = {"albedo": "ks", "Cxy": "cxy", "Cz": "cz", "sharpness": "exponent"}
    COEFFS = (
        _KD,
        _KS,
        Coefficient("cxy", 1, -1.0, -2.0, 2.0),
        Coefficient("cz", 1, 1.0, -2.0, 2.0),
        Coefficient("exponent", 1, 50.0, 1e-2, 1e6, log=True),
    )
    # mirror gap (with h, cosθd, sin²θh) 23; 1 − cosθi cosθo 9; cosθi cosθo 1; 1 − ωi·ωo 2;
    # the weighted sum y 7; the power 5
    FLOPS = _HALF + _CD + _S2H + _GAP_FLOPS + 9 + 1 + 2 + 7 + _POWER_FLOPS + _COMBINE

    @classmethod
    def constants(cls, c):
        cxy, cz = c["cxy"], c["cz"]
        m = torch.maximum(cxy.abs(), cz.abs()).clamp(min=torch.finfo(cxy.dtype).tiny)
        a, b = cxy / m, cz / m
        n = c["exponent"].clamp(min=0.0)
        return {
            "w_forward": (-a).clamp(min=0.0),
            "w_retro": a.clamp(min=0.0),
            "w_normal": 1.0 - a.abs(),
            "w_cc": 1.0 - b,
            "n": n,
            "norm": (n + 2.0) / (2.0 * math.pi),
        }

    @classmethod
    def lobe(cls, g, c):
        return lafortune_lobe(cls.constants(c), lafortune_terms(g))

    @classmethod
    def init_shape(cls, alpha):
        # Phong-like, but just off the kink of max(C_xy², C_z²) at |C_xy| = |C_z|: L-BFGS-B
        # started on it stalls at once (its gradient there is neither one-sided derivative).
        return {"cxy": -0.98, "cz": 1.0, **Phong.init_shape(alpha)}

    @classmethod
    def validate_shape(cls, bbm_name, shape):
        if shape["cxy"] == 0.0 and shape["cz"] == 0.0:
            raise ValueError(f"{cls.NAME}: {bbm_name} parameters 'Cxy' and 'Cz' are both 0: the normalised lobe is undefined")


# --------------------------------------------------------------------------- Ashikhmin-Shirley


class AshikhminShirley(NganBRDF):
    """The specular term of Ashikhmin and Shirley, "An anisotropic Phong BRDF model" (JGT
    2000), isotropic (n_u = n_v = n), with Schlick's Fresnel:

    lobe = (n + 1)/(8π) · cos^n θh / (cosθd · max(cosθi, cosθo)) · F(cosθd),
    F = F0 + (1 − F0)(1 − cosθd)^5.

    As Ngan et al. fitted it (BBM's NganAshikhminShirley: ngan.h wraps ashikhminshirley.h
    with Schlick's F on F0 = "fresnelReflectance" in a scaled model): the published
    "albedo" multiplies the whole lobe, F included, so k_s = albedo and F0 is kept (it is
    not A-S's R_s, which Ngan's albedo does not replace); the model has no A-S diffuse
    term (k_d/π instead). cosθd is floored at COS_MIN in the denominator only (pairs
    within 1e-7 rad of the horizon). Coefficients: kd, ks (RGB), exponent, f0.
    """

    NAME = "ashikhmin_shirley"
    PUBLISHED_AS = ("NganAshikhminShirley",)
    PUBLISHED_PARAMS = {"albedo": "ks", "fresnelReflectance": "f0", "sharpness": "exponent"}
    COEFFS = (
        _KD,
        _KS,
        Coefficient("exponent", 1, 50.0, 1e-3, 1e6, log=True),
        Coefficient("f0", 1, 0.04, 0.0, 1.0),
    )
    # cos^n θh 4 + Fresnel 6 + max 1, cosθd·max 1, divide 1, ·norm 1, ·F 1
    FLOPS = _HALF + _CD + _H2 + 4 + 6 + 5 + _COMBINE

    @classmethod
    def constants(cls, c):
        n = c["exponent"].clamp(min=0.0)
        return {"n": n, "norm": (n + 1.0) / (8.0 * math.pi), **cls._fresnel_constants(c)}

    @classmethod
    def _fresnel_constants(cls, c):
        return {"f0": c["f0"], "one_minus_f0": 1.0 - c["f0"]}

    @classmethod
    def fresnel(cls, p: dict[str, Tensor], cos_d: Tensor) -> Tensor:
        return schlick_fresnel(p["f0"], cos_d)

    @classmethod
    def lobe(cls, g, c):
        p = cls.constants(c)
        denominator = g.cos_d.clamp(min=COS_MIN) * torch.maximum(g.cos_i, g.cos_o)
        return p["norm"] * cos_power_h(p["n"], g) * cls.fresnel(p, g.cos_d) / denominator

    @classmethod
    def init_shape(cls, alpha):
        return {"exponent": 2.0 / (alpha * alpha) - 2.0, "f0": 0.04}  # Beckmann-equivalent n in θh


class AshikhminShirleyIor(AshikhminShirley):
    """The Ashikhmin-Shirley specular lobe of `AshikhminShirley` with the unpolarised
    dielectric Fresnel of a relative IoR η (Cook and Torrance 1982) in place of Schlick's,
    as Löw, Kronander, Ynnerman and Unger fitted it ("BRDF models for accurate and
    efficient rendering of glossy surfaces", ACM TOG 2012; BBM's LowAshikhminShirley in
    low.h: a scaled model, so k_s = the published "albedo", and "fresnelReflectance" is
    then the IoR, e.g. 1.45). Coefficients: kd, ks (RGB), exponent, ior.
    """

    NAME = "ashikhmin_shirley_ior"
    PUBLISHED_AS = ("LowAshikhminShirley",)
    PUBLISHED_PARAMS = {"albedo": "ks", "fresnelReflectance": "ior", "sharpness": "exponent"}
    COEFFS = (
        _KD,
        _KS,
        Coefficient("exponent", 1, 50.0, 1e-3, 1e6, log=True),
        Coefficient("ior", 1, 1.5, 1.01, 50.0, log=True),
    )
    # the dielectric Fresnel 19 in place of Schlick's 6
    FLOPS = AshikhminShirley.FLOPS - 6 + 19

    @classmethod
    def _fresnel_constants(cls, c):
        return {"ior": c["ior"]}

    @classmethod
    def fresnel(cls, p, cos_d):
        return fresnel_dielectric(p["ior"], cos_d)

    @classmethod
    def init_shape(cls, alpha):
        return {"exponent": 2.0 / (alpha * alpha) - 2.0, "ior": 1.5}


MODELS: dict[str, type[NganBRDF]] = {
    cls.NAME: cls for cls in (Ward, WardDuer, Phong, BlinnPhongNgan, Lafortune, AshikhminShirley, AshikhminShirleyIor)
}
