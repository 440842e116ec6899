"""drjit twins of the analytic models' importance samplers (brdfbench/sampling/lobes.py).

Same contract as drjit_samplers.py (whose base class and helpers these reuse): `sample`
and `pdf` in drjit operations, following the torch formulas operation by operation. One
difference: the torch cosine lobes evaluate their density in float64 for fp32 inputs; the
twin evaluates the same formulas in fp32, so near a lobe's rim (cos α → 0, where the inner
product with the axis cancels) it agrees with torch to fp32 rounding in absolute terms,
not relatively. The samplers' hooks (`drjit_sampler()`) build these; this module reads the
samplers' attributes and imports no sampler module.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .drjit_kernels import div, expm1, log1p
from .drjit_samplers import (
    FLOAT32_TINY,
    INV_2PI,
    TWO_PI,
    DrSampler,
    _finite_max,
    _opaque,
    _polar_from_tan2,
    half,
    log_cos_theta,
    norm,
    reflect,
)

#: lobes.RIM_EPS · ε(fp32): samples keep cos α at least this far from their lobe's rim.
LOG_RIM_FLOOR = math.log(64.0 * float(np.finfo(np.float32).eps))


def _dot(a, b):
    return a.x * b.x + a.y * b.y + a.z * b.z


# --------------------------------------------------------------------------- microfacet


class _AnisotropicTwin(DrSampler):
    """h with tan φ = k tan(2πu₂), reflected (lobes._Anisotropic)."""

    def _sample(self, wi, u):
        s, c = dr.sincos(TWO_PI * u.y)
        x, y = c, self.k * s
        r = dr.sqrt(x * x + y * y)
        cos_p, sin_p = x / r, y / r
        cos_h, sin2_h = self._polar(u.x, cos_p, sin_p)
        sin_h = dr.sqrt(dr.maximum(sin2_h, 0.0))
        return reflect(wi, mi.Vector3f(sin_h * cos_p, sin_h * sin_p, cos_h))

    def _pdf(self, wi, wo):
        h, cos_d = half(wi, wo)
        return _finite_max(self._density_h(h) / (4.0 * cos_d))


class WardTwin(_AnisotropicTwin):
    name = "ward"

    def __init__(self, sampler):
        self.k = _opaque(sampler._k)
        self.ax2, self.ay2 = _opaque(sampler._ax2), _opaque(sampler._ay2)
        self.ax2ay2 = _opaque(sampler._ax2 * sampler._ay2)
        self.norm = _opaque(sampler._norm)

    def _polar(self, u, cos_p, sin_p):
        b = self.ax2ay2 / (self.ay2 * cos_p * cos_p + self.ax2 * sin_p * sin_p)
        return _polar_from_tan2(b * -log1p(-u))

    def _density_h(self, h):
        c2 = h.z * h.z
        ok = c2 > 0
        c2 = dr.select(ok, c2, 1.0)
        q = h.x * h.x / self.ax2 + h.y * h.y / self.ay2
        return dr.select(ok, dr.exp(-q / c2 - 1.5 * dr.log(c2)) * self.norm, 0.0)


class AshikhminShirleyTwin(_AnisotropicTwin):
    name = "ashikhmin_shirley"

    def __init__(self, sampler):
        self.k = _opaque(sampler._k)
        self.nu, self.nv = _opaque(sampler._nu), _opaque(sampler._nv)
        self.norm = _opaque(sampler._norm)

    def _polar(self, u, cos_p, sin_p):
        e = self.nu * cos_p * cos_p + self.nv * sin_p * sin_p
        log_cos = log1p(-u) / (e + 1.0)
        return dr.exp(log_cos), -expm1(2.0 * log_cos)

    def _density_h(self, h):
        x2, y2 = h.x * h.x, h.y * h.y
        s2 = x2 + y2
        has_phi = s2 > 0
        e = dr.select(has_phi, (self.nu * x2 + self.nv * y2) / dr.select(has_phi, s2, 1.0), self.nu)
        return self.norm * dr.exp(e * log_cos_theta(h))


# --------------------------------------------------------------------------- cosine lobes


def _frame(a):
    """Duff et al. (2017)'s orthonormal basis about the unit vector a (lobes._frame)."""
    s = dr.select(a.z >= 0, 1.0, -1.0)
    k = -1.0 / (s + a.z)
    b = a.x * a.y * k
    return mi.Vector3f(1.0 + s * a.x * a.x * k, s * b, -s * a.x), mi.Vector3f(b, s + a.y * a.y * k, -a.y)


class CosineLobeTwin(DrSampler):
    """`phong` and `lafortune` (lobes._CosineLobe): a cosine lobe about a(ωi)."""

    name = "cosine_lobe"

    def __init__(self, sampler):
        self.cxy, self.cz = _opaque(sampler._cxy), _opaque(sampler._cz)
        self.n, self.n1 = _opaque(sampler._n), _opaque(sampler._n + 1.0)
        self.norm = _opaque((sampler._n + 1.0) * INV_2PI)

    def _axis(self, wi):
        a = mi.Vector3f(self.cxy * wi.x, self.cxy * wi.y, self.cz * wi.z)
        length = norm(a)
        zero = length == 0
        return dr.select(zero, mi.Vector3f(0.0, 0.0, 1.0), div(a, dr.select(zero, 1.0, length)))

    def _sample(self, wi, u):
        a = self._axis(wi)
        log_cos = dr.maximum(log1p(-u.x) / self.n1, LOG_RIM_FLOOR)
        cos_a, sin_a = dr.exp(log_cos), dr.sqrt(-expm1(2.0 * log_cos))
        s, c = dr.sincos(TWO_PI * u.y)
        t1, t2 = _frame(a)
        return (sin_a * c) * t1 + (sin_a * s) * t2 + cos_a * a

    def _pdf(self, wi, wo):
        a = self._axis(wi)
        w2 = _dot(wo, wo)
        d = wo - a
        perp = d - _dot(d, a) * a
        sin2 = _dot(perp, perp) / w2
        cos_a = _dot(wo, a) / dr.sqrt(w2)
        near = (sin2 <= 0.5) & (cos_a > 0)
        log_cos = dr.select(near, 0.5 * log1p(-dr.select(near, sin2, 0.0)), dr.log(dr.maximum(cos_a, FLOAT32_TINY)))
        return _finite_max(dr.select(cos_a > 0, self.norm * dr.exp(self.n * log_cos), 0.0))
