"""drjit kernel of `lafortune_lobes.LafortuneLobes` (several generalised cosine lobes).

Follows the torch lobe operation by operation in fp32: the shared terms once, each lobe as
`ngan_kernels.LafortuneKernel` forms it, then per channel k_d/π + k_s (L₁ + Σ w_j L_j). The
per-lobe constants are the model class's own `lobe_constants`, computed on the host in fp32
torch as the torch path forms them. Imported only by the model's `drjit_kernel()` hook;
imports no model module.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import torch

from brdfbench.render.drjit_kernels import FLOAT32_MAX, INV_PI, fp32_values, opaque

from .drjit_kernels import AnalyticKernel, _Geometry
from .ngan_kernels import cos_power, mirror_gap


class LafortuneLobesKernel(AnalyticKernel):
    name = "lafortune_lobes"

    def __init__(self, model):
        c = {k: v.to(torch.float32) for k, v in model.coeffs.items()}
        self.kd_pi = opaque(fp32_values(c["kd"] * INV_PI))
        self.ks = opaque(fp32_values(c["ks"]))
        cls = type(model)  # taken from the model: this module imports no model
        scalars = {k: v[0] for k, v in c.items()}
        self.lobes = [{k: opaque(fp32_values(v))[0] for k, v in p.items()} for p in cls.lobe_constants(scalars)]
        self.weights = [opaque(fp32_values(c[f"weight{j}"])) for j in range(2, cls.LOBES + 1)]

    def _lobes(self, g: _Geometry) -> list:
        dc = g.cos_i - g.cos_o
        cc = g.cos_i * g.cos_o
        gap = mirror_gap(g)
        one_minus_dot = 2.0 * g.sin2_d
        one_minus_cc = 0.5 * ((dc * dc) + (g.sin2_i + g.sin2_o))
        out = []
        for p in self.lobes:
            y = p["w_forward"] * gap + p["w_retro"] * one_minus_dot + p["w_normal"] * one_minus_cc + p["w_cc"] * cc
            out.append(cos_power(p["n"], p["norm"], y))
        return out

    def eval(self, wi, wo):
        first, *rest = self._lobes(_Geometry(wi, wo))
        out = []
        for ch, (kd, ks) in enumerate(zip(self.kd_pi, self.ks)):
            total = first
            for value, weight in zip(rest, self.weights):
                total = total + value * weight[ch]
            out.append(kd + total * ks)
        return mi.Color3f(*(dr.clip(v, 0.0, FLOAT32_MAX) for v in out))
