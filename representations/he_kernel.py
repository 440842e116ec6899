"""drjit kernel of `he_model.He` (He et al.'s directional-diffuse term as Ngan et al. fitted it).

Follows `he_model.he_lobe` operation by operation in fp32 (same clamps, same windows, the
same terms in the same order), one lobe per RGB channel; the per-material constants are the
model class's own `constants`, computed on the host in fp32 torch as the torch path forms
them. Where the torch path sums each element's series on one branch (its subset), every lane
here computes both and selects. drjit has no erfc: `erfc` is a Chebyshev fit accurate to
1.2e-7 relative, as fp32 needs (torch's is exact).
Imported only by `He.drjit_kernel()`: this module imports neither the model nor, with the
representation, drjit.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from brdfbench.render.drjit_kernels import FLOAT32_MAX, log1p

from .drjit_kernels import _Geometry
from .he_terms import (HALF_LOG_2PI, INV_SQRT_8PI, INV_SQRT_PI, LOG_CAP, M_SWITCH, N_DOWN, N_STRIDED, N_UP, S_MIN,
                       STIRLERR, T_HI, T_LO, U_MAX)
from .ngan_kernels import NganKernel

FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def lambert_w_log(L):
    """Twin of he_model.lambert_w_log."""
    lc = dr.maximum(L, -40.0)
    z = dr.exp(dr.minimum(lc, 1.0))
    lz = log1p(z)
    small = lz * (1.0 - log1p(lz) / (2.0 + lz))
    big_l = dr.maximum(lc, 1.0)
    log_big = dr.log(big_l)
    w = dr.select(lc < 1.0, small, big_l - log_big + log_big / big_l)
    for _ in range(4):
        w = w * (1.0 + lc - dr.log(w)) / (1.0 + w)
    return dr.select(L < -40.0, dr.exp(dr.minimum(L, -40.0)), w)


def stirlerr_series(m):
    """Twin of he_model.stirlerr_series."""
    r = 1.0 / m
    r2 = r * r
    return r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 * (1.0 / 1680.0 - r2 / 1188.0))))


def stirlerr(m):
    """Twin of he_model.stirlerr."""
    out = stirlerr_series(m)
    for k in range(7, 0, -1):
        out = dr.select(m < k + 0.5, STIRLERR[k - 1], out)
    return out


def bd0(x, mean, diff):
    """Twin of he_model.bd0."""
    v = diff / (x + mean)
    w = v * v
    p = 1.0 / 3.0 + w * (1.0 / 5.0 + w * (1.0 / 7.0 + w * (1.0 / 9.0 + w / 11.0)))
    series = diff * v + 2.0 * x * (v * w) * p
    direct = x * dr.log(x / mean) - diff
    return dr.select(dr.abs(v) < 0.05, series, direct)


def log_term(m, g, a):
    """Twin of he_model.log_term."""
    return -bd0(m, g, m - g) - 1.5 * dr.log(m) - HALF_LOG_2PI - stirlerr(m) - a / m


def series_peak(g, a, log_g):
    """Twin of he_model.series_peak."""
    w = lambert_w_log(math.log(2.0) + dr.log(dr.maximum(a, FLOAT32_TINY)) - 2.0 * log_g)
    m = dr.maximum(g * dr.exp(0.5 * w), 1.0)
    for _ in range(2):
        r = log_g - dr.log(m + 0.5) - 1.0 / m + a / (m * m)
        d = -m / (m + 0.5) + 1.0 / m - 2.0 * a / (m * m)
        m = dr.maximum(m * dr.exp(dr.clip(-r / dr.minimum(d, -1e-3), -3.0, 3.0)), 1.0)
    curvature = 1.0 / (m + 0.5) - 1.0 / (m * m) + 2.0 * a / (m * m * m)
    return m, dr.rsqrt(dr.maximum(curvature, 1e-12))


def integer_window(g, a, m_c):
    """Twin of he_model._integer_window (the same steps, summed in order)."""
    m_r = dr.maximum(dr.round(m_c), 1.0)
    above = mi.Float(0.0)
    c = mi.Float(0.0)
    for k in range(N_UP):
        m = m_r + float(k)
        c = c + (dr.log((g / (m + 1.0)) * (m / (m + 1.0))) + a / (m * (m + 1.0)))
        above = above + dr.exp(dr.minimum(c, LOG_CAP))
    below = mi.Float(0.0)
    c = mi.Float(0.0)
    for k in range(N_DOWN):
        m = m_r - float(k)
        d = dr.maximum(m, 2.0)
        c = c - (dr.log((g / d) * ((d - 1.0) / d)) + a / ((d - 1.0) * d))
        below = below + dr.select(m >= 2.0, dr.exp(dr.minimum(c, LOG_CAP)), 0.0)
    return log_term(m_r, g, a) + dr.log(1.0 + above + below)


def trapezoid(g, a, log_g, m_c, s):
    """Twin of he_model._trapezoid."""
    low = dr.minimum(T_LO * s, m_c - 1.0)
    h = (low + T_HI * s) / (N_STRIDED - 1)
    log_gm = dr.log(g / m_c)
    st_c = stirlerr_series(m_c)
    total = mi.Float(0.0)
    for k in range(N_STRIDED):
        d = float(k) * h - low
        x = m_c + d
        log_ratio = (-bd0(x, m_c, d) + d * log_gm - 1.5 * log1p(d / m_c)
                     - (stirlerr_series(x) - st_c) + a * d / (x * m_c))
        total = total + dr.exp(log_ratio)
    return log_term(m_c, g, a) + dr.log(h * total)


def he_log_series(g, a):
    """Twin of he_model.he_log_series: both branches, selected per lane."""
    g = dr.maximum(g, FLOAT32_TINY)
    log_g = dr.log(g)
    m_c, s = series_peak(g, a, log_g)
    strided = (m_c >= M_SWITCH) & (s >= S_MIN)
    return dr.select(strided, trapezoid(g, a, log_g, m_c, s), integer_window(g, a, m_c))


def fresnel(eta, cos_d):
    """Twin of he_model.fresnel."""
    c = cos_d
    e = (eta - 1.0) * (eta + 1.0)
    g = dr.sqrt(e + c * c)
    s = dr.maximum(g + c, FLOAT32_TINY)
    g_minus_c = e / s
    a = g_minus_c / s
    b = (c * s - 1.0) / (c * g_minus_c + 1.0)
    return dr.clip(0.5 * a * a * (1.0 + b * b), 0.0, 1.0)


def erfc(u):
    """erfc(u) for u ≥ 0 to 1.2e-7 relative (the Chebyshev fit of Press et al., Numerical
    Recipes §6.2): 1 − erf(u) would lose it where K = tanθ erfc(u) is large (grazing θ, u ~ 3)."""
    t = 1.0 / (1.0 + 0.5 * u)
    poly = -1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806 + t * (
        0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))))
    return t * dr.exp(poly - u * u)


def log_shadowing(q, cos, sin2):
    """Twin of he_model.log_shadowing."""
    u = dr.minimum(q * cos * dr.rsqrt(dr.maximum(sin2, FLOAT32_TINY)), U_MAX)
    e = erfc(u)
    lam = 0.5 * (dr.exp(-u * u) * INV_SQRT_PI / u - e)
    return log1p(-0.5 * e) - log1p(lam), q * e / u


class HeKernel(NganKernel):
    """k_d/π + k_s ⊙ ρ_dd with an RGB lobe (one series per channel's wavelength)."""

    name = "he"
    model_name = "he"

    def lobe(self, g: _Geometry) -> list:
        """The three channels' ρ_dd (twin of he_model.he_lobe)."""
        p = self.shape
        vz = g.cos_i + g.cos_o
        cd2 = dr.maximum(g.cos_d * g.cos_d, FLOAT32_TINY)
        vxy2 = 4.0 * cd2 * g.sin2_h
        log_s_i, k_i = log_shadowing(p["q"], g.cos_i, g.sin2_i)
        log_s_o, k_o = log_shadowing(p["q"], g.cos_o, g.sin2_o)
        f0 = dr.maximum((k_i + k_o) * INV_SQRT_8PI, FLOAT32_TINY)
        one_plus_w = 1.0 + lambert_w_log(2.0 * dr.log(f0))
        f = fresnel(p["ior"], g.cos_d)
        shared = (log_s_i + log_s_o) + 2.0 * dr.log(4.0 * cd2 / vz) - dr.log(math.pi * (g.cos_i * g.cos_o))
        vz2 = vz * vz / one_plus_w
        lobes = []
        for c in range(3):
            log_sum = he_log_series(p[f"b{c}"] * vz2, p[f"a{c}"] * vxy2)
            lobes.append(f * dr.exp(shared + p[f"log_norm{c}"] + log_sum))
        return lobes

    def eval(self, wi, wo):
        lobes = self.lobe(_Geometry(wi, wo))
        out = [kd + lobe * ks for kd, lobe, ks in zip(self.kd_pi, lobes, self.ks)]
        return mi.Color3f(*(dr.clip(v, 0.0, FLOAT32_MAX) for v in out))

