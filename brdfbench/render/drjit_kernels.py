"""BRDF kernels in drjit operations, so that a representation fuses into Mitsuba's kernels.

A `Kernel` evaluates RGB BRDF values (1/sr, not cosine-weighted) as `mi.Color3f` at local
unit directions `mi.Vector3f` in the protocol's convention (z = normal, ωi toward the
light, ωo toward the viewer), with drjit operations only. Mitsuba then traces it into its
own symbolic kernels: no torch call, no host round trip, no per-bounce kernel launch.

`kernel_for(model)` looks, in order, for

(a) a method `drjit_kernel()` on the model: the hook for third-party representations. It
    returns a Kernel (any object with `name` and `eval(wi, wo) -> mi.Color3f`) or None to
    decline. Rules for a hook's kernel:
    - drjit operations on `mi.*` types of the current variant only (no numpy, torch or
      Python branching on values), so it traces in symbolic mode;
    - per-material data (weights, tables, coefficients) lives in drjit arrays made at
      construction (`dr.opaque(mi.Float, x)` scalars, `mi.Float(array)` read with
      `dr.gather`), never Python float literals: literals are baked into the kernel's
      code, so every material would compile its own kernel;
    - only lanes with both directions strictly above the horizon matter; the adapter
      zeroes the others and counts (and zeroes) non-finite values itself.
(b) a built-in twin, matched by exact class (a subclass may change `_eval`): the MERL
    table (nearest cell, also downsampled) and PCA (a reconstructed MERL table) as a
    table gather, lambert, blinn_phong, cook_torrance, ggx, nbrdf and naive_mlp;
(c) None: the adapter evaluates the model in torch (evaluated mode, see mitsuba_bsdf.py).

Kernels are used in JIT variants (llvm_*, cuda_*) only; scalar variants take the torch
path. The twins follow the torch code operation by operation (same clamps, same order of
the per-material constants, computed on the host with the same torch ops), so they agree
to fp32 rounding. The MERL cell indices are computed in fp64 as brdfbench.merl does, so
they are the reference's cells: drjit's atan2 and hypot may differ from torch's in the last
bit, which moves a pair only if it lies within ~1e-16 rad of a cell edge, or where the
reference's own angle is rounding noise (φd at ωi = ωo exactly, where it is undefined).
"""

from __future__ import annotations

import math
import weakref
from typing import Any, Callable

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from .. import merl
from ..data.nbrdf_h5 import MAX_LOG_VALUE  # the neural outputs' pre-exponential clamp

INV_PI = 1.0 / math.pi
TWO_PI = 2.0 * math.pi
#: The largest double below 2π: φd is kept in [0, 2π), as brdfbench.coords does.
BELOW_TWO_PI = float(np.nextafter(TWO_PI, 0.0))
FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT32_EPS = float(np.finfo(np.float32).eps)


class Kernel:
    """A BRDF in drjit operations; subclasses set `name` and implement `eval`."""

    name = "kernel"

    def eval(self, wi: mi.Vector3f, wo: mi.Vector3f) -> mi.Color3f:
        """BRDF values (not cosine-weighted) at local directions both above the horizon."""
        raise NotImplementedError


# --------------------------------------------------------------------------- helpers


def opaque(values: Any) -> list:
    """Per-material scalars as opaque size-1 drjit arrays: kernel inputs, not code constants."""
    return [dr.opaque(mi.Float, float(v)) for v in np.asarray(values, dtype=np.float32).reshape(-1)]


def _fp32(t: torch.Tensor) -> list[float]:
    return [float(x) for x in t.to(torch.float32).reshape(-1)]


def _safe(x):
    """x where positive, else 1: a divisor that leaves zero vectors at zero."""
    return dr.select(x > 0, x, 1.0)


def _max_abs(v):
    return dr.maximum(dr.maximum(dr.abs(v.x), dr.abs(v.y)), dr.abs(v.z))


def div(v, d):
    """v / d per component: drjit's vector-by-scalar division multiplies by a reciprocal,
    which rounds differently from torch."""
    return type(v)(v.x / d, v.y / d, v.z / d)


def _dot(a, b):
    return a.x * b.x + a.y * b.y + a.z * b.z


def _cross(a, b):
    return type(a)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)


def log1p(x):
    """log(1 + x), accurate for tiny |x| (drjit has none): log(u)·x/(u − 1), u = 1 + x."""
    u = 1.0 + x
    return dr.select(u == 1.0, x, dr.log(u) * x / (u - 1.0))


def expm1(x):
    """exp(x) − 1 without cancellation near 0: (e − 1)·x/log(e), e = exp(x); −1 once e = 0."""
    e = dr.exp(x)
    return dr.select(e == 1.0, x, dr.select(e - 1.0 == -1.0, -1.0, (e - 1.0) * x / dr.log(e)))


def half_vector(wi, wo):
    """Twin of brdfbench.coords.half_vector (stable for ωi + ωo ≈ 0), in the inputs' precision,
    for pairs both above the horizon: its fallback for ωo = −ωi exactly (never both above)
    is left out."""
    s = wi + wo
    diff = wi - wo
    opposite = _dot(diff, diff) > _dot(s, s)
    s = div(s, _safe(_max_abs(s)))
    v = dr.select(opposite, _cross(diff, _cross(s, diff)), s)
    v = div(v, _safe(_max_abs(v)))
    return div(v, _safe(dr.norm(v)))  # dr.norm rounds as torch's vector_norm


def to_half_frame(wi, h, rho=None):
    """ωi rotated so that h becomes the pole (by −φh about z, then −θh about y), as
    coords.to_half_diff; `rho` = hypot(h_x, h_y) where already known."""
    rho = dr.hypot(h.x, h.y) if rho is None else rho
    has_rho = rho > 0
    safe_rho = dr.select(has_rho, rho, 1.0)
    cos_p = dr.select(has_rho, h.x / safe_rho, 1.0)
    sin_p = dr.select(has_rho, h.y / safe_rho, 0.0)
    x = cos_p * wi.x + sin_p * wi.y
    y = cos_p * wi.y - sin_p * wi.x
    return type(wi)(h.z * x - rho * wi.z, y, rho * x + h.z * wi.z)


def spherical(v):
    """(θ, φ) of vectors as coords.vector_to_spherical: θ via atan2, φ in (−π, π], 0 at the pole."""
    rho = dr.hypot(v.x, v.y)
    theta = dr.atan2(rho, v.z)
    phi = dr.select(rho > 0, dr.atan2(v.y, v.x), 0.0)
    return theta, dr.select(phi == -math.pi, math.pi, phi)


# --------------------------------------------------------------------------- MERL tables


def merl_indices(wi: mi.Vector3f, wo: mi.Vector3f):
    """(θh, θd, φd) cell indices (mi.Int32) of direction pairs, computed in fp64 operation
    by operation as brdfbench.merl.cell_indices."""
    wi, wo = mi.Vector3d(wi), mi.Vector3d(wo)
    h = half_vector(wi, wo)
    rho_h = dr.hypot(h.x, h.y)
    theta_h = dr.atan2(rho_h, h.z)  # as spherical(h), without the unused φh
    theta_d, phi_d = spherical(to_half_frame(wi, h, rho_h))
    phi_d = dr.select(phi_d < 0, phi_d + TWO_PI, phi_d)
    phi_d = dr.select(phi_d >= TWO_PI, BELOW_TWO_PI, phi_d)
    # Divisors are opaque: drjit turns a division by a literal into a product with its
    # reciprocal, which rounds differently from the reference's division.
    half_pi, pi = dr.opaque(mi.Float64, math.pi / 2.0), dr.opaque(mi.Float64, math.pi)
    warped = dr.sqrt(dr.maximum(theta_h / half_pi * merl.RES_THETA_H * merl.RES_THETA_H, 0.0))
    ih = dr.select(theta_h <= 0, 0, dr.clip(mi.Int32(warped), 0, merl.RES_THETA_H - 1))
    id_ = dr.clip(mi.Int32(theta_d / half_pi * merl.RES_THETA_D), 0, merl.RES_THETA_D - 1)
    p = dr.select(phi_d > math.pi, phi_d - math.pi, phi_d)
    ip = dr.clip(mi.Int32(p / pi * (2 * merl.RES_PHI_D) / 2), 0, merl.RES_PHI_D - 1)
    return ih, id_, ip


class MerlTableKernel(Kernel):
    """Nearest-cell lookup of a MERL-layout table, optionally one sample per x³ block.

    `values` (3, n_θh, n_θd, n_φd) in 1/sr (negatives = invalid); stored clamped at 0 as
    one fp32 drjit array of RGB triples, read with a single `dr.gather` per lookup.
    """

    name = "merl_table"

    def __init__(self, values: np.ndarray, downsample: int = 1, name: str = "merl_table"):
        self.name = name
        self.downsample = downsample
        self.shape = values.shape[1:]
        rgb = np.clip(values, 0.0, None).reshape(3, -1).T.astype(np.float32)
        self.table = mi.Float(np.ascontiguousarray(rgb).reshape(-1))

    def eval(self, wi, wo):
        ih, id_, ip = merl_indices(wi, wo)
        x = self.downsample
        if x > 1:
            ih, id_, ip = ih // x, id_ // x, ip // x
        idx = mi.UInt32((ih * self.shape[1] + id_) * self.shape[2] + ip)
        return dr.gather(mi.Color3f, self.table, idx)


_TABLE_CACHE: dict[tuple, tuple] = {}  # (variant, id(values), downsample, name) -> (weakref to values, kernel)
_TABLE_CACHE_SIZE = 8


def table_kernel(values: np.ndarray, downsample: int = 1, name: str = "merl_table") -> MerlTableKernel:
    """A MerlTableKernel for a table array, reused while that very array is alive: building
    one copies 1.5 M cells to the device, which costs more than a small render."""
    key = (mi.variant(), id(values), downsample, name)
    hit = _TABLE_CACHE.get(key)
    if hit is not None and hit[0]() is values:
        return hit[1]
    kernel = MerlTableKernel(values, downsample, name)
    if len(_TABLE_CACHE) >= _TABLE_CACHE_SIZE:
        _TABLE_CACHE.pop(next(iter(_TABLE_CACHE)))
    _TABLE_CACHE[key] = (weakref.ref(values), kernel)
    return kernel


def _merl_kernel(model) -> Kernel | None:
    if model.mode != "nearest":
        return None  # trilinear: the torch path
    if model.downsample == 1:
        if model.table is None:
            return None
        return table_kernel(model.table.values, name="merl")
    if model.samples is None:
        return None
    scales = np.asarray(merl.CHANNEL_SCALES).reshape(3, 1, 1, 1)
    return MerlTableKernel(model.samples * scales, model.downsample, name=f"merl_downsample{model.downsample}")


def _pca_kernel(model) -> Kernel | None:
    if model.coefficients is None:
        return None
    return MerlTableKernel(model.table.values, name="pca")


# --------------------------------------------------------------------------- analytic


class LambertKernel(Kernel):
    name = "lambert"

    def __init__(self, model):
        self.rho_pi = opaque(_fp32(model.albedo / math.pi))

    def eval(self, wi, wo):
        return mi.Color3f(*self.rho_pi)


class _Geometry:
    """Twin of representations/analytic.py `geometry` (fp32, same clamps)."""

    COS_MIN = 1e-7

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


def _ggx_ndf(a2, g: _Geometry):
    q = a2 * g.cos2_h + g.sin2_h
    return a2 / (math.pi * q * q)


def _schlick_fresnel(f0, one_minus_f0, cos_d):
    m = 1.0 - cos_d
    m2 = m * m
    return f0 + one_minus_f0 * (m2 * m2 * m)


class AnalyticKernel(Kernel):
    """k_d/π + k_s · lobe, clamped to [0, fp32 max]; subclasses define `lobe`."""

    def __init__(self, model):
        c = {k: v.to(torch.float32) for k, v in model.coeffs.items()}
        self.kd_pi = opaque(_fp32(c["kd"] * INV_PI))
        self.ks = opaque(_fp32(c["ks"]))
        self.shape = {k: opaque(_fp32(v))[0] for k, v in self.constants({k: v[0] for k, v in c.items()}).items()}

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
        alpha = (c["roughness"] * c["roughness"]).clamp(min=1e-6)
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
        alpha = c["alpha"].clamp(min=1e-6)
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


class MLPKernel(Kernel):
    """The NBRDF / naive MLP (representations/mlp.py): dense layers with ReLU, then
    expm1(min(z, 80)) clamped at 0, times the channel scales.

    Every weight is an opaque scalar, so materials of one architecture share one compiled
    kernel. The price: inside Mitsuba's BSDF call, per-instance inputs are read from the
    call's data with a packet gather per 8 values, which halves the throughput of weights
    baked in as literals (measured on the 256² sphere), which would compile per material.
    """

    def __init__(self, model):
        self.name = model.plugin_name
        self.features = model.features
        weights = model.weights
        n_layers = sum(1 for k in weights if k.startswith("W"))
        self.layers = []
        for i in range(1, n_layers + 1):
            w = weights[f"W{i}"].to(torch.float32).numpy()
            b = weights[f"b{i}"].to(torch.float32).numpy()
            flat = opaque(w)
            cols = [[flat[r * w.shape[1] + c] for r in range(w.shape[0])] for c in range(w.shape[1])]
            self.layers.append((cols, opaque(b)))
        self.scale = opaque(model.output_scale.to(torch.float32).numpy())

    def inputs(self, wi, wo) -> list:
        if self.features == "directions":
            return [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]
        # Rusinkiewicz (sin θh, 0, cos θh, d): the unit h and the unit ωi in h's frame are
        # these very sines and cosines, without the angles' atan2 / sin / cos round trip.
        h = half_vector(wi, wo)
        rho_h = dr.hypot(h.x, h.y)
        d = to_half_frame(wi, h, rho_h)
        d = div(d, _safe(dr.norm(d)))
        return [rho_h, None, h.z, d.x, d.y, d.z]

    def eval(self, wi, wo):
        x = self.inputs(wi, wo)
        for layer, (cols, bias) in enumerate(self.layers):
            out = []
            for col, b in zip(cols, bias):
                acc = b
                for xi, w in zip(x, col):
                    if xi is not None:  # the constant 0 input of the Rusinkiewicz encoding
                        acc = dr.fma(xi, w, acc)
                out.append(acc)
            last = layer == len(self.layers) - 1
            x = out if last else [dr.maximum(v, 0.0) for v in out]
        values = []
        for z, scale in zip(x, self.scale):
            z = dr.minimum(z, MAX_LOG_VALUE)
            values.append(dr.select(z > 0, expm1(z), 0.0) * scale)
        return mi.Color3f(*values)


def _mlp_kernel(model) -> Kernel | None:
    if model.weights is None or len(model.output_scale.reshape(-1)) != 3:
        return None
    return MLPKernel(model)


# --------------------------------------------------------------------------- lookup

_R = "brdfbench_representations"
#: Built-in twins by exact class ("module:qualname"): names only, so nothing is imported here.
BUILTIN: dict[str, Callable[[Any], Kernel | None]] = {
    f"{_R}.merl:TabulatedMERL": _merl_kernel,
    f"{_R}.pca:PCA": _pca_kernel,
    f"{_R}.lambert:Lambert": LambertKernel,
    f"{_R}.analytic:CookTorrance": CookTorranceKernel,
    f"{_R}.analytic:GGX": GGXKernel,
    f"{_R}.analytic:BlinnPhong": BlinnPhongKernel,
    f"{_R}.nbrdf:NBRDF": _mlp_kernel,
    f"{_R}.nbrdf:NaiveMLP": _mlp_kernel,
}


def class_key(obj: Any) -> str:
    cls = type(obj)
    return f"{cls.__module__}:{cls.__qualname__}"


def kernel_for(model) -> Kernel | None:
    """The drjit kernel of a model: its `drjit_kernel()` hook, else a built-in twin, else None
    (the torch path). Always None in scalar variants, which take the torch path."""
    return native_twin(model, "drjit_kernel", BUILTIN)


def native_twin(obj, hook_name: str, builtin: dict[str, Callable]):
    """`obj.<hook_name>()` where the object has that hook, else the builder registered for
    its exact class in `builtin`, else None; always None in scalar variants."""
    if not dr.is_jit_v(mi.Float):
        return None
    hook = getattr(obj, hook_name, None)
    if callable(hook):
        return hook()
    builder = builtin.get(class_key(obj))
    return builder(obj) if builder is not None else None
