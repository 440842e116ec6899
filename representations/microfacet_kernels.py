"""drjit kernels of `microfacet_models.py` (Beckmann Cook-Torrance variants, Löw et al.'s models).

Each follows its torch lobe operation by operation in fp32 (same clamps, same order; the
per-material constants are computed on the host with the same torch ops), so the two agree
to fp32 rounding. Imported only by the models' `drjit_kernel()` hooks: importing a
representation imports neither drjit nor mitsuba.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

from brdfbench.render.drjit_kernels import log1p

from .analytic_terms import BECKMANN_M_MIN as ROUGHNESS_MIN
from .drjit_kernels import INV_PI, AnalyticKernel, _Geometry, _schlick_fresnel, fresnel_dielectric

FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def _beckmann_unnormalised(inv_m2, g: _Geometry):
    """Twin of microfacet_models.beckmann_unnormalised."""
    c2 = dr.maximum(g.cos2_h, FLOAT32_TINY)
    d = dr.exp(-((g.sin2_h / c2) * inv_m2) - 2.0 * dr.log(c2)) * inv_m2
    return dr.select(g.cos2_h > 0, d, 0.0)


def _vgroove_over_cc(g: _Geometry):
    """Twin of microfacet_models.vgroove_over_cc."""
    two_hz = 2.0 * dr.sqrt(g.cos2_h)
    den = dr.maximum(dr.maximum(g.cos_i, g.cos_o) * g.cos_d, FLOAT32_TINY)
    return dr.minimum(1.0 / (g.cos_i * g.cos_o), two_hz / den)


def _abc_power(b, c, x):
    """Twin of microfacet_models.abc_power."""
    return dr.exp(-c * log1p(b * x))


def _beckmann_constants(c):
    m = c["roughness"].clamp(min=ROUGHNESS_MIN)
    return {"inv_m2": 1.0 / (m * m)}


class CookTorranceBeckmannKernel(AnalyticKernel):
    name = "cook_torrance_beckmann"

    @staticmethod
    def constants(c):
        return {**_beckmann_constants(c), "f0": c["eta"], "one_minus_f0": 1.0 - c["eta"]}

    def lobe(self, g):
        p = self.shape
        d = _beckmann_unnormalised(p["inv_m2"], g) * (1.0 / math.pi**2)
        return d * _vgroove_over_cc(g) * _schlick_fresnel(p["f0"], p["one_minus_f0"], g.cos_d)


class CookTorrance1982Kernel(AnalyticKernel):
    name = "cook_torrance_1982"

    @staticmethod
    def constants(c):
        return {**_beckmann_constants(c), "eta": c["eta"]}

    def lobe(self, g):
        p = self.shape
        d = _beckmann_unnormalised(p["inv_m2"], g) * INV_PI
        return d * _vgroove_over_cc(g) * fresnel_dielectric(p["eta"], g.cos_d)


class LowSmoothKernel(AnalyticKernel):
    name = "low_smooth"

    @staticmethod
    def constants(c):
        return {"b4": 4.0 * c["B"], "C": c["C"], "eta": c["eta"]}

    def lobe(self, g):
        p = self.shape
        x = (g.cos_d * g.cos_d) * g.sin2_h
        s = _abc_power(p["b4"], p["C"], x)
        cos2 = 0.5 * (g.cos_i * g.cos_i + g.cos_o * g.cos_o) + x
        return s * fresnel_dielectric(p["eta"], dr.sqrt(dr.minimum(cos2, 1.0)))


class LowMicrofacetKernel(AnalyticKernel):
    name = "low_microfacet"

    @staticmethod
    def constants(c):
        return {"B": c["B"], "C": c["C"], "eta": c["eta"]}

    def lobe(self, g):
        p = self.shape
        s = _abc_power(p["B"], p["C"], g.sin2_h / (1.0 + dr.sqrt(g.cos2_h)))
        s = dr.select(g.cos2_h > 0, s, 0.0)
        return s * _vgroove_over_cc(g) * fresnel_dielectric(p["eta"], g.cos_d) * INV_PI
