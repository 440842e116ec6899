"""drjit kernels of the Ngan-family models (`ngan_models.py`), built by their `drjit_kernel()` hooks.

Each kernel follows its torch lobe operation by operation in fp32 (same clamps, same order);
the per-material constants are the model class's own `constants`, computed on the host in
fp32 torch as the torch path forms them. Imported only by the hooks: importing a
representation imports neither drjit nor mitsuba.
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from brdfbench.render.drjit_kernels import FLOAT32_EPS, log1p

from .analytic_terms import COS_MIN
from .drjit_kernels import AnalyticKernel, _schlick_fresnel, fresnel_dielectric

FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def mirror_gap(g):
    """Twin of ngan_models.mirror_gap."""
    dc = g.cos_i - g.cos_o
    return 2.0 * (g.cos_d * g.cos_d) * g.sin2_h + 0.5 * (dc * dc)


def cos_power(n, norm, y):
    """Twin of ngan_models.cos_power."""
    lobe = norm * dr.exp(n * log1p(-dr.minimum(y, 1.0 - FLOAT32_EPS)))
    return dr.select(y < 1.0, lobe, 0.0)


def cos_power_h(n, g):
    """Twin of ngan_models.cos_power_h."""
    log_c2 = dr.select(g.sin2_h < 0.5, log1p(-dr.minimum(g.sin2_h, 0.5)), dr.log(dr.maximum(g.cos2_h, FLOAT32_TINY)))
    return dr.select(g.cos2_h > 0, dr.exp(n * (0.5 * log_c2)), 0.0)


class NganKernel(AnalyticKernel):
    """k_d/π + k_s · lobe with the per-material constants of the model class's `constants`."""

    model_name = ""

    def __init__(self, model):
        self.model_cls = type(model)  # taken from the model: this module imports no model
        super().__init__(model)

    def constants(self, c):
        return self.model_cls.constants(c)


class WardKernel(NganKernel):
    name = "ward"
    model_name = "ward"

    def peak(self, g):
        p = self.shape
        tan2 = g.sin2_h / dr.maximum(g.cos2_h, FLOAT32_TINY)
        return p["norm"] * dr.exp(tan2 * p["neg_inv_a2"])

    def lobe(self, g):
        return self.peak(g) / dr.sqrt(g.cos_i * g.cos_o)


class WardDuerKernel(WardKernel):
    name = "ward_duer"
    model_name = "ward_duer"

    def lobe(self, g):
        return self.peak(g) / (g.cos_i * g.cos_o)


class PhongKernel(NganKernel):
    name = "phong"
    model_name = "phong"

    def lobe(self, g):
        return cos_power(self.shape["n"], self.shape["norm"], mirror_gap(g))


class BlinnPhongNganKernel(NganKernel):
    name = "blinn_phong_ngan"
    model_name = "blinn_phong_ngan"

    def lobe(self, g):
        return self.shape["norm"] * cos_power_h(self.shape["n"], g)


class LafortuneKernel(NganKernel):
    name = "lafortune"
    model_name = "lafortune"

    def lobe(self, g):
        p = self.shape
        dc = g.cos_i - g.cos_o
        cc = g.cos_i * g.cos_o
        one_minus_cc = 0.5 * ((dc * dc) + (g.sin2_i + g.sin2_o))
        one_minus_dot = 2.0 * g.sin2_d
        y = (p["w_forward"] * mirror_gap(g) + p["w_retro"] * one_minus_dot
             + p["w_normal"] * one_minus_cc + p["w_cc"] * cc)
        return cos_power(p["n"], p["norm"], y)


class AshikhminShirleyKernel(NganKernel):
    name = "ashikhmin_shirley"
    model_name = "ashikhmin_shirley"

    def fresnel(self, cos_d):
        return _schlick_fresnel(self.shape["f0"], self.shape["one_minus_f0"], cos_d)

    def lobe(self, g):
        p = self.shape
        denominator = dr.maximum(g.cos_d, COS_MIN) * dr.maximum(g.cos_i, g.cos_o)
        return p["norm"] * cos_power_h(p["n"], g) * self.fresnel(g.cos_d) / denominator


class AshikhminShirleyIorKernel(AshikhminShirleyKernel):
    name = "ashikhmin_shirley_ior"
    model_name = "ashikhmin_shirley_ior"

    def fresnel(self, cos_d):
        return fresnel_dielectric(self.shape["ior"], cos_d)


#: The kernel of each model class (exactly that class: a subclass may change its lobe).
KERNELS = {k.model_name: k for k in (WardKernel, WardDuerKernel, PhongKernel, BlinnPhongNganKernel, LafortuneKernel,
                                    AshikhminShirleyKernel, AshikhminShirleyIorKernel)}
