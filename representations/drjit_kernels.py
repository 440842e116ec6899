"""drjit kernels of the built-in representations, built by their `drjit_kernel()` hooks.

The same hook a third party implements (rules in brdfbench.render.drjit_kernels, whose
helpers and table kernels these build on). Each kernel follows its torch model operation
by operation (same clamps, same order of the per-material constants, computed on the host
with the same torch ops), so the two agree to fp32 rounding. Imported only by the hooks,
inside them: importing a representation imports neither drjit nor mitsuba.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from brdfbench import merl
from brdfbench.nbrdf.network import MAX_LOG_VALUE, Network, n_layers
from brdfbench.render.drjit_kernels import (FLOAT32_EPS, FLOAT32_MAX, INV_PI, Kernel, MerlTableKernel,
                                            MerlTrilinearKernel, div, expm1, fp32_values, half_vector, log1p,
                                            opaque, safe_divisor, table_kernel, to_half_frame)

from .analytic_terms import ALPHA_MIN, COS_MIN
from .triplane_model import WARP_R_MIN

# --------------------------------------------------------------------------- tables


def merl_kernel(model) -> Kernel | None:
    """The table of a fitted `merl` model: nearest cell (also downsampled) or trilinear."""
    if model.mode == "trilinear":
        return None if model.table is None else table_kernel(model.table.values, name="merl_trilinear",
                                                              cls=MerlTrilinearKernel)
    if model.downsample == 1:
        if model.table is None:
            return None
        return table_kernel(model.table.values, name="merl")
    if model.samples is None:
        return None
    scales = np.asarray(merl.CHANNEL_SCALES).reshape(3, 1, 1, 1)
    return MerlTableKernel(model.samples * scales, model.downsample, name=f"merl_downsample{model.downsample}")


def pca_kernel(model) -> Kernel | None:
    """The MERL table a fitted `pca` model reconstructed, by nearest cell."""
    if model.coefficients is None:
        return None
    return MerlTableKernel(model.table.values, name="pca")


# --------------------------------------------------------------------------- analytic


class LambertKernel(Kernel):
    name = "lambert"

    def __init__(self, model):
        self.rho_pi = opaque(fp32_values(model.albedo / math.pi))

    def eval(self, wi, wo):
        return mi.Color3f(*self.rho_pi)


class _Geometry:
    """Twin of analytic_terms.geometry (fp32, same clamps)."""

    COS_MIN = COS_MIN

    def __init__(self, wi, wo):
        h = half_vector(wi, wo)
        hz = dr.maximum(h.z, 0.0)
        s = wi + wo
        self.cos_i = dr.clip(wi.z, self.COS_MIN, 1.0)
        self.cos_o = dr.clip(wo.z, self.COS_MIN, 1.0)
        self.sin2_i = dr.clip(wi.x * wi.x + wi.y * wi.y, 0.0, 1.0)
        self.sin2_o = dr.clip(wo.x * wo.x + wo.y * wo.y, 0.0, 1.0)
        self.cos2_h = hz * hz
        self.sin2_h = dr.clip(h.x * h.x + h.y * h.y, 0.0, 1.0)
        self.cos_d = dr.clip(0.5 * dr.norm(s), 0.0, 1.0)
        self.dot_xy = dr.clip(wi.x * wo.x + wi.y * wo.y, -1.0, 1.0)
        d = wi - wo
        self.sin2_d = dr.clip(0.25 * (d.x * d.x + d.y * d.y + d.z * d.z), 0.0, 1.0)


def _ggx_ndf(a2, g: _Geometry):
    q = a2 * g.cos2_h + g.sin2_h
    return a2 / (math.pi * q * q)


def fresnel_dielectric(eta, cos_d):
    """Twin of analytic_terms.fresnel_dielectric (fp32, same clamps)."""
    c = cos_d
    e = (eta - 1.0) * (eta + 1.0)
    g2 = e + c * c
    g = dr.sqrt(dr.maximum(g2, 0.0))
    s = dr.maximum(g + c, np.finfo(np.float32).tiny)
    g_minus_c = e / s
    a = g_minus_c / s
    b = (c * s - 1.0) / (c * g_minus_c + 1.0)
    f = 0.5 * a * a * (1.0 + b * b)
    return dr.select(g2 > 0, dr.clip(f, 0.0, 1.0), 1.0)


def _schlick_fresnel(f0, one_minus_f0, cos_d):
    m = 1.0 - cos_d
    m2 = m * m
    return f0 + one_minus_f0 * (m2 * m2 * m)


class AnalyticKernel(Kernel):
    """k_d/π + k_s · lobe, clamped to [0, fp32 max]; subclasses define `lobe`."""

    def __init__(self, model):
        c = {k: v.to(torch.float32) for k, v in model.coeffs.items()}
        self.kd_pi = opaque(fp32_values(c["kd"] * INV_PI))
        self.ks = opaque(fp32_values(c["ks"]))
        self.shape = {k: opaque(fp32_values(v))[0] for k, v in self.constants({k: v[0] for k, v in c.items()}).items()}

    @staticmethod
    def constants(c: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Per-material scalars of the lobe, in fp32 torch ops as analytic.py forms them."""
        raise NotImplementedError

    def lobe(self, g: _Geometry):
        raise NotImplementedError

    def eval(self, wi, wo):
        lobe = self.lobe(_Geometry(wi, wo))
        out = [kd + lobe * ks for kd, ks in zip(self.kd_pi, self.ks)]
        return mi.Color3f(*(dr.clip(v, 0.0, FLOAT32_MAX) for v in out))


class CookTorranceKernel(AnalyticKernel):
    name = "cook_torrance"

    @staticmethod
    def constants(c):
        alpha = (c["roughness"] * c["roughness"]).clamp(min=ALPHA_MIN)
        k = 0.5 * alpha * alpha
        r = (c["ior"] - 1.0) / (c["ior"] + 1.0)
        f0 = r * r
        return {"a2": alpha * alpha, "k": k, "one_minus_k": 1.0 - k, "f0": f0, "one_minus_f0": 1.0 - f0}

    def lobe(self, g):
        p = self.shape
        k, one_minus_k = p["k"], p["one_minus_k"]
        geometric = 0.25 / ((g.cos_i * one_minus_k + k) * (g.cos_o * one_minus_k + k))
        return _ggx_ndf(p["a2"], g) * geometric * _schlick_fresnel(p["f0"], p["one_minus_f0"], g.cos_d)


class GGXKernel(AnalyticKernel):
    name = "ggx"

    @staticmethod
    def constants(c):
        alpha = c["alpha"].clamp(min=ALPHA_MIN)
        return {"a2": alpha * alpha, "f0": c["f0"], "one_minus_f0": 1.0 - c["f0"]}

    def lobe(self, g):
        p = self.shape
        a2 = p["a2"]
        ai = dr.sqrt(g.cos_i * g.cos_i + a2 * g.sin2_i)
        ao = dr.sqrt(g.cos_o * g.cos_o + a2 * g.sin2_o)
        smith = 0.5 / (g.cos_o * ai + g.cos_i * ao)
        return _ggx_ndf(a2, g) * smith * _schlick_fresnel(p["f0"], p["one_minus_f0"], g.cos_d)


class BlinnPhongKernel(AnalyticKernel):
    name = "blinn_phong"

    @staticmethod
    def constants(c):
        n = c["exponent"].clamp(min=0.0)
        return {"n": n, "norm": (n + 8.0) / (8.0 * math.pi)}

    def lobe(self, g):
        p = self.shape
        log_cos = 0.5 * log1p(-dr.minimum(g.sin2_h, 1.0 - FLOAT32_EPS))
        lobe = p["norm"] * dr.exp(p["n"] * log_cos)
        return dr.select(g.cos2_h > 0, lobe, 0.0)


# --------------------------------------------------------------------------- neural


def opaque_layer(w: torch.Tensor, b: torch.Tensor) -> tuple[list, list]:
    """A dense layer's kernel (in, out) and bias as opaque scalars: the kernel's columns
    (one list of `in` weights per output) and the biases, the form `dense_layers` reads."""
    w = w.to(torch.float32).numpy()
    flat = opaque(w)
    return ([[flat[r * w.shape[1] + c] for r in range(w.shape[0])] for c in range(w.shape[1])],
            opaque(b.to(torch.float32).numpy()))


def dense_layers(x: list, layers: list, activation) -> list:
    """Dense layers as fused multiply-adds over per-input lists: `layers` holds (columns of
    opaque weights, opaque biases) per layer, `activation` follows every layer but the last;
    a None input is a constant 0 and is skipped."""
    for layer, (cols, bias) in enumerate(layers):
        out = []
        for col, b in zip(cols, bias):
            acc = b
            for xi, w in zip(x, col):
                if xi is not None:
                    acc = dr.fma(xi, w, acc)
            out.append(acc)
        x = out if layer == len(layers) - 1 else [activation(v) for v in out]
    return x


class MLPKernel(Kernel):
    """The NBRDF / naive MLP network (brdfbench.nbrdf.network): dense layers with ReLU,
    then expm1(min(z, MAX_LOG_VALUE)) clamped at 0, times the channel scales.

    Every weight is an opaque scalar, so materials of one architecture share one compiled
    kernel. The price: inside Mitsuba's BSDF call, per-instance inputs are read from the
    call's data with a packet gather per 8 values, which is slower than weights baked in
    as literals, which would compile a kernel per material.
    """

    def __init__(self, network: Network, name: str):
        self.name = name
        self.features = network.features
        weights = network.weights
        self.layers = [opaque_layer(weights[f"W{i}"], weights[f"b{i}"]) for i in range(1, n_layers(weights) + 1)]
        self.scale = opaque(network.output_scale.numpy())

    def inputs(self, wi, wo) -> list:
        if self.features == "directions":
            return [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]
        # Rusinkiewicz (sin θh, 0, cos θh, d): the unit h and the unit ωi in h's frame are
        # these very sines and cosines, without the angles' atan2 / sin / cos round trip.
        h = half_vector(wi, wo)
        rho_h = dr.hypot(h.x, h.y)
        d = to_half_frame(wi, h, rho_h)
        d = div(d, safe_divisor(dr.norm(d)))
        return [rho_h, None, h.z, d.x, d.y, d.z]

    def eval(self, wi, wo):
        x = dense_layers(self.inputs(wi, wo), self.layers, lambda v: dr.maximum(v, 0.0))
        values = []
        for z, scale in zip(x, self.scale):
            z = dr.minimum(z, MAX_LOG_VALUE)
            values.append(dr.select(z > 0, expm1(z), 0.0) * scale)
        return mi.Color3f(*values)


# --------------------------------------------------------------------------- tripleplane


class TripleplaneKernel(Kernel):
    """The tripleplane model (triplane_model.py) in drjit: the two texture reads gather from
    per-material arrays (the difference texture with its pole row broadcast over φ, as the
    torch read builds it), the decoder's weights are opaque scalars; so materials of one
    size share one compiled kernel. SiLU is v / (1 + exp(−v)); exp last, clamped."""

    name = "tripleplane"

    def __init__(self, shape, tensors: dict[str, torch.Tensor]):
        self.shape = shape
        self.name = "triplane_gated" if shape.latent or shape.warps else "tripleplane"
        c_h, c_d = shape.channels
        r_d, p_d = shape.d_res
        g = max(1, shape.latent)  # channels per feature in a texel (a C × D_s matrix when gated)
        self.h_tex = mi.Float(tensors["H"].to(torch.float32).reshape(-1).numpy().copy())
        pole = tensors["D_pole"].to(torch.float32).reshape(1, 1, c_d * g).expand(1, p_d, c_d * g)
        grid = torch.cat((pole, tensors["D"].to(torch.float32).reshape(r_d - 1, p_d, c_d * g)), dim=0)
        self.d_tex = mi.Float(grid.reshape(-1).numpy().copy())
        self.z_s = opaque(tensors["z_s"].numpy()) if shape.latent else None
        self.warps = {tex: (opaque(tensors[f"warp_{tex}_alpha"].numpy()), opaque(tensors[f"warp_{tex}_weight"].numpy()))
                      for tex in ("h", "d")} if shape.warps else None
        self.layers = [opaque_layer(tensors[f"W{i}"], tensors[f"b{i}"]) for i in range(1, n_layers(tensors) + 1)]

    @staticmethod
    def _radial(r, nodes: int):
        u = dr.clip(r, 0.0, 1.0) * float(nodes - 1)
        i0 = dr.minimum(dr.floor(u), float(nodes - 2))
        return mi.UInt32(i0), u - i0

    def _warped(self, r, tex: str):
        if self.warps is None:
            return r
        alphas, weights = self.warps[tex]
        log_r = dr.log(dr.maximum(r, WARP_R_MIN))
        out = 0.0
        for a, w in zip(alphas, weights):
            out = out + w * dr.exp(a * log_r)
        return dr.select(r > 0, out, 0.0)

    def _gated(self, values: list, channels: int) -> list:
        if self.z_s is None:
            return values
        g = len(self.z_s)
        out = []
        for c in range(channels):
            acc = 0.0
            for k, z in enumerate(self.z_s):
                acc = dr.fma(values[c * g + k], z, acc)
            out.append(acc)
        return out

    def _features(self, wi, wo) -> list:
        c_h, c_d = self.shape.channels
        g = max(1, self.shape.latent)
        r_nodes, p = self.shape.d_res
        h = half_vector(wi, wo)
        rho_h = dr.hypot(h.x, h.y)
        d = to_half_frame(wi, h, rho_h)
        d = div(d, safe_divisor(dr.norm(d)))
        fh = self._gated(self._radial_read(self._warped(rho_h, "h"), c_h * g), c_h)
        fd = self._gated(self._polar_read(self._warped(dr.hypot(d.x, d.y), "d"), d, c_d * g, r_nodes, p), c_d)
        return fh + fd

    def _radial_read(self, r, c_h: int) -> list:
        out = []
        i0, t = self._radial(r, self.shape.h_res)
        for c in range(c_h):
            a = dr.gather(mi.Float, self.h_tex, i0 * c_h + c)
            b = dr.gather(mi.Float, self.h_tex, (i0 + 1) * c_h + c)
            out.append(a + (b - a) * t)
        return out

    def _polar_read(self, r, d, c_d: int, r_nodes: int, p: int) -> list:
        out = []
        phi = dr.atan2(d.y, d.x)
        phi = phi - math.pi * dr.floor(phi / math.pi)  # φd mod π, in [0, π)
        v = phi * (p / math.pi)
        j = dr.floor(v)
        s = v - j
        j0 = mi.UInt32(dr.select(j >= p, j - p, j))  # φ rounded up to π reads node 0
        j1 = dr.select(j0 + 1 >= p, j0 + 1 - p, j0 + 1)
        k0, t = self._radial(r, r_nodes)
        for c in range(c_d):
            def at(i, jj):
                return dr.gather(mi.Float, self.d_tex, (i * p + jj) * c_d + c)

            a0, a1, b0, b1 = at(k0, j0), at(k0, j1), at(k0 + 1, j0), at(k0 + 1, j1)
            lo = a0 + (a1 - a0) * s
            hi = b0 + (b1 - b0) * s
            out.append(lo + (hi - lo) * t)
        return out

    def eval(self, wi, wo):
        x = dense_layers(self._features(wi, wo), self.layers, lambda v: v / (1.0 + dr.exp(-v)))
        return mi.Color3f(*(dr.exp(dr.minimum(g, MAX_LOG_VALUE)) for g in x))
