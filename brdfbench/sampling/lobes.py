"""Importance samplers of the literature's analytic BRDF models (representations/ngan_models.py).

Microfacet samplers (half vector h drawn about the normal, ωi reflected about it,
pdf(ωo) = p(h) / (4 |ωo·h|)): `ward` (Ward 1992, with Walter's 2005 pdf) and
`ashikhmin_shirley` (Ashikhmin & Shirley 2000), both anisotropic. Cosine-lobe samplers
(ωo drawn about an axis that depends on ωi, pdf (n + 1)/(2π) max(0, cos α)^n, α the angle
to the axis): `phong` (the mirror direction, Lafortune & Willems 1994) and `lafortune`
(one generalised cosine lobe, Lafortune et al. 1997). A sample below the horizon is a valid
sample of density 0 (a lobe whose axis is tilted from the normal reaches below it).

Numerics as in builtin.py (stable forms, clamps, fp32 and fp64 alike), and:

- both microfacet azimuths, tan φ = k tan(2πu₂), are formed as (cos φ, sin φ) ∝
  (cos 2πu₂, k sin 2πu₂): the papers' four-quadrant map, with no tan to blow up; u₂
  drives φ and u₁ θ, as in builtin.py (the papers swap them);
- Ward's −log u₁ is −log1p(−u₁) here: the same distribution, finite at u₁ = 0;
- a lobe's frame is Duff et al.'s branchless orthonormal basis; cos α of a sample is
  floored at 64 ε of the dtype, so that rounding never puts a sample just outside the
  lobe it was drawn from (a sliver of mass (64 ε)^(n+1) moves onto that rim);
- a lobe's density is computed in float64 (the axis, sin²α and cos α for fp32 inputs
  too, then rounded once): cos α is an inner product with an arbitrary axis, which
  cancels near the lobe's rim in the input dtype, and sin²α = |ωo − (ωo·a)a|² (as a
  perpendicular part of ωo − a, no cancellation at the peak) keeps n up to 1e12 resolved.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import torch

from ..errors import ConfigError
from . import Sampler
from .builtin import ALPHA_MAX, ALPHA_MIN, EXPONENT_MAX, INV_2PI, INV_PI, _finite_max, _half, _polar_from_tan2, _real
from .directions import TWO_PI, log_cos_theta, norm, reflect

Tensor = torch.Tensor

#: Samples keep cos α ≥ RIM_EPS · ε(dtype) from their lobe's rim.
RIM_EPS = 64.0


def _exponent_for_mirror_lobe(alpha: float) -> float:
    """n = 1/(2α²) − ½: a lobe about the mirror direction is twice as wide (in ωo) as the
    Beckmann h lobe of roughness α, exp(−θo²/(4α²)) ≈ cosⁿθo; α = 1 gives n = 0."""
    return max(0.0, 0.5 / (alpha * alpha) - 0.5)


def _exponent_for_half_vector(alpha: float) -> float:
    """n = 2/α² − 2, the Beckmann-equivalent exponent of a cosⁿθh lobe (as builtin.py)."""
    return max(0.0, 2.0 / (alpha * alpha) - 2.0)


# --------------------------------------------------------------------------- microfacet


class _Anisotropic(Sampler):
    """h about the normal with an elliptic azimuth, tan φ = k tan(2πu₂); ωo = reflect(ωi, h)."""

    tags = frozenset({"microfacet"})
    _k: float  # the azimuth's stretch k

    def _sample(self, wi, u):
        psi = TWO_PI * u[:, 1]
        x, y = torch.cos(psi), self._k * torch.sin(psi)
        r = torch.sqrt(x * x + y * y)  # ≥ min(1, k)·(1 − ε): never 0
        cos_p, sin_p = x / r, y / r
        cos_h, sin2_h = self._polar(u[:, 0], cos_p, sin_p)
        sin_h = torch.sqrt(sin2_h.clamp(min=0.0))
        h = torch.stack((sin_h * cos_p, sin_h * sin_p, cos_h), dim=-1)
        return reflect(wi, h)

    def _pdf(self, wi, wo):
        h, cos_d = _half(wi, wo)
        return _finite_max(self._density_h(h) / (4.0 * cos_d))

    def _polar(self, u, cos_p, sin_p):
        """(cos θh, sin² θh) for variates u in [0, 1) at azimuth (cos φ, sin φ)."""
        raise NotImplementedError

    def _density_h(self, h):
        """p(h), the solid-angle density of h, for half vectors above the horizon."""
        raise NotImplementedError


class Ward(_Anisotropic):
    """Anisotropic Ward half-vector sampling: Ward, "Measuring and modeling anisotropic
    reflection" (SIGGRAPH 1992), with the density of Walter, "Notes on the Ward BRDF"
    (tech. report PCG-05-06, Cornell, 2005), who shows Ward's sampling draws h from

    p(h) = exp(−tan²θh (cos²φh/α_x² + sin²φh/α_y²)) / (π α_x α_y cos³θh),

    by tan φh = (α_y/α_x) tan(2πu₂), tan²θh = −log(1 − u₁)/(cos²φh/α_x² + sin²φh/α_y²);
    pdf(ωo) = p(h) / (4 |ωo·h|). Isotropic (α_x = α_y) it is `beckmann`'s D(h) cos θh.

    .. pluginparameters::

     * - alpha_x
       - |float|
       - Roughness along x (the tangent): finite, > 0 (default: 0.1); used clamped to
         [ALPHA_MIN, ALPHA_MAX] = [1e-6, 1e6].
     * - alpha_y
       - |float|
       - Roughness along y: finite, > 0 (default: alpha_x, isotropic); clamped likewise.
    """

    def __init__(self, alpha_x: float = 0.1, alpha_y: float | None = None) -> None:
        ax = _real("ward", "alpha_x", alpha_x, minimum=0.0, strict=True)
        ay = ax if alpha_y is None else _real("ward", "alpha_y", alpha_y, minimum=0.0, strict=True)
        super().__init__(alpha_x=ax, alpha_y=ay)
        self._ax = min(max(ax, ALPHA_MIN), ALPHA_MAX)
        self._ay = min(max(ay, ALPHA_MIN), ALPHA_MAX)
        self._k = self._ay / self._ax
        self._ax2, self._ay2 = self._ax * self._ax, self._ay * self._ay
        self._norm = INV_PI / (self._ax * self._ay)

    @classmethod
    def roughness_params(cls, alpha):
        """α_x = α (α_y follows unless given: isotropic Ward is Beckmann of roughness α)."""
        return {"alpha_x": alpha}

    def _polar(self, u, cos_p, sin_p):
        # 1/(cos²φ/α_x² + sin²φ/α_y²) = α_x² α_y² / (α_y² cos²φ + α_x² sin²φ)
        b = self._ax2 * self._ay2 / (self._ay2 * cos_p * cos_p + self._ax2 * sin_p * sin_p)
        return _polar_from_tan2(b * -torch.log1p(-u))

    def _density_h(self, h):
        c2 = h[:, 2] * h[:, 2]
        ok = c2 > 0
        c2 = torch.where(ok, c2, torch.ones_like(c2))
        # tan²θh cos²φh = h_x²/h_z², tan²θh sin²φh = h_y²/h_z²; cos³ as exp(1.5 log cos²)
        q = h[:, 0] * h[:, 0] / self._ax2 + h[:, 1] * h[:, 1] / self._ay2
        value = torch.exp(-q / c2 - 1.5 * torch.log(c2)) * self._norm
        return torch.where(ok, value, torch.zeros_like(value))

    DRJIT_TWIN = "drjit_lobe_samplers:WardTwin"


class AshikhminShirley(_Anisotropic):
    """Ashikhmin-Shirley half-vector sampling: Ashikhmin and Shirley, "An anisotropic Phong
    BRDF model" (Journal of Graphics Tools 5(2), 2000):

    p(h) = √((n_u + 1)(n_v + 1)) / (2π) · cos^(n_u cos²φh + n_v sin²φh) θh,

    by φh = atan(√((n_u + 1)/(n_v + 1)) tan(πξ₁/2)) over the four quadrants (here
    tan φh = √((n_u + 1)/(n_v + 1)) tan(2πu₂)) and cos θh = (1 − u₁)^(1/(n_u cos²φh +
    n_v sin²φh + 1)); pdf(ωo) = p(h) / (4 |ωo·h|). Isotropic with n_u = n_v = n + 1 it is
    `blinn_phong`'s D(h) cos θh of exponent n.

    .. pluginparameters::

     * - nu
       - |float|
       - Exponent n_u (along x, the tangent): finite, ≥ 0 (default: 100); used as
         min(n_u, EXPONENT_MAX = 1e12).
     * - nv
       - |float|
       - Exponent n_v (along y): finite, ≥ 0 (default: nu, isotropic); clamped likewise.
    """

    def __init__(self, nu: float = 100.0, nv: float | None = None) -> None:
        a = _real("ashikhmin_shirley", "nu", nu, minimum=0.0, strict=False)
        b = a if nv is None else _real("ashikhmin_shirley", "nv", nv, minimum=0.0, strict=False)
        super().__init__(nu=a, nv=b)
        self._nu, self._nv = min(a, EXPONENT_MAX), min(b, EXPONENT_MAX)
        self._k = math.sqrt(self._nu + 1.0) / math.sqrt(self._nv + 1.0)
        self._norm = math.sqrt(self._nu + 1.0) * math.sqrt(self._nv + 1.0) * INV_2PI

    @classmethod
    def roughness_params(cls, alpha):
        """n_u = 2/α² − 2, the Beckmann-equivalent exponent in θh (n_v follows unless given)."""
        return {"nu": _exponent_for_half_vector(alpha)}

    def _polar(self, u, cos_p, sin_p):
        e = self._nu * cos_p * cos_p + self._nv * sin_p * sin_p
        log_cos = torch.log1p(-u) / (e + 1.0)
        return torch.exp(log_cos), -torch.expm1(2.0 * log_cos)

    def _density_h(self, h):
        x2, y2 = h[:, 0] * h[:, 0], h[:, 1] * h[:, 1]
        s2 = x2 + y2
        has_phi = s2 > 0  # at the pole cos^e θh = 1 for any e
        e = torch.where(has_phi, (self._nu * x2 + self._nv * y2) / torch.where(has_phi, s2, torch.ones_like(s2)),
                        torch.full_like(s2, self._nu))
        return self._norm * torch.exp(e * log_cos_theta(h))

    DRJIT_TWIN = "drjit_lobe_samplers:AshikhminShirleyTwin"


# --------------------------------------------------------------------------- cosine lobes


def _frame(a: Tensor) -> tuple[Tensor, Tensor]:
    """Two unit vectors completing unit vectors a (N, 3) to right-handed orthonormal frames:
    Duff, Burgess, Christensen, Hery, Kensler, Liani and Villemin, "Building an orthonormal
    basis, revisited" (JCGT 6(1), 2017), listing 3."""
    x, y, z = a.unbind(-1)
    s = torch.where(z >= 0, torch.ones_like(z), -torch.ones_like(z))
    k = -1.0 / (s + z)
    b = x * y * k
    t1 = torch.stack((1.0 + s * x * x * k, s * b, -s * x), dim=-1)
    t2 = torch.stack((b, s + y * y * k, -y), dim=-1)
    return t1, t2


class _CosineLobe(Sampler):
    """ωo about a unit axis a(ωi) with pdf (n + 1)/(2π) max(0, cos α)^n, α = ∠(ωo, a)."""

    _cxy: float
    _cz: float

    def __init__(self, exponent: float, **params: Any) -> None:
        super().__init__(**params, exponent=exponent)
        self._n = min(exponent, EXPONENT_MAX)
        self._norm = (self._n + 1.0) * INV_2PI

    @classmethod
    def roughness_params(cls, alpha):
        return {"exponent": _exponent_for_mirror_lobe(alpha)}

    def axis(self, wi: Tensor) -> Tensor:
        """The unit lobe axes (N, 3), float64: (C_xy ωi_x, C_xy ωi_y, C_z ωi_z) normalised;
        the normal where that vector is exactly 0 (e.g. C_z = 0 at normal incidence)."""
        w = wi.to(torch.float64)
        a = torch.stack((self._cxy * w[:, 0], self._cxy * w[:, 1], self._cz * w[:, 2]), dim=-1)
        length = norm(a)
        zero = length == 0
        normal = torch.zeros_like(a)
        normal[:, 2] = 1.0
        return torch.where(zero[:, None], normal, a / torch.where(zero, torch.ones_like(length), length)[:, None])

    def _sample(self, wi, u):
        a = self.axis(wi).to(wi.dtype)
        floor = math.log(RIM_EPS * torch.finfo(wi.dtype).eps)
        log_cos = (torch.log1p(-u[:, 0]) / (self._n + 1.0)).clamp(min=floor)
        cos_a, sin_a = torch.exp(log_cos), torch.sqrt(-torch.expm1(2.0 * log_cos))
        phi = TWO_PI * u[:, 1]
        t1, t2 = _frame(a)
        return (sin_a * torch.cos(phi))[:, None] * t1 + (sin_a * torch.sin(phi))[:, None] * t2 + cos_a[:, None] * a

    def _pdf(self, wi, wo):
        a = self.axis(wi)
        w = wo.to(torch.float64)
        w2 = (w * w).sum(-1)
        d = w - a  # exact near the peak (Sterbenz); ωo's part perpendicular to a is d's
        perp = d - (d * a).sum(-1, keepdim=True) * a
        sin2 = (perp * perp).sum(-1) / w2
        cos_a = (w * a).sum(-1) / torch.sqrt(w2)
        near = (sin2 <= 0.5) & (cos_a > 0)
        log_cos = torch.where(near, 0.5 * torch.log1p(-torch.where(near, sin2, torch.zeros_like(sin2))),
                              torch.log(cos_a.clamp(min=torch.finfo(torch.float64).tiny)))
        p = torch.where(cos_a > 0, self._norm * torch.exp(self._n * log_cos), torch.zeros_like(log_cos))
        return _finite_max(p.to(wi.dtype))


class Phong(_CosineLobe):
    """Modified Phong lobe sampling: Lafortune and Willems, "Using the modified Phong
    reflectance model for physically based rendering" (tech. report CW197, KU Leuven, 1994):
    ωo about the mirror direction r = (−ωi_x, −ωi_y, ωi_z) with

    pdf(ωo) = (n + 1)/(2π) cosⁿα, α = ∠(ωo, r) < 90°,

    by cos α = (1 − u₁)^(1/(n+1)), azimuth 2πu₂ about r. The part of the lobe below the
    horizon gives valid samples of density 0.

    .. pluginparameters::

     * - exponent
       - |float|
       - The Phong exponent n: finite, ≥ 0 (default: 100); used as min(n, EXPONENT_MAX =
         1e12). Roughness α maps to n = 1/(2α²) − ½ (the reflected Beckmann lobe's width).
    """

    _cxy, _cz = -1.0, 1.0

    def __init__(self, exponent: float = 100.0) -> None:
        super().__init__(_real("phong", "exponent", exponent, minimum=0.0, strict=False))

    DRJIT_TWIN = "drjit_lobe_samplers:CosineLobeTwin"


def _coefficient(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise ConfigError(f"sampler 'lafortune': parameter {key}={value!r} must be a finite number")
    return float(value)


class Lafortune(_CosineLobe):
    """One generalised cosine lobe of Lafortune, Foo, Torrance and Greenberg, "Non-linear
    approximation of reflectance functions" (SIGGRAPH 1997), sampled as Lafortune and
    Willems (1994) sample a Phong lobe: the lobe max(0, C_xy(ωi_x ωo_x + ωi_y ωo_y) +
    C_z ωi_z ωo_z)^n is |A|ⁿ max(0, cos α)ⁿ about the axis A = (C_xy ωi_x, C_xy ωi_y,
    C_z ωi_z), so ωo is drawn about a = A/|A| with

    pdf(ωo) = (n + 1)/(2π) max(0, cos α)ⁿ, α = ∠(ωo, a).

    C_xy = −1, C_z = 1 is `phong`; C_xy = 0, C_z = 1 is `power_cosine` (above the
    horizon). Where A = 0 for one ωi (C_z = 0 at normal incidence, C_xy = 0 on the horizon)
    the lobe falls back to the normal.

    .. pluginparameters::

     * - cxy
       - |float|
       - C_xy: finite (default: −1; < 0 reflects forward, > 0 back towards ωi).
     * - cz
       - |float|
       - C_z: finite (default: 1); not 0 together with cxy.
     * - exponent
       - |float|
       - The lobe exponent n: finite, ≥ 0 (default: 100); used as min(n, EXPONENT_MAX =
         1e12). Roughness α maps to n = 1/(2α²) − ½, as for `phong`.
    """

    def __init__(self, cxy: float = -1.0, cz: float = 1.0, exponent: float = 100.0) -> None:
        self._cxy, self._cz = _coefficient("cxy", cxy), _coefficient("cz", cz)
        if self._cxy == 0.0 and self._cz == 0.0:
            raise ConfigError("sampler 'lafortune': parameters cxy=0 and cz=0 leave the lobe without an axis")
        super().__init__(_real("lafortune", "exponent", exponent, minimum=0.0, strict=False), cxy=self._cxy, cz=self._cz)

    DRJIT_TWIN = "drjit_lobe_samplers:CosineLobeTwin"
