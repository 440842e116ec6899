"""BRDF kernels in drjit operations, so that a representation fuses into Mitsuba's kernels.

A `Kernel` evaluates RGB BRDF values (1/sr, not cosine-weighted) as `mi.Color3f` at local
unit directions `mi.Vector3f` in the protocol's convention (z = normal, ωi toward the
light, ωo toward the viewer), with drjit operations only. Mitsuba then traces it into its
own symbolic kernels: no torch call, no host round trip, no per-bounce kernel launch.

`kernel_for(model)` calls the model's `drjit_kernel()` method, the one hook for every
representation, built-in or third-party. It returns a Kernel (any object with `name` and
`eval(wi, wo) -> mi.Color3f`) or None to decline; a model without the hook, or declining,
is evaluated by the adapter in torch (evaluated mode, see mitsuba_bsdf.py). Rules for a
hook's kernel:
- drjit operations on `mi.*` types of the current variant only (no numpy, torch or
  Python branching on values), so it traces in symbolic mode;
- per-material data (weights, tables, coefficients) lives in drjit arrays made at
  construction (`dr.opaque(mi.Float, x)` scalars, `mi.Float(array)` read with
  `dr.gather`), never Python float literals: literals are baked into the kernel's code,
  so every material would compile its own kernel;
- only lanes with both directions strictly above the horizon matter; the adapter zeroes
  the others and counts (and zeroes) non-finite values itself;
- an array read by packet gathers (`dr.gather(mi.Vector4f, ...)`) must start on an
  aligned address (`aligned_zeros`), or drjit silently splits the packet, and the kernel
  then depends on where numpy's allocator put the array;
- the hook imports drjit and mitsuba inside itself, so that importing the representation
  imports neither.

This module holds what any kernel may build on: the math helpers below (twins of
brdfbench.coords, in the same operations, so a kernel agrees with torch to fp32 rounding),
the MERL cell lookup and the table kernels (`MerlTableKernel`, `MerlTrilinearKernel`,
`table_kernel`). The built-in representations' own kernels live with them, in their
plugin package, as a third party's would. Kernels are used in JIT variants (llvm_*,
cuda_*) only; scalar variants take the torch path.

MERL tables are looked up in the reference reader's cells. `merl_cell` finds them in fp32
(no division but three in its arctangents, scale-invariant forms that need no
normalisation) and measures how far each continuous cell coordinate lies from a cell edge;
a lane within `MERL_EDGE_TOL` cells of one (about 10x the fp32 path's worst error, measured
over 10⁷ adversarial and random pairs) or in an ill-conditioned configuration takes a
symbolic branch that recomputes the cells in fp64 with the reader's own operations, as
brdfbench.merl does (`merl_indices`). The branch runs for a small share of a renderer's
lanes, so most of a render keeps the fp32 path.
drjit's fp64 sin, cos, acos and atan2 are its
own, not the C library's that brdfbench.merl and the reader call: their last bits differ
for a fifth to two fifths of arguments, which moves a pair only within ~1e-13 cells of a
cell edge or where the reader's own angle is rounding noise (φd at ωi = ωo). Pairs that
sit exactly on an edge by symmetry, which fp32 directions keep (ωo = the normal: φd on
the 0 ≡ π fold; both directions in one plane with the normal), are such pairs: about a
third of θo = 0 pairs take the other side of the fold.
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from .. import merl

INV_PI = 1.0 / math.pi
TWO_PI = 2.0 * math.pi
#: The largest double below 2π: φd is kept in [0, 2π), as brdfbench.coords does.
BELOW_TWO_PI = float(np.nextafter(TWO_PI, 0.0))
FLOAT32_MAX = float(np.finfo(np.float32).max)
FLOAT32_EPS = float(np.finfo(np.float32).eps)


class Kernel:
    """A BRDF in drjit operations; subclasses set `name` and implement `eval`.

    `finite = True` promises finite values for every input (a table gather from a finite
    table): the adapter then skips counting non-finite values.
    """

    name = "kernel"
    finite = False

    def eval(self, wi: mi.Vector3f, wo: mi.Vector3f) -> mi.Color3f:
        """BRDF values (not cosine-weighted) at local directions both above the horizon."""
        raise NotImplementedError


# --------------------------------------------------------------------------- helpers


def opaque(values: Any) -> list:
    """Per-material scalars as opaque size-1 drjit arrays: kernel inputs, not code constants."""
    return [dr.opaque(mi.Float, float(v)) for v in np.asarray(values, dtype=np.float32).reshape(-1)]


def aligned_zeros(shape: tuple[int, ...], align: int = 64) -> np.ndarray:
    """fp32 zeros whose data starts on an `align`-byte boundary. drjit maps a numpy array's
    memory as it is, and silently replaces a packet gather from memory that is not aligned
    to the packet by separate gathers: with numpy's 16-byte alignment the kernel would then
    depend on where the allocator happened to put the table."""
    count = int(np.prod(shape))
    raw = np.zeros(count * 4 + align, dtype=np.uint8)
    start = (-raw.ctypes.data) % align
    return raw[start:start + count * 4].view(np.float32).reshape(shape)


def fp32_values(t: torch.Tensor) -> list[float]:
    """A tensor's values rounded to fp32, as Python floats (for `opaque`)."""
    return [float(x) for x in t.to(torch.float32).reshape(-1)]


def safe_divisor(x):
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
    s = div(s, safe_divisor(_max_abs(s)))
    v = dr.select(opposite, _cross(diff, _cross(s, diff)), s)
    v = div(v, safe_divisor(_max_abs(v)))
    return div(v, safe_divisor(dr.norm(v)))  # dr.norm rounds as torch's vector_norm


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


def merl_coordinates64(wi: mi.Vector3f, wo: mi.Vector3f):
    """Continuous (θh, θd, φd) cell coordinates (mi.Float64) and θh, computed in fp64
    operation by operation as brdfbench.merl.continuous_indices (coords' angles): the
    trilinear kernel's fp64 branch. The nearest cells come from `merl_indices`."""
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
    u_h = dr.sqrt(dr.maximum(theta_h / half_pi * merl.RES_THETA_H * merl.RES_THETA_H, 0.0))
    u_d = theta_d / half_pi * merl.RES_THETA_D
    p = dr.select(phi_d > math.pi, phi_d - math.pi, phi_d)
    u_p = p / pi * (2 * merl.RES_PHI_D) / 2
    return u_h, u_d, u_p, theta_h


def c_atan2(y, x):
    """atan2 with C's signed zeros: drjit's own gives +0 for atan2(±0, ±0) and +π for
    atan2(−0, x < 0), where C gives ±0 or ±π by the signs (and so the reader's φd cell)."""
    t = type(x)  # both branches typed: a select of two Python floats would be an fp32 π
    on_axis = dr.copysign(dr.select(dr.copysign(1.0, x) < 0, t(math.pi), t(0.0)), y)
    return dr.select(y == 0, on_axis, dr.atan2(y, x))


def _rotated(v, axis, angle):
    """Rodrigues' rotation as the MERL reader accumulates it (see brdfbench.merl); `axis`
    has opaque components, so that its zeros are multiplied through as in the reader
    (drjit folds a product with a literal 0 to +0, losing the sign of zero)."""
    c, s = dr.cos(angle), dr.sin(angle)
    k = (axis.x * v.x + axis.y * v.y + axis.z * v.z) * (1.0 - c)
    w = _cross(axis, v)
    return type(v)(v.x * c + axis.x * k + w.x * s, v.y * c + axis.y * k + w.y * s, v.z * c + axis.z * k + w.z * s)


def merl_reader_angles64(wi: mi.Vector3f, wo: mi.Vector3f):
    """(θh, θd, φd) in fp64, operation by operation as the MERL reader (brdfbench.merl's
    `reader_angles`), φd in [−π, π]. drjit's fp64 sin, cos, acos and atan2 are not the C
    library's (their last bits differ for a fifth to two fifths of arguments), so where the
    reader's cell hangs on those bits this may pick the other one."""
    wi, wo = mi.Vector3d(wi), mi.Vector3d(wo)

    def normalized(v):
        return div(v, dr.sqrt(v.x * v.x + v.y * v.y + v.z * v.z))

    zero, one = dr.opaque(mi.Float64, 0.0), dr.opaque(mi.Float64, 1.0)
    half = normalized((wi + wo) / 2.0)
    theta_h = dr.acos(half.z)
    phi_h = c_atan2(half.y, half.x)
    temp = _rotated(normalized(wi), mi.Vector3d(zero, zero, one), -phi_h)
    diff = _rotated(temp, mi.Vector3d(zero, one, zero), -theta_h)
    return theta_h, dr.acos(diff.z), c_atan2(diff.y, diff.x)


def merl_indices(wi: mi.Vector3f, wo: mi.Vector3f):
    """(θh, θd, φd) cell indices (mi.Int32) of direction pairs as the MERL reader finds
    them, in fp64 (`merl_reader_angles64`); NaN angles give cell 0, as its casts do."""
    theta_h, theta_d, phi_d = merl_reader_angles64(wi, wo)
    # Divisors are opaque: drjit turns a division by a literal into a product with its
    # reciprocal, which rounds differently from the reader's division.
    half_pi, pi = dr.opaque(mi.Float64, math.pi / 2.0), dr.opaque(mi.Float64, math.pi)
    u_h = dr.sqrt(dr.select(theta_h > 0, theta_h, 0.0) / half_pi * merl.RES_THETA_H * merl.RES_THETA_H)
    u_d = theta_d / half_pi * merl.RES_THETA_D
    u_p = dr.select(phi_d < 0, phi_d + pi, phi_d) / pi * (2 * merl.RES_PHI_D) / 2

    def index(u, n):
        return dr.clip(mi.Int32(dr.select(u >= 0, u, 0.0)), 0, n - 1)  # NaN fails u >= 0

    return index(u_h, merl.RES_THETA_H), index(u_d, merl.RES_THETA_D), index(u_p, merl.RES_PHI_D)


#: Distance (in cells) from a cell edge below which `merl_cell` recomputes a lane in fp64:
#: about 10x the fp32 path's worst error (3e-5 cells, φd's scaled by sin θd).
MERL_EDGE_TOL = 3e-4
#: |ωi + ωo|² below which the fp32 path defers to fp64 (|ωi + ωo| < 0.1: grazing, nearly
#: opposite pairs, where the tilt of h from inputs' norm errors grows as 1/|ωi + ωo|).
MERL_MIN_SUM2 = 1e-2
_ATAN_TERMS = 8


def _atan_coefficients(terms: int = _ATAN_TERMS) -> tuple[float, ...]:
    """Odd polynomial a·(1 + c1 a² + c2 a⁴ + …) for atan(a) on [0, 1], near-minimax (absolute
    error 1.2e-7 rad, fitted once by iteratively reweighted least squares); the leading
    coefficient is exactly 1, so atan(a) ≈ a stays relatively exact near 0."""
    a = np.cos(np.linspace(0.0, np.pi, 4001)) * 0.5 + 0.5
    s = a * a
    basis = np.stack([a * s**k for k in range(1, terms)], axis=1)
    target = np.arctan(a) - a
    weight = np.ones_like(a)
    for _ in range(60):
        coef, *_ = np.linalg.lstsq(basis * weight[:, None], target * weight, rcond=None)
        err = np.abs(basis @ coef - target)
        weight = weight * (err / err.max()) ** 0.3 + 1e-3
    return (1.0, *(float(c) for c in coef))


ATAN_COEFFICIENTS = _atan_coefficients()


def atan_nonneg(y, x):
    """atan2(y, x) for y, x ≥ 0, in [0, π/2]; absolute error ~2e-7 rad in fp32. NaN for
    y = x = 0: the callers send such (ill-posed) lanes to fp64."""
    big, small = dr.maximum(y, x), dr.minimum(y, x)
    a = small / big
    s = a * a
    r = ATAN_COEFFICIENTS[-1]
    for c in ATAN_COEFFICIENTS[-2:0:-1]:
        r = dr.fma(r, s, c)
    r = dr.fma(a * s, r, a)
    return dr.select(y > x, 0.5 * math.pi - r, r)


def merl_coordinates(wi: mi.Vector3f, wo: mi.Vector3f):
    """Continuous MERL cell coordinates in fp32, in cells: (u_h, u_d, u_p) whose floors are
    the (θh, θd, φd) indices, plus sin²θd and cos θd up to a common positive scale (φd's
    conditioning) and a mask of the pairs the fp32 forms handle (`well_posed`).

    h is the reader's, ωi + ωo as given (not normalised first), left unnormalised: every
    angle comes from atan2 of two quantities with the same scale. ωi in h's frame is
    (dx, dy, dz)/(ρ|h|) with ρ = |h_xy|; φd ∈ [0, π] is folded as the reader folds it. Not
    well posed: |ωi + ωo| < 0.1, and sin θh or sin θh sin θd below 1e-7, where the reader's
    acos of a z near 1 is off by up to 2e-16/sin θ rad (and φh, φd are undefined at 0).
    """
    s = wi + wo
    sum2 = _dot(s, s)
    v = s  # the reader's h, unnormalised
    rho2 = v.x * v.x + v.y * v.y
    norm2 = rho2 + v.z * v.z
    rho, norm = dr.sqrt(rho2), dr.sqrt(norm2)
    along = v.x * wi.x + v.y * wi.y
    dy = norm * (v.x * wi.y - v.y * wi.x)
    dx = v.z * along - rho2 * wi.z
    dz = rho * (along + v.z * wi.z)
    sin2 = dx * dx + dy * dy
    theta_h = atan_nonneg(rho, v.z)
    theta_d = atan_nonneg(dr.sqrt(sin2), dz)
    dx = dr.select(dy < 0, -dx, dx)  # φd + π ~ φd: fold into [0, π]
    r = atan_nonneg(dr.abs(dy), dr.abs(dx))
    phi_d = dr.select(dx < 0, math.pi - r, r)
    u_h = dr.sqrt(theta_h * (merl.RES_THETA_H * merl.RES_THETA_H / (0.5 * math.pi)))
    u_d = theta_d * (merl.RES_THETA_D / (0.5 * math.pi))
    u_p = phi_d * (merl.RES_PHI_D / math.pi)
    well_posed = (sum2 >= MERL_MIN_SUM2) & (rho2 > 1e-14 * norm2) & (sin2 > 1e-14 * norm2 * norm2)
    return u_h, u_d, u_p, sin2, dz, well_posed


def merl_cells_fast(wi: mi.Vector3f, wo: mi.Vector3f):
    """(θh, θd, φd) cell indices in fp32 and a mask of lanes whose cells fp32 cannot vouch
    for: within MERL_EDGE_TOL of a cell edge (φd's distance scaled by sin θd, since its error
    grows as 1/sin θd), not well posed, or not finite. Those must be recomputed in fp64."""
    u_h, u_d, u_p, sin2, dz, well_posed = merl_coordinates(wi, wo)
    f_h, f_d, f_p = dr.floor(u_h), dr.floor(u_d), dr.floor(u_p)

    def edge(u, f):
        return dr.minimum(u - f, f + 1.0 - u)

    tol = MERL_EDGE_TOL
    e_p = edge(u_p, f_p)
    sure = (well_posed & (edge(u_h, f_h) >= tol) & (edge(u_d, f_d) >= tol)
            & (e_p * e_p * sin2 >= (tol * tol) * (sin2 + dz * dz)))
    ih = dr.clip(mi.Int32(f_h), 0, merl.RES_THETA_H - 1)
    id_ = dr.clip(mi.Int32(f_d), 0, merl.RES_THETA_D - 1)
    ip = dr.clip(mi.Int32(f_p), 0, merl.RES_PHI_D - 1)
    return ih, id_, ip, ~sure  # NaN compares false: never "sure"


def merl_cell(wi: mi.Vector3f, wo: mi.Vector3f, downsample: int = 1, shape=merl.SHAPE):
    """Flat index of the reference's cell (one sample per downsample³ block of `shape`):
    fp32 where it is sure, fp64 in a symbolic branch for the rest."""

    def flat(ih, id_, ip):
        if downsample > 1:
            ih, id_, ip = ih // downsample, id_ // downsample, ip // downsample
        return (ih * shape[1] + id_) * shape[2] + ip

    ih, id_, ip, unsure = merl_cells_fast(wi, wo)
    return dr.if_stmt((wi, wo, flat(ih, id_, ip)), unsure,
                      true_fn=lambda wi, wo, idx: flat(*merl_indices(wi, wo)),
                      false_fn=lambda wi, wo, idx: idx,
                      label="merl_cell_fp64")


class MerlTableKernel(Kernel):
    """Nearest-cell lookup of a MERL-layout table, optionally one sample per x³ block.

    `values` (3, n_θh, n_θd, n_φd) in 1/sr (negatives = invalid); stored clamped at 0 as
    one fp32 drjit array of (R, G, B, valid) quadruples (16 B a cell), read by one packet
    gather per lookup. Inside Mitsuba's BSDF calls the table's address is call data, known
    per lane: there a packet gather beats three per-channel gathers (1.07x on the sphere
    benchmark); at the top level of brdfbench's own integrators it costs about 4 %. A
    finite table yields finite values, so the adapter skips its non-finite count.
    """

    name = "merl_table"

    def __init__(self, values: np.ndarray, downsample: int = 1, name: str = "merl_table"):
        self.name = name
        self.downsample = downsample
        self.shape = values.shape[1:]
        rgbv = aligned_zeros((int(np.prod(self.shape)), 4))
        flat = values.reshape(3, -1).T
        rgbv[:, :3] = np.clip(flat, 0.0, None)
        rgbv[:, 3] = np.all(flat >= 0, axis=1)
        self.finite = bool(np.isfinite(rgbv).all())
        self.table = mi.Float(rgbv.reshape(-1))  # drjit maps numpy's memory: no copy

    def eval(self, wi, wo):
        v = dr.gather(mi.Vector4f, self.table, mi.UInt32(merl_cell(wi, wo, self.downsample, self.shape)))
        return mi.Color3f(v.x, v.y, v.z)


class MerlTrilinearKernel(MerlTableKernel):
    """Trilinear interpolation between cell centres, as brdfbench.merl.lookup_trilinear:
    θh and θd clamp at the table's ends, φd wraps with period π, invalid cells get zero
    weight, and a point whose eight neighbours are all invalid is 0. The coordinates are
    fp32 (`merl_coordinates`) where well posed, fp64 elsewhere: the weights are continuous,
    so no cell choice hangs on a last bit, and the values agree with the fp64 torch lookup
    to fp32 rounding."""

    name = "merl_trilinear"

    def eval(self, wi, wo):
        u_h, u_d, u_p, _, _, well_posed = merl_coordinates(wi, wo)
        # θh = 0 or θd = 0 (φh or φd undefined: the reference's conventions pick them) and
        # grazing, nearly opposite pairs: fp64 coordinates, in a branch
        u_h, u_d, u_p = dr.if_stmt(
            (wi, wo, u_h, u_d, u_p), ~well_posed,
            true_fn=lambda wi, wo, *u: tuple(mi.Float(c) for c in merl_coordinates64(wi, wo)[:3]),
            false_fn=lambda wi, wo, *u: u, label="merl_trilinear_fp64")
        n_h, n_d, n_p = self.shape

        def corners(u, n, wrap):
            x = u - 0.5
            lo = dr.floor(x)
            frac = x - lo
            lo = mi.Int32(lo)
            hi = lo + 1
            if wrap:
                lo = dr.select(lo < 0, lo + n, dr.select(lo >= n, lo - n, lo))
                hi = dr.select(hi >= n, hi - n, hi)
            else:
                frac = dr.select((lo < 0) | (hi > n - 1), 0.0, frac)
                lo, hi = dr.clip(lo, 0, n - 1), dr.clip(hi, 0, n - 1)
            return (lo, 1.0 - frac), (hi, frac)

        acc = [mi.Float(0.0)] * 3
        total = mi.Float(0.0)
        for ih, wh in corners(u_h, n_h, False):
            for id_, wd in corners(u_d, n_d, False):
                for ip, wp in corners(u_p, n_p, True):
                    v = dr.gather(mi.Vector4f, self.table, mi.UInt32((ih * n_d + id_) * n_p + ip))
                    w = wh * wd * wp * v.w
                    acc = [a + w * c for a, c in zip(acc, (v.x, v.y, v.z))]
                    total += w
        inv = dr.select(total > 0, 1.0 / dr.select(total > 0, total, 1.0), 0.0)
        return mi.Color3f(*(a * inv for a in acc))


_TABLE_CACHE: dict[tuple, tuple] = {}  # (variant, id(values), downsample, name, class) -> (weakref to values, kernel)
_TABLE_CACHE_SIZE = 8


def table_kernel(values: np.ndarray, downsample: int = 1, name: str = "merl_table",
                 cls: type[MerlTableKernel] = MerlTableKernel) -> MerlTableKernel:
    """A MerlTableKernel (or `cls`) for a table array, reused while that very array is
    alive: building one copies 1.5 M cells to the device, which costs more than a small
    render."""
    key = (mi.variant(), id(values), downsample, name, cls)
    hit = _TABLE_CACHE.get(key)
    if hit is not None and hit[0]() is values:
        return hit[1]
    kernel = cls(values, downsample, name)
    if len(_TABLE_CACHE) >= _TABLE_CACHE_SIZE:
        _TABLE_CACHE.pop(next(iter(_TABLE_CACHE)))
    _TABLE_CACHE[key] = (weakref.ref(values), kernel)
    return kernel


# --------------------------------------------------------------------------- lookup


def kernel_for(model) -> Kernel | None:
    """The drjit kernel of a model: what its `drjit_kernel()` hook returns, else None (the
    torch path). Always None in scalar variants, which take the torch path."""
    return native_hook(model, "drjit_kernel")


def native_hook(obj, hook_name: str):
    """`obj.<hook_name>()` where the object has that hook, else None; always None in
    scalar variants."""
    if not dr.is_jit_v(mi.Float):
        return None
    hook = getattr(obj, hook_name, None)
    return hook() if callable(hook) else None
