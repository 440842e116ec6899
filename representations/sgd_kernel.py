"""drjit kernel of `sgd.SGD` (Bagher, Soler and Holzschuch's shifted gamma distribution model).

Follows `sgd.sgd_lobe` operation by operation in fp32 (same clamps, same order), one lobe per
RGB channel: every shape coefficient is per channel, so the per-material constants are
three opaque scalars each, formed on the host by `sgd.sgd_constants` in fp64 and rounded
once to fp32, exactly as `SGD._eval` forms them. Imported only by `SGD.drjit_kernel()`:
importing the representation imports neither drjit nor mitsuba.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from brdfbench.render.drjit_kernels import FLOAT32_EPS, FLOAT32_MAX, INV_PI, expm1, fp32_values, log1p, opaque

from .drjit_kernels import AnalyticKernel, _Geometry
from .sgd_terms import S_MAX, W_MAX, sgd_constants

FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def _g1(k: dict, j: int, psi):
    """Twin of sgd.sgd_g1 for channel j (ψ = π/2 − θ)."""
    above = psi < k["x_h"][j]
    q = dr.select(above, dr.minimum(psi * k["inv_x_h"][j], 1.0 - FLOAT32_EPS), 0.0)
    w = dr.minimum(k["w_h"][j] + k["k"][j] * log1p(-q), W_MAX)
    v = dr.minimum(k["e_star"][j] * expm1(w), W_MAX)
    g = dr.maximum(-k["one_plus_lam"][j] * expm1(v), 0.0)
    return dr.select(above, g, 1.0)


class SGDKernel(AnalyticKernel):
    """k_d/π + k_s ⊙ lobe with an RGB lobe (the base class's lobe is one for all channels)."""

    name = "sgd"

    def __init__(self, model):
        c = {name: v.to(torch.float32) for name, v in model.coeffs.items()}
        self.kd_pi = opaque(fp32_values(c["kd"] * INV_PI))
        self.ks = opaque(fp32_values(c["ks"]))
        constants = sgd_constants(model.shape_of(model.coeffs))  # fp64, as SGD._eval
        self.shape = {name: opaque(fp32_values(v.to(torch.float32))) for name, v in constants.items()}

    def lobe(self, g: _Geometry) -> list:
        """The three channels' lobes (twin of sgd.sgd_lobe)."""
        k = self.shape
        c2 = dr.maximum(g.cos2_h, FLOAT32_TINY)
        tan2 = g.sin2_h / c2
        log_c2 = dr.log(c2)
        psi_i = dr.atan2(g.cos_i, dr.sqrt(g.sin2_i))
        psi_o = dr.atan2(g.cos_o, dr.sqrt(g.sin2_o))
        m = 1.0 - g.cos_d
        m2 = m * m
        m5 = m2 * m2 * m
        inv_cc = 1.0 / (g.cos_i * g.cos_o)
        lobes = []
        for j in range(3):
            s = dr.minimum(k["alpha"][j] + tan2 * k["inv_alpha"][j], S_MAX)
            d = k["k_pi2"][j] * dr.exp(-s - k["p"][j] * dr.log(s) - 2.0 * log_c2)
            d = dr.select(g.cos2_h > 0, d, 0.0)
            shadow = _g1(k, j, psi_i) * _g1(k, j, psi_o)
            fresnel = dr.maximum(k["f0"][j] - k["f1"][j] * g.cos_d + k["one_minus_f0"][j] * m5, 0.0)
            lobes.append(d * shadow * fresnel * inv_cc)
        return lobes

    def eval(self, wi, wo):
        lobes = self.lobe(_Geometry(wi, wo))
        out = [kd + lobe * ks for kd, lobe, ks in zip(self.kd_pi, lobes, self.ks)]
        return mi.Color3f(*(dr.clip(v, 0.0, FLOAT32_MAX) for v in out))
