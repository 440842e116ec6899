"""The six importance samplers of Hu 2026 (Table 3.1, Appendix A), and GGX VNDF.

Hemisphere samplers draw ωo about the normal, independently of ωi: `uniform`, `cosine`,
`power_cosine`. Microfacet samplers draw the half vector h about the normal with density
D(h) cosθh and reflect ωi about it: `blinn_phong`, `beckmann`, `ggx`; `ggx_vndf` draws h
from the distribution of normals visible from ωi (Heitz 2018). Hu 2026's microfacet pdfs
are corrected:

- the density of ωo is D(h) cosθh / (4 |ωo·h|), the Jacobian of the reflection
  (Hu 2026 gives D(h) cosθh);
- the Beckmann NDF is exp(−tan²θh/α²) / (π α² cos⁴θh): Hu 2026 drops the 1/π, so its
  "CDF" π(1 − exp(−tan²θh/α²)) runs to π, and its sample() inverts that, as
  tan²θh = −α² ln(1 − ξ/π); here tan²θh = −α² ln(1 − ξ).

Stable forms, accurate in fp32 and fp64 for α down to 1e-3 (exponents to 1e6 and
beyond), at θi up to 89.9°, and finite for u at 0 and at 1 − ε:

- every polar angle is produced as the pair (cos θ, sin²θ), with sin²θ computed without
  cancellation: u(2 − u) (uniform), u (cosine), −expm1(2 log cos θ) with log cos θ =
  log1p(−u)/(n + 1) (power cosine, Blinn-Phong), and for a tan²θ = t the pair
  (1/(1 + t), t/(1 + t)), where t = α²·(−log1p(−u)) (Beckmann) or, for GGX, the pair
  ((1 − u)/((1 − u) + α²u), α²u/((1 − u) + α²u)), which has no cancellation at all;
- densities take sin²θh = h_x² + h_y² and cos²θh = h_z² from the half vector's
  components (h = (ωi + ωo)/|ωi + ωo|, the sum rescaled before its norm: for pairs above
  the horizon it has z > 0, so it never vanishes), and cosⁿ as exp(n log cos θ) with
  `log_cos_theta` (log1p near the pole, log z near the horizon);
- |ωo·h| = |ωi + ωo| / 2, a norm, never a vanishing difference.

α is clamped to [ALPHA_MIN, ALPHA_MAX] and exponents to ≤ EXPONENT_MAX in the
arithmetic (sample and pdf alike, so they stay consistent): beyond those, fp32 would
underflow α² or overflow the peak density. Densities are clamped to the dtype's largest
finite value (a guard for pairs within rounding of ωi + ωo = 0, where 1/|ωo·h| blows up).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import torch

from ..errors import ConfigError
from . import Sampler
from .directions import TWO_PI, direction, log_cos_theta, norm, reflect, sin2_theta

Tensor = torch.Tensor

INV_PI = 1.0 / math.pi
INV_2PI = 1.0 / (2.0 * math.pi)
ALPHA_MIN = 1e-6
ALPHA_MAX = 1e6
EXPONENT_MAX = 1e12


def _real(sampler: str, key: str, value: Any, *, minimum: float, strict: bool) -> float:
    """A finite real parameter ≥ (or >) minimum, else a ConfigError naming key and value."""
    bound = f"> {minimum:g}" if strict else f">= {minimum:g}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ConfigError(f"sampler {sampler!r}: parameter {key}={value!r} must be a finite number {bound}")
    v = float(value)
    if not math.isfinite(v) or v < minimum or (strict and v == minimum):
        raise ConfigError(f"sampler {sampler!r}: parameter {key}={value!r} must be a finite number {bound}")
    return v


def _finite_max(x: Tensor) -> Tensor:
    return x.clamp(max=torch.finfo(x.dtype).max)


def _alpha_to_exponent(alpha: float) -> float:
    """Beckmann-equivalent exponent n = 2/α² − 2 (Walter et al. 2007), ≥ 0."""
    return max(0.0, 2.0 / (alpha * alpha) - 2.0)


# --------------------------------------------------------------------------- hemisphere


class _Hemisphere(Sampler):
    tags = frozenset({"hemisphere"})

    def _sample(self, wi: Tensor, u: Tensor) -> Tensor:
        cos_t, sin2_t = self._polar(u[:, 0])
        return direction(cos_t, sin2_t, TWO_PI * u[:, 1])

    def _polar(self, u: Tensor) -> tuple[Tensor, Tensor]:
        """(cos θ, sin² θ) of the polar angle for variates u in [0, 1)."""
        raise NotImplementedError


class Uniform(_Hemisphere):
    """Uniform hemisphere sampling: pdf(ωo) = 1/(2π), cos θ = 1 − u₁.

    .. pluginparameters::

     * - (none)
       -
       - ωo does not depend on ωi.
    """

    def __init__(self) -> None:
        super().__init__()

    def _polar(self, u):
        return 1.0 - u, u * (2.0 - u)

    def _pdf(self, wi, wo):
        return torch.full((wo.shape[0],), INV_2PI, dtype=wo.dtype)

    DRJIT_TWIN = "drjit_samplers:UniformTwin"


class Cosine(_Hemisphere):
    """Cosine-weighted hemisphere sampling: pdf(ωo) = cos θo / π, cos θ = √(1 − u₁).

    .. pluginparameters::

     * - (none)
       -
       - ωo does not depend on ωi.
    """

    def __init__(self) -> None:
        super().__init__()

    def _polar(self, u):
        return torch.sqrt(1.0 - u), u

    def _pdf(self, wi, wo):
        return wo[:, 2] * INV_PI

    DRJIT_TWIN = "drjit_samplers:CosineTwin"


class PowerCosine(_Hemisphere):
    """Power-cosine hemisphere sampling: pdf(ωo) = (n + 1) cosⁿθo / (2π),
    cos θ = (1 − u₁)^(1/(n+1)).

    .. pluginparameters::

     * - exponent
       - |float|
       - The exponent n: finite, ≥ 0 (default: 100). n = 0 is uniform, n = 1 cosine
         sampling; used as min(n, EXPONENT_MAX = 1e12).
    """

    def __init__(self, exponent: float = 100.0) -> None:
        n = _real("power_cosine", "exponent", exponent, minimum=0.0, strict=False)
        super().__init__(exponent=n)
        self._n = min(n, EXPONENT_MAX)

    @classmethod
    def roughness_params(cls, alpha):
        return {"exponent": _alpha_to_exponent(alpha)}

    def _polar(self, u):
        log_cos = torch.log1p(-u) / (self._n + 1.0)
        return torch.exp(log_cos), -torch.expm1(2.0 * log_cos)

    def _pdf(self, wi, wo):
        n = self._n
        return _finite_max((n + 1.0) * INV_2PI * torch.exp(n * log_cos_theta(wo)))

    DRJIT_TWIN = "drjit_samplers:PowerCosineTwin"


# --------------------------------------------------------------------------- microfacet


class _Microfacet(Sampler):
    """h drawn about the normal with density D(h) cosθh; ωo = 2(ωi·h)h − ωi."""

    tags = frozenset({"microfacet"})

    def _sample(self, wi: Tensor, u: Tensor) -> Tensor:
        cos_h, sin2_h = self._polar(u[:, 0])
        h = direction(cos_h, sin2_h, TWO_PI * u[:, 1])
        return reflect(wi, h)

    def _pdf(self, wi: Tensor, wo: Tensor) -> Tensor:
        h, cos_d = _half(wi, wo)
        return _finite_max(self._d_cos(h) / (4.0 * cos_d))

    def _polar(self, u: Tensor) -> tuple[Tensor, Tensor]:
        """(cos θh, sin² θh) for variates u in [0, 1)."""
        raise NotImplementedError

    def _d_cos(self, h: Tensor) -> Tensor:
        """D(h) cos θh for half vectors above the horizon."""
        raise NotImplementedError


def _half(wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor]:
    """Half vector h and |ωo·h| = |ωi + ωo|/2 of pairs above the horizon (ωi + ωo has z > 0,
    so it never vanishes; it is rescaled first so that a tiny sum does not underflow)."""
    s = wi + wo
    scale = s.abs().amax(dim=-1, keepdim=True)
    s = s / scale
    length = torch.linalg.vector_norm(s, dim=-1, keepdim=True)
    return s / length, 0.5 * (scale * length)[:, 0]


def _polar_from_tan2(t: Tensor) -> tuple[Tensor, Tensor]:
    """(cos θ, sin² θ) from tan² θ = t ≥ 0 (clamped finite)."""
    t = t.clamp(max=1e30)
    return torch.rsqrt(1.0 + t), t / (1.0 + t)


class BlinnPhong(_Microfacet):
    """Blinn-Phong microfacet sampling: D(h) cos θh = (n + 2) cos^(n+1)θh / (2π),
    cos θh = (1 − u₁)^(1/(n+2)); pdf(ωo) = D(h) cos θh / (4 |ωo·h|).

    .. pluginparameters::

     * - exponent
       - |float|
       - The Blinn-Phong exponent n: finite, ≥ 0 (default: 100); used as
         min(n, EXPONENT_MAX = 1e12). n = 2/α² − 2 matches Beckmann roughness α.
    """

    def __init__(self, exponent: float = 100.0) -> None:
        n = _real("blinn_phong", "exponent", exponent, minimum=0.0, strict=False)
        super().__init__(exponent=n)
        self._n = min(n, EXPONENT_MAX)

    @classmethod
    def roughness_params(cls, alpha):
        return {"exponent": _alpha_to_exponent(alpha)}

    def _polar(self, u):
        log_cos = torch.log1p(-u) / (self._n + 2.0)
        return torch.exp(log_cos), -torch.expm1(2.0 * log_cos)

    def _d_cos(self, h):
        n = self._n
        return (n + 2.0) * INV_2PI * torch.exp((n + 1.0) * log_cos_theta(h))

    DRJIT_TWIN = "drjit_samplers:BlinnPhongTwin"


class Beckmann(_Microfacet):
    """Beckmann microfacet sampling: D(h) = exp(−tan²θh/α²) / (π α² cos⁴θh),
    tan²θh = −α² log(1 − u₁); pdf(ωo) = D(h) cos θh / (4 |ωo·h|).

    .. pluginparameters::

     * - alpha
       - |float|
       - Roughness α (RMS slope of the microfacets): finite, > 0 (default: 0.1); used
         clamped to [ALPHA_MIN, ALPHA_MAX] = [1e-6, 1e6].
    """

    def __init__(self, alpha: float = 0.1) -> None:
        a = _real("beckmann", "alpha", alpha, minimum=0.0, strict=True)
        super().__init__(alpha=a)
        self._a2 = min(max(a, ALPHA_MIN), ALPHA_MAX) ** 2

    @classmethod
    def roughness_params(cls, alpha):
        return {"alpha": alpha}

    def _polar(self, u):
        return _polar_from_tan2(self._a2 * -torch.log1p(-u))

    def _d_cos(self, h):
        s2 = sin2_theta(h)
        c2 = h[:, 2] * h[:, 2]
        ok = c2 > 0
        c2 = torch.where(ok, c2, torch.ones_like(c2))
        # exp(−tan²/α²) / (π α² cos³), with cos³ = exp(1.5 log cos²) to keep tiny cosines finite
        log_value = -s2 / (self._a2 * c2) - 1.5 * torch.log(c2)
        value = torch.exp(log_value) * (INV_PI / self._a2)
        return torch.where(ok, value, torch.zeros_like(value))

    DRJIT_TWIN = "drjit_samplers:BeckmannTwin"


class GGX(_Microfacet):
    """GGX (Trowbridge-Reitz) microfacet sampling: D(h) = α² / (π cos⁴θh (α² + tan²θh)²),
    tan²θh = α² u₁/(1 − u₁); pdf(ωo) = D(h) cos θh / (4 |ωo·h|).

    .. pluginparameters::

     * - alpha
       - |float|
       - Roughness α: finite, > 0 (default: 0.1); used clamped to
         [ALPHA_MIN, ALPHA_MAX] = [1e-6, 1e6].
    """

    def __init__(self, alpha: float = 0.1) -> None:
        a = _real("ggx", "alpha", alpha, minimum=0.0, strict=True)
        super().__init__(alpha=a)
        self._a2 = min(max(a, ALPHA_MIN), ALPHA_MAX) ** 2

    @classmethod
    def roughness_params(cls, alpha):
        return {"alpha": alpha}

    def _polar(self, u):
        v = 1.0 - u  # exact for u ≥ ½ (Sterbenz), where it is small
        d = v + self._a2 * u
        return torch.sqrt(v / d), self._a2 * u / d

    def _d_cos(self, h):
        return _ggx_d(self._a2, h) * h[:, 2]

    DRJIT_TWIN = "drjit_samplers:GGXTwin"


def _ggx_d(a2: float, h: Tensor) -> Tensor:
    """GGX D(h) = α² / (π (α² cos²θh + sin²θh)²): no cancellation, finite at grazing h."""
    q = a2 * h[:, 2] * h[:, 2] + sin2_theta(h)
    return a2 * INV_PI / (q * q)


class GGXVisible(Sampler):
    """GGX sampling of the normals visible from ωi (Heitz 2018): h has density
    G1(ωi) max(0, ωi·h) D(h) / cos θi, so pdf(ωo) = G1(ωi) D(h) / (4 cos θi)
    = D(h) / (2 (cos θi + √(cos²θi + α² sin²θi))).

    .. pluginparameters::

     * - alpha
       - |float|
       - Roughness α: finite, > 0 (default: 0.1); used clamped to
         [ALPHA_MIN, ALPHA_MAX] = [1e-6, 1e6].
    """

    tags = frozenset({"microfacet"})

    def __init__(self, alpha: float = 0.1) -> None:
        a = _real("ggx_vndf", "alpha", alpha, minimum=0.0, strict=True)
        super().__init__(alpha=a)
        self._a = min(max(a, ALPHA_MIN), ALPHA_MAX)

    @classmethod
    def roughness_params(cls, alpha):
        return {"alpha": alpha}

    def _sample(self, wi, u):
        a = self._a
        # ωi in the configuration where the GGX surface of roughness α is stretched to α = 1
        v = torch.stack((a * wi[:, 0], a * wi[:, 1], wi[:, 2]), dim=-1)
        v = v / norm(v).clamp(min=torch.finfo(v.dtype).tiny)[:, None]
        # a frame (t1, t2, v) about it; t1 is horizontal
        rho = torch.hypot(v[:, 0], v[:, 1])
        has_rho = rho > 0
        safe_rho = torch.where(has_rho, rho, torch.ones_like(rho))
        t1 = torch.stack(
            (
                torch.where(has_rho, -v[:, 1] / safe_rho, torch.ones_like(rho)),
                torch.where(has_rho, v[:, 0] / safe_rho, torch.zeros_like(rho)),
                torch.zeros_like(rho),
            ),
            dim=-1,
        )
        t2 = torch.linalg.cross(v, t1)
        # a uniform point (p1, p2) of the unit disk, its lower half squeezed onto the
        # visible projection of the hemisphere: p2' = (1 − s) b + s p2, b = √(1 − p1²),
        # s = (1 + v_z)/2; then p3 = √(1 − p1² − p2'²). Near the rim that difference
        # cancels (in fp32 it is all rounding for u₁ → 1, and at α = 1e-3 p3 decides θh), so
        # it is formed as b² − p2'² = s (b − p2)(2(1 − s) b + s (b + p2)), with
        # b² = (1 − u₁) + u₁ sin²φ and b ∓ p2 = (1 − u₁)/(b ± p2) on the side that cancels.
        u1 = u[:, 0]
        one_minus_r2 = 1.0 - u1
        phi = TWO_PI * u[:, 1]
        r = torch.sqrt(u1)
        sin_phi = torch.sin(phi)
        p1, p2 = r * torch.cos(phi), r * sin_phi
        b = torch.sqrt(one_minus_r2 + u1 * sin_phi * sin_phi)  # > 0 for u₁ < 1
        up = p2 >= 0
        b_minus = torch.where(up, one_minus_r2 / (b + p2.clamp(min=0.0)), b - p2)
        b_plus = torch.where(up, b + p2, one_minus_r2 / (b - p2.clamp(max=0.0)))
        rho2 = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]
        one_minus_s = 0.5 * torch.where(v[:, 2] > 0, rho2 / (1.0 + v[:, 2]), 1.0 - v[:, 2])
        s = 1.0 - one_minus_s
        p2s = one_minus_s * b + s * p2
        p3 = torch.sqrt((s * b_minus * (2.0 * one_minus_s * b + s * b_plus)).clamp(min=0.0))
        m = p1[:, None] * t1 + p2s[:, None] * t2 + p3[:, None] * v
        # back to roughness α
        h = torch.stack((a * m[:, 0], a * m[:, 1], m[:, 2].clamp(min=0.0)), dim=-1)
        h = h / norm(h).clamp(min=torch.finfo(h.dtype).tiny)[:, None]
        return reflect(wi, h)

    def _pdf(self, wi, wo):
        a2 = self._a * self._a
        h, _ = _half(wi, wo)
        cos_i = wi[:, 2]
        lam = cos_i + torch.sqrt(cos_i * cos_i + a2 * sin2_theta(wi))
        return _finite_max(_ggx_d(a2, h) / (2.0 * lam))

    DRJIT_TWIN = "drjit_samplers:GGXVisibleTwin"
