"""drjit twins of the built-in importance samplers (brdfbench/sampling/builtin.py).

A twin has `sample(wi, u) -> wo` (mi.Vector3f from local ωi and u ∈ [0, 1)², mi.Point2f)
and `pdf(wi, wo) -> mi.Float` (solid-angle density; 0 where ωi or ωo is at or below the
horizon), in drjit operations only, so it traces into Mitsuba's symbolic kernels. The
formulas follow the torch samplers operation by operation (same stable forms, clamps and
constants), so both agree to fp32 rounding.

`sampler_for(sampler)` returns what the sampler's `drjit_sampler()` hook returns (the one
hook for built-in and third-party samplers alike: same rules as a representation's
`drjit_kernel()`, see drjit_kernels.py); the built-ins' hooks build the twins below. A
sampler without the hook, or declining with None, runs in torch, the adapter then
rendering in evaluated mode. Always None in scalar variants.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .drjit_kernels import FLOAT32_MAX, div, expm1, log1p, native_hook

INV_PI = 1.0 / math.pi
INV_2PI = 1.0 / (2.0 * math.pi)
TWO_PI = 2.0 * math.pi
ALPHA_MIN, ALPHA_MAX, EXPONENT_MAX = 1e-6, 1e6, 1e12
#: The largest fp32 below 1: u is clamped into [0, 1) as Sampler.sample does.
BELOW_ONE = float(np.nextafter(np.float32(1.0), np.float32(0.0)))
FLOAT32_TINY = float(np.finfo(np.float32).tiny)


# --------------------------------------------------------------------------- helpers


def direction(cos_t, sin2_t, phi):
    """Unit vector from cos θ, sin² θ and φ (sampling/directions.py `direction`)."""
    sin_t = dr.sqrt(dr.maximum(sin2_t, 0.0))
    s, c = dr.sincos(phi)
    return mi.Vector3f(sin_t * c, sin_t * s, cos_t)


def reflect(wi, h):
    dot = wi.x * h.x + wi.y * h.y + wi.z * h.z
    return 2.0 * dot * h - wi


def sin2_theta(v):
    return dr.clip(v.x * v.x + v.y * v.y, 0.0, 1.0)


def norm(v):
    """Norm without under/overflow: rescaled by the largest component."""
    scale = dr.maximum(dr.maximum(dr.abs(v.x), dr.abs(v.y)), dr.abs(v.z))
    w = div(v, dr.select(scale > 0, scale, 1.0))
    return scale * dr.norm(w)


def log_cos_theta(v):
    """log cos θ: ½ log1p(−sin²θ) near the pole, log z near the horizon."""
    s2 = sin2_theta(v)
    near_pole = s2 <= 0.5
    z = dr.maximum(v.z, FLOAT32_TINY)
    return dr.select(near_pole, 0.5 * log1p(-dr.select(near_pole, s2, 0.0)), dr.log(z))


def half(wi, wo):
    """Half vector and |ωo·h| = |ωi + ωo|/2 of pairs above the horizon."""
    s = wi + wo
    scale = dr.maximum(dr.maximum(dr.abs(s.x), dr.abs(s.y)), dr.abs(s.z))
    s = div(s, scale)
    length = dr.norm(s)
    return div(s, length), 0.5 * (scale * length)


def _finite_max(x):
    return dr.minimum(x, FLOAT32_MAX)


def _f32(x: float) -> float:
    """A host constant rounded to fp32, as torch rounds a Python scalar into an fp32 op."""
    return float(np.float32(x))


# --------------------------------------------------------------------------- the twins


class DrSampler:
    """Base of the twins: clamps u, masks the horizon; subclasses give `_sample` and `_pdf`."""

    name = "sampler"

    def sample(self, wi: mi.Vector3f, u: mi.Point2f) -> mi.Vector3f:
        u = mi.Point2f(dr.minimum(dr.maximum(u.x, 0.0), BELOW_ONE), dr.minimum(dr.maximum(u.y, 0.0), BELOW_ONE))
        return self._sample(wi, u)

    def pdf(self, wi: mi.Vector3f, wo: mi.Vector3f) -> mi.Float:
        return dr.select((wi.z > 0) & (wo.z > 0), self._pdf(wi, wo), 0.0)

    def _sample(self, wi, u):
        raise NotImplementedError

    def _pdf(self, wi, wo):
        raise NotImplementedError


class _Hemisphere(DrSampler):
    def _sample(self, wi, u):
        cos_t, sin2_t = self._polar(u.x)
        return direction(cos_t, sin2_t, TWO_PI * u.y)


class UniformTwin(_Hemisphere):
    name = "uniform"

    def __init__(self, sampler):
        pass

    def _polar(self, u):
        return 1.0 - u, u * (2.0 - u)

    def _pdf(self, wi, wo):
        return dr.full(mi.Float, INV_2PI, dr.width(wo))


class CosineTwin(_Hemisphere):
    name = "cosine"

    def __init__(self, sampler):
        pass

    def _polar(self, u):
        return dr.sqrt(1.0 - u), u

    def _pdf(self, wi, wo):
        return wo.z * INV_PI


def _opaque(x: float):
    return dr.opaque(mi.Float, _f32(x))


class PowerCosineTwin(_Hemisphere):
    name = "power_cosine"

    def __init__(self, sampler):
        n = sampler._n
        self.n = _opaque(n)
        self.n1 = _opaque(n + 1.0)
        self.norm = _opaque((n + 1.0) * INV_2PI)

    def _polar(self, u):
        log_cos = log1p(-u) / self.n1
        return dr.exp(log_cos), -expm1(2.0 * log_cos)

    def _pdf(self, wi, wo):
        return _finite_max(self.norm * dr.exp(self.n * log_cos_theta(wo)))


class _Microfacet(DrSampler):
    def _sample(self, wi, u):
        cos_h, sin2_h = self._polar(u.x)
        return reflect(wi, direction(cos_h, sin2_h, TWO_PI * u.y))

    def _pdf(self, wi, wo):
        h, cos_d = half(wi, wo)
        return _finite_max(self._d_cos(h) / (4.0 * cos_d))


class BlinnPhongTwin(_Microfacet):
    name = "blinn_phong"

    def __init__(self, sampler):
        n = sampler._n
        self.n1 = _opaque(n + 1.0)
        self.n2 = _opaque(n + 2.0)
        self.norm = _opaque((n + 2.0) * INV_2PI)

    def _polar(self, u):
        log_cos = log1p(-u) / self.n2
        return dr.exp(log_cos), -expm1(2.0 * log_cos)

    def _d_cos(self, h):
        return self.norm * dr.exp(self.n1 * log_cos_theta(h))


def _polar_from_tan2(t):
    t = dr.minimum(t, 1e30)
    return dr.rsqrt(1.0 + t), t / (1.0 + t)


class BeckmannTwin(_Microfacet):
    name = "beckmann"

    def __init__(self, sampler):
        self.a2 = _opaque(sampler._a2)
        self.norm = _opaque(INV_PI / sampler._a2)

    def _polar(self, u):
        return _polar_from_tan2(self.a2 * -log1p(-u))

    def _d_cos(self, h):
        s2 = sin2_theta(h)
        c2 = h.z * h.z
        ok = c2 > 0
        c2 = dr.select(ok, c2, 1.0)
        log_value = -s2 / (self.a2 * c2) - 1.5 * dr.log(c2)
        return dr.select(ok, dr.exp(log_value) * self.norm, 0.0)


class GGXTwin(_Microfacet):
    name = "ggx"

    def __init__(self, sampler):
        self.a2 = _opaque(sampler._a2)
        self.d_norm = _opaque(sampler._a2 * INV_PI)

    def _polar(self, u):
        v = 1.0 - u
        d = v + self.a2 * u
        return dr.sqrt(v / d), self.a2 * u / d

    def _d_cos(self, h):
        q = self.a2 * h.z * h.z + sin2_theta(h)
        return self.d_norm / (q * q) * h.z


class GGXVisibleTwin(DrSampler):
    """Heitz (2018) visible-normal sampling, with the cancellation-free rim of builtin.GGXVisible."""

    name = "ggx_vndf"

    def __init__(self, sampler):
        a = sampler._a
        self.a = _opaque(a)
        self.a2 = _opaque(a * a)
        self.d_norm = _opaque(a * a * INV_PI)

    def _sample(self, wi, u):
        a = self.a
        v = mi.Vector3f(a * wi.x, a * wi.y, wi.z)
        v = div(v, dr.maximum(norm(v), FLOAT32_TINY))
        rho = dr.hypot(v.x, v.y)
        has_rho = rho > 0
        safe_rho = dr.select(has_rho, rho, 1.0)
        t1 = mi.Vector3f(dr.select(has_rho, -v.y / safe_rho, 1.0), dr.select(has_rho, v.x / safe_rho, 0.0), 0.0)
        t2 = dr.cross(v, t1)
        u1 = u.x
        one_minus_r2 = 1.0 - u1
        r = dr.sqrt(u1)
        sin_phi, cos_phi = dr.sincos(TWO_PI * u.y)
        p1, p2 = r * cos_phi, r * sin_phi
        b = dr.sqrt(one_minus_r2 + u1 * sin_phi * sin_phi)
        up = p2 >= 0
        b_minus = dr.select(up, one_minus_r2 / (b + dr.maximum(p2, 0.0)), b - p2)
        b_plus = dr.select(up, b + p2, one_minus_r2 / (b - dr.minimum(p2, 0.0)))
        rho2 = v.x * v.x + v.y * v.y
        one_minus_s = 0.5 * dr.select(v.z > 0, rho2 / (1.0 + v.z), 1.0 - v.z)
        s = 1.0 - one_minus_s
        p2s = one_minus_s * b + s * p2
        p3 = dr.sqrt(dr.maximum(s * b_minus * (2.0 * one_minus_s * b + s * b_plus), 0.0))
        m = p1 * t1 + p2s * t2 + p3 * v
        h = mi.Vector3f(a * m.x, a * m.y, dr.maximum(m.z, 0.0))
        h = div(h, dr.maximum(norm(h), FLOAT32_TINY))
        return reflect(wi, h)

    def _pdf(self, wi, wo):
        h, _ = half(wi, wo)
        cos_i = wi.z
        lam = cos_i + dr.sqrt(cos_i * cos_i + self.a2 * sin2_theta(wi))
        q = self.a2 * h.z * h.z + sin2_theta(h)
        return _finite_max(self.d_norm / (q * q) / (2.0 * lam))


def sampler_for(sampler) -> DrSampler | None:
    """The drjit twin of a sampler: what its `drjit_sampler()` hook returns (the built-ins
    return the twins above), else None (the torch path). Always None in scalar variants."""
    return native_hook(sampler, "drjit_sampler")
