"""MERL `.binary` tables: reading, writing, validation and lookup.

Follows the reference reader (Matusik et al., BRDFRead.cpp): a header of three int32 dims
(90, 90, 180), then float64 values channel-major (all R, then G, then B), each channel
scaled by 1/1500, 1.15/1500, 1.66/1500; θh indexed by square-root warping; φd folded by
reciprocity into [0, π). Negative cells mark invalid measurements.

The nearest-cell lookup runs the reader's own arithmetic, operation by operation in
float64, so that it picks the reader's cell even where the choice hangs on rounding (on
a cell edge, or where an angle is undefined). The reader takes angles and builds two
vectors from them (sin θ cos φ, sin θ sin φ, cos θ); `lookup_nearest_angles` starts from
the angles, `lookup_nearest` from the vectors, which it takes as those two vectors: their
plain sum, normalised, is the half vector h; a normalised copy of ωi is rotated by −φh
about the normal and −θh about y into the difference vector; θh, θd are acos of z, φh,
φd atan2 of (y, x), and a negative φd (−π included) moves up by π. Rounding noise is
reproduced too: the few lookups whose cell a last bit could move (within ~1e-13 cells of
an edge, or near a degenerate pair) are recomputed with the C library's functions
(Python's `math`), as the reader calls them; the rest use numpy's, whose last bits may
differ on some CPUs.

Degenerate pairs get the reader's answer, not a convention of ours:
- θh = 0 exactly (h = +z: ωo is ωi mirrored about the normal, given as vectors, or both
  are the normal): φh = atan2(+0, +0) = 0, so θd and φd are ωi's own polar angle and
  azimuth, φd folded as above (ωi = ωo = normal: cell (0, 0, 0)).
- θd = 0 (ωi = ωo): the θd cell is 0 and φd is the atan2 of what rounding leaves of the
  difference vector's x and y, an arbitrary but reproducible cell of that row, the one the
  reader picks for the same vectors.
- Near either (θh or θd below ~1e-6 rad, e.g. a mirror pair given as angles, whose h is
  the normal only up to rounding), φh or φd is likewise rounding noise, reproduced as the
  reader computes it. For ωo = −ωi the half vector is 0/0: every angle is NaN, and the
  reader's casts make that cell (0, 0, 0).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import torch

from . import coords, reused
from .atomic import replacing
from .errors import DataError

RES_THETA_H = 90
RES_THETA_D = 90
RES_PHI_D = 180  # the reference's BRDF_SAMPLING_RES_PHI_D / 2
SHAPE = (RES_THETA_H, RES_THETA_D, RES_PHI_D)
N_CELLS = RES_THETA_H * RES_THETA_D * RES_PHI_D
CHANNEL_SCALES = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)
HEADER_BYTES = 12
FILE_BYTES = HEADER_BYTES + 3 * N_CELLS * 8
INVALID_RAW = -1.0
_SCALES = np.asarray(CHANNEL_SCALES).reshape(3, 1, 1, 1)


@dataclass(frozen=True)
class MerlTable:
    """A MERL table as stored: `raw` (3, 90, 90, 180) float64 file values; < 0 = invalid.

    `values` are in BRDF units (1/sr): raw times the channel scales, negatives included,
    as the reference reader computes them.
    """

    raw: np.ndarray

    def __post_init__(self):
        if self.raw.shape != (3, *SHAPE):
            raise ValueError(f"MERL table must have shape (3, 90, 90, 180), got {self.raw.shape}")

    @classmethod
    def from_values(cls, values: np.ndarray, valid: np.ndarray | None = None) -> "MerlTable":
        """Table from BRDF values (3, 90, 90, 180); cells outside `valid` become INVALID_RAW."""
        raw = np.divide(values, _SCALES, dtype=np.float64)  # values cast to float64 first, as asarray would
        if valid is not None:
            raw[:, ~np.asarray(valid, dtype=bool)] = INVALID_RAW
        return cls(raw)

    @cached_property
    def values(self) -> np.ndarray:
        return self.raw * _SCALES

    @cached_property
    def valid(self) -> np.ndarray:
        """(90, 90, 180) mask of cells valid in all three channels."""
        r = self.raw  # (r >= 0).all(axis=0), without its strided reduction
        return (r[0] >= 0) & (r[1] >= 0) & (r[2] >= 0)

    def lookup(self, wi: torch.Tensor, wo: torch.Tensor, mode: str = "nearest") -> torch.Tensor:
        """BRDF values (N, 3) float64 at direction pairs (raw × channel scales, negatives
        included), as the reference returns them."""
        if mode == "nearest":
            return lookup_nearest(self.values, wi, wo)
        if mode == "trilinear":
            return lookup_trilinear(self.values, wi, wo)
        raise ValueError(f"unknown MERL lookup mode {mode!r}; expected 'nearest' or 'trilinear'")

    def lookup_angles(self, theta_i, phi_i, theta_o, phi_o, mode: str = "nearest") -> torch.Tensor:
        """BRDF values (N, 3) float64 at spherical angles (radians, broadcast together),
        the reader's own input: nearest is its lookup_brdf_val; trilinear interpolates at
        the vectors it builds from the angles."""
        if mode == "nearest":
            return lookup_nearest_angles(self.values, theta_i, phi_i, theta_o, phi_o)
        if mode == "trilinear":
            ti, pi_, to, po = _spherical(theta_i, phi_i, theta_o, phi_o)
            wi, wo = (torch.from_numpy(np.stack(_reader_vector(t, p, _FAST), axis=1)) for t, p in ((ti, pi_), (to, po)))
            return lookup_trilinear(self.values, wi, wo)
        raise ValueError(f"unknown MERL lookup mode {mode!r}; expected 'nearest' or 'trilinear'")


# --------------------------------------------------------------------------- file I/O


def _fail(path, fault: str) -> DataError:
    return DataError(f"{path}: {fault}")


def read_binary(path: str | os.PathLike) -> MerlTable:
    """Read and validate a MERL `.binary` file."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            raw = f.read(FILE_BYTES + 1)  # bounded: an oversized file (or a device) is not read whole
            size = os.fstat(f.fileno()).st_size if len(raw) > FILE_BYTES else len(raw)
    except IsADirectoryError:
        raise _fail(path, "is a directory, not a MERL .binary file") from None
    except OSError as exc:
        raise _fail(path, f"cannot read MERL file ({exc.strerror})") from None
    if len(raw) < HEADER_BYTES:
        raise _fail(path, f"truncated MERL file: {len(raw)} bytes, shorter than the 12-byte header")
    dims = tuple(int(d) for d in np.frombuffer(raw[:HEADER_BYTES], dtype="<i4"))
    if dims != SHAPE:
        raise _fail(path, f"wrong MERL header dims {dims}, expected {SHAPE}")
    if len(raw) < FILE_BYTES:
        raise _fail(path, f"truncated MERL file: {len(raw)} bytes, expected {FILE_BYTES}")
    if len(raw) > FILE_BYTES:
        raise _fail(path, f"oversized MERL file: {max(size, len(raw))} bytes, expected {FILE_BYTES}")
    data = np.frombuffer(raw, dtype="<f8", offset=HEADER_BYTES).reshape(3, *SHAPE)
    bad = ~np.isfinite(data)
    if bad.any():
        c, i, j, k = np.argwhere(bad)[0]
        raise _fail(path, f"{int(bad.sum())} non-finite (NaN/Inf) cells, first at channel {c}, index ({i}, {j}, {k})")
    return MerlTable(data.copy())


def write_binary(path: str | os.PathLike, table: MerlTable) -> None:
    """Write a MERL `.binary` file atomically (temporary file, then rename)."""
    path = Path(path)
    raw = np.asarray(table.raw, dtype="<f8")
    if not np.all(np.isfinite(raw)):
        raise ValueError(f"refusing to write {path}: the table has non-finite cells")
    with replacing(path) as tmp, open(tmp, "wb") as f:
        f.write(np.asarray(SHAPE, dtype="<i4").tobytes())
        f.write(raw.tobytes())


# --------------------------------------------------------------------------- the reader's angles
#
# The reader's conversion, vectorised over numpy float64 arrays, every operation the
# reader's and in its order, without fused multiply-adds. Basic operations round as C's;
# only sin, cos, acos and atan2 depend on the library: `_FAST` is numpy's, `_LIBM` the C
# library's, one Python call per value (slow: used only where a last bit can matter).


def _c_acos(x: float) -> float:
    return math.acos(x) if -1.0 <= x <= 1.0 else math.nan  # NaN outside [-1, 1], as C's


def _nan_if_infinite(f):
    return lambda x: f(x) if math.isfinite(x) else math.nan  # C's sin(±inf) is NaN; math's raises


def _per_value(f, nargs):
    u = np.frompyfunc(f, nargs, 1)
    return lambda *a: u(*a).astype(np.float64)


_FAST = (np.sin, np.cos, np.arccos, np.arctan2)
_LIBM = (_per_value(_nan_if_infinite(math.sin), 1), _per_value(_nan_if_infinite(math.cos), 1),
         _per_value(_c_acos, 1), _per_value(math.atan2, 2))
_NORMAL = (0.0, 0.0, 1.0)
_BINORMAL = (0.0, 1.0, 0.0)


def _normalized(v):
    n = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v[0] / n, v[1] / n, v[2] / n


def _rotated(v, axis, angle, fns):
    """Rodrigues' rotation as the reader accumulates it: v cos a + axis (axis · v)(1 − cos a)
    + (axis × v) sin a. The axis's zeros are multiplied through, not skipped: they set the
    signs of zero results, and so which side of the φd = 0 ≡ π fold an in-plane pair takes."""
    sin, cos = fns[0], fns[1]
    c, s = cos(angle), sin(angle)
    k = (axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2]) * (1.0 - c)
    w = (axis[1] * v[2] - axis[2] * v[1], axis[2] * v[0] - axis[0] * v[2], axis[0] * v[1] - axis[1] * v[0])
    return tuple(v[i] * c + axis[i] * k + w[i] * s for i in range(3))


def _reader_vector(theta, phi, fns):
    """The vector the reader builds from spherical angles (before it normalises a copy)."""
    sin, cos = fns[0], fns[1]
    r = sin(theta)
    return r * cos(phi), r * sin(phi), cos(theta)


def _half_diff(vin, vout, fns):
    """(θh, φh, θd, φd), the half and difference vectors and |ωi + ωo|/2 from the reader's two vectors."""
    acos, atan2 = fns[2], fns[3]
    mid = tuple((vin[i] + vout[i]) / 2.0 for i in range(3))
    half = _normalized(mid)
    theta_h, phi_h = acos(half[2]), atan2(half[1], half[0])
    diff = _rotated(_rotated(_normalized(vin), _NORMAL, -phi_h, fns), _BINORMAL, -theta_h, fns)
    mid_norm = np.sqrt(mid[0] * mid[0] + mid[1] * mid[1] + mid[2] * mid[2])
    return theta_h, phi_h, acos(diff[2]), atan2(diff[1], diff[0]), half, diff, mid_norm


#: How far two libraries' sin, cos, acos or atan2 of the same value may be apart (rad):
#: a few ulps of π, generously.
_LIBRARY_SPREAD = 4e-15
#: Safety factor on the estimated spread of a cell coordinate.
_MARGIN = 16.0


def _last_bit_matters(theta_h, theta_d, phi_d, half, diff, mid_norm, from_angles: bool) -> np.ndarray:
    """Lanes whose cell another library's last bits could move: a first-order bound of how
    far the cell coordinates can move, against their distance to a cell edge. The spread
    of each function result feeds through the rotations; it is amplified by 1/|d_xy| in θd
    and φd (acos near 1, atan2 near the pole), and, where the vectors themselves come from
    sin and cos, by 1/|ωi + ωo| in h and 1/|h_xy| in θh and φh. NaN lanes count as
    sensitive."""
    e = _LIBRARY_SPREAD
    rho_h = np.hypot(half[0], half[1])
    rho_d = np.hypot(diff[0], diff[1])
    e_theta_h = e_phi_h = e
    if from_angles:  # h itself differs: in direction, and in the rounding of its z (acos near 1)
        e_half = 3 * e / mid_norm
        e_theta_h = e + e_half + e / rho_h
        e_phi_h = e + (e_half + e) / rho_h
    e_diff = 3 * e + e_theta_h + e_phi_h
    u_h, u_d, u_p = _cell_coordinates(theta_h, theta_d, phi_d)
    cells_per_rad = RES_THETA_D / (math.pi / 2)  # also φd's: 180 cells over π
    spread_h = 0.5 * u_h / theta_h * e_theta_h  # d u_h / d θh = u_h / (2 θh)
    spread_dp = cells_per_rad * e_diff / rho_d
    sure = ((np.abs(u_h - np.round(u_h)) >= _MARGIN * spread_h)
            & (np.abs(u_d - np.round(u_d)) >= _MARGIN * spread_dp)
            & (np.abs(u_p - np.round(u_p)) >= _MARGIN * spread_dp))
    return ~sure


def _reader_angles(vin=None, vout=None, angles=None):
    """(θh, θd, φd) as the reader computes them, numpy float64: from its two vectors
    (vin, vout: three arrays each) or from spherical angles (θi, φi, θo, φo). Lanes whose
    cell a last bit could move are recomputed with the C library's functions."""

    def run(fns, pick=slice(None)):
        if angles is None:
            a, b = tuple(x[pick] for x in vin), tuple(x[pick] for x in vout)
        else:
            ti, pi_, to, po = (x[pick] for x in angles)
            a, b = _reader_vector(ti, pi_, fns), _reader_vector(to, po, fns)
        return _half_diff(a, b, fns)

    with np.errstate(all="ignore"):
        theta_h, _, theta_d, phi_d, half, diff, mid_norm = run(_FAST)
        redo = np.flatnonzero(_last_bit_matters(theta_h, theta_d, phi_d, half, diff, mid_norm, angles is not None))
        if redo.size:
            theta_h[redo], _, theta_d[redo], phi_d[redo], *_ = run(_LIBM, redo)
    return theta_h, theta_d, phi_d


def _vectors(w: torch.Tensor) -> tuple[np.ndarray, ...]:
    rows = np.ascontiguousarray(w.detach().to(device="cpu", dtype=torch.float64).numpy().T)
    return rows[0], rows[1], rows[2]


def _spherical(theta_i, phi_i, theta_o, phi_o) -> tuple[np.ndarray, ...]:
    arrays = (x.detach().to(device="cpu", dtype=torch.float64).numpy() if isinstance(x, torch.Tensor)
              else np.asarray(x, dtype=np.float64) for x in (theta_i, phi_i, theta_o, phi_o))
    return tuple(np.ascontiguousarray(x).reshape(-1) for x in np.broadcast_arrays(*arrays))


def reader_angles(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(θh, θd, φd) float64 of direction pairs (N, 3) as the reader computes them, with the
    directions taken as its two vectors; φd in [−π, π], unfolded (see the module docstring)."""
    return tuple(torch.from_numpy(x) for x in _reader_angles(_vectors(wi), _vectors(wo)))


def reader_angles_spherical(theta_i, phi_i, theta_o, phi_o) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(θh, θd, φd) float64 as the reader computes them from spherical angles (radians,
    broadcast together, flattened), the reader's own input."""
    return tuple(torch.from_numpy(x) for x in _reader_angles(angles=_spherical(theta_i, phi_i, theta_o, phi_o)))


# --------------------------------------------------------------------------- indexing

_INT_MIN = -(2**31)


def _c_int(x: np.ndarray) -> np.ndarray:
    """C's (int) cast as x86-64 executes it: truncation; NaN and out-of-range give INT_MIN."""
    ok = (x > -2147483649.0) & (x < 2147483648.0)
    return np.where(ok, np.trunc(np.where(ok, x, 0.0)), _INT_MIN).astype(np.int64)


def _cell_coordinates(theta_h, theta_d, phi_d):
    """What the reader truncates to its (θh, θd, φd) indices, in its operations (φd folded);
    0 for θh <= 0, which it indexes 0 without computing."""
    t = np.where(theta_h > 0, theta_h, 0.0)
    u_h = np.sqrt((t / (math.pi / 2.0)) * RES_THETA_H * RES_THETA_H)
    u_d = theta_d / (math.pi * 0.5) * RES_THETA_D
    u_p = _fold(phi_d) / math.pi * (2 * RES_PHI_D) / 2
    return u_h, u_d, u_p


def _fold(p):
    return np.where(p < 0, p + math.pi, np.where(p > math.pi, p - math.pi, p))


def _indices(theta_h, theta_d, phi_d) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    with np.errstate(invalid="ignore"):
        u_h, u_d, u_p = _cell_coordinates(theta_h, theta_d, phi_d)
        return tuple(np.clip(_c_int(u), 0, n - 1) for u, n in zip((u_h, u_d, u_p), SHAPE))


def _numpy(t) -> np.ndarray:
    return t.detach().to(device="cpu", dtype=torch.float64).numpy() if isinstance(t, torch.Tensor) else np.asarray(t, np.float64)


def theta_half_index(theta_h: torch.Tensor) -> torch.Tensor:
    """Reference θh index: int(sqrt(θh / (π/2) · 90 · 90)), 0 for θh <= 0, clamped to [0, 89].

    The square root is numpy's (IEEE, correctly rounded, as C's sqrt): torch's float64
    sqrt on AVX-512 CPUs can be 1 ulp off, which moves θh right below a cell edge
    (sqrt(k² − ulp) rounds to k) into the wrong cell.
    """
    x = _numpy(theta_h)
    return torch.from_numpy(_indices(x, np.zeros_like(x), np.zeros_like(x))[0])


def theta_diff_index(theta_d: torch.Tensor) -> torch.Tensor:
    """Reference θd index: int(θd / (π/2) · 90), clamped to [0, 89]."""
    x = _numpy(theta_d)
    return torch.from_numpy(_indices(np.zeros_like(x), x, np.zeros_like(x))[1])


def fold_phi_diff(phi_d: torch.Tensor) -> torch.Tensor:
    """φd folded by reciprocity (φd ~ φd + π) into [0, π], from either convention: the
    reader's atan2 in [−π, π], whose negatives (−π included) move up by π, or
    coords.to_half_diff's [0, 2π), whose values above π are the reader's negatives.

    φd = π stays π (and lands in the last cell, 179, after clamping). In [0, 2π) that π
    stands for both the reader's +π (cell 179) and its −π (cell 0): only the reader's own
    angles (`reader_angles`) tell them apart, which is why the lookup uses those.
    """
    p = phi_d.double()
    return torch.where(p < 0, p + math.pi, torch.where(p > math.pi, p - math.pi, p))


def phi_diff_index(phi_d: torch.Tensor) -> torch.Tensor:
    """Reference φd index: int(φd / π · 360 / 2) after `fold_phi_diff`, clamped to [0, 179]."""
    x = _numpy(phi_d)
    return torch.from_numpy(_indices(np.zeros_like(x), np.zeros_like(x), x)[2])


def cell_indices(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The reader's (θh, θd, φd) cell indices of each pair (int64); see `brdfbench.reused`."""
    return reused.derived(direction_data, wi, wo, "cells")


def angle_cell_indices(theta_i, phi_i, theta_o, phi_o) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The reader's (θh, θd, φd) cell indices (int64) at spherical angles, as lookup_brdf_val
    finds them: for in-plane slices and other plots drawn in angles."""
    return tuple(torch.from_numpy(i) for i in _indices(*_reader_angles(angles=_spherical(theta_i, phi_i, theta_o, phi_o))))


DIRECTION_DATA = ("cells", "flat", "continuous")


def direction_data(wi: torch.Tensor, wo: torch.Tensor, kind: str) -> tuple[torch.Tensor, ...]:
    """What the lookups derive from the directions alone, always computed afresh: "cells",
    the reader's cell indices; "flat", (`flat_index` of them,); "continuous",
    `continuous_indices` of the angles."""
    if kind not in DIRECTION_DATA:
        raise ValueError(f"unknown direction data {kind!r}; expected one of {', '.join(DIRECTION_DATA)}")
    if wi.shape != wo.shape or wi.shape[-1:] != (3,):
        raise ValueError(f"directions must both have shape (N, 3), got {tuple(wi.shape)} and {tuple(wo.shape)}")
    if kind == "continuous":
        hd = coords.to_half_diff(wi.double(), wo.double())
        return continuous_indices(hd.theta_h, hd.theta_d, hd.phi_d)
    cells = tuple(torch.from_numpy(i) for i in _indices(*_reader_angles(_vectors(wi), _vectors(wo))))
    return cells if kind == "cells" else (flat_index(*cells),)


def flat_index(ih: torch.Tensor, id_: torch.Tensor, ip: torch.Tensor) -> torch.Tensor:
    """Index of cells (ih, id, ip) in a table flattened to (3, N_CELLS)."""
    return (ih * RES_THETA_D + id_) * RES_PHI_D + ip


def gather_cells(values: np.ndarray, flat: torch.Tensor) -> torch.Tensor:
    """Values (N, 3), float64, of the cells at flat indices: the transpose of a (3, N)
    tensor, gathered one channel at a time (faster than indexing all three at once)."""
    table = torch.from_numpy(np.ascontiguousarray(values)).reshape(3, N_CELLS)
    out = torch.empty(3, flat.shape[0], dtype=table.dtype)
    for channel in range(3):
        torch.take(table[channel], flat, out=out[channel])
    return out.T


def lookup_nearest(values: np.ndarray, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """Nearest-cell values (N, 3), float64, exactly as the reference reader returns them."""
    return gather_cells(values, reused.derived(direction_data, wi, wo, "flat")[0])


def lookup_nearest_angles(values: np.ndarray, theta_i, phi_i, theta_o, phi_o) -> torch.Tensor:
    """Nearest-cell values (N, 3), float64, at spherical angles: the reader's lookup_brdf_val."""
    return gather_cells(values, flat_index(*angle_cell_indices(theta_i, phi_i, theta_o, phi_o)))


def continuous_indices(theta_h, theta_d, phi_d):
    """Fractional cell coordinates of coords.to_half_diff's angles (φd in [0, 2π)); cell
    centres sit at i + 0.5. Their integer parts are the reader's indices up to rounding at
    cell edges and at degenerate pairs, which trilinear weights do not feel."""
    th = torch.sqrt(torch.clamp(theta_h.double() / (math.pi / 2.0), min=0.0)) * RES_THETA_H
    td = theta_d.double() / (math.pi / 2.0) * RES_THETA_D
    pd = fold_phi_diff(phi_d) / math.pi * RES_PHI_D
    return th, td, pd


def lookup_trilinear(values: np.ndarray, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """Trilinear interpolation between cell centres; φd wraps (period π); invalid cells get zero weight."""
    th, td, pd = reused.derived(direction_data, wi, wo, "continuous")
    table = torch.from_numpy(np.ascontiguousarray(values)).reshape(3, N_CELLS)
    valid = (table >= 0).all(dim=0).double()  # scales are positive: same sign as raw

    def corners(x, n, wrap):
        x = x - 0.5
        lo = torch.floor(x)
        frac = x - lo
        lo = lo.long()
        hi = lo + 1
        if wrap:
            lo, hi = lo % n, hi % n
        else:
            frac = torch.where(lo < 0, torch.zeros_like(frac), frac)
            frac = torch.where(hi > n - 1, torch.zeros_like(frac), frac)
            lo, hi = lo.clamp(0, n - 1), hi.clamp(0, n - 1)
        return (lo, 1 - frac), (hi, frac)

    acc = torch.zeros(wi.shape[0], 3, dtype=torch.float64)
    wsum = torch.zeros(wi.shape[0], dtype=torch.float64)
    for ih, wh in corners(th, RES_THETA_H, False):
        for id_, wd in corners(td, RES_THETA_D, False):
            for ip, wp in corners(pd, RES_PHI_D, True):
                flat = (ih * RES_THETA_D + id_) * RES_PHI_D + ip
                w = wh * wd * wp * valid[flat]
                acc += w[:, None] * table[:, flat].T
                wsum += w
    out = acc / torch.where(wsum > 0, wsum, torch.ones_like(wsum))[:, None]
    return torch.where((wsum > 0)[:, None], out, torch.full_like(out, -1.0))


# --------------------------------------------------------------------------- the grid


def grid_angles(dtype=torch.float64) -> coords.HalfDiff:
    """Rusinkiewicz angles (φh = 0) of the 90×90×180 cell centres, each flattened (N_CELLS,).

    Centres sit half a cell into each bin of the reference indexing, so `lookup_nearest`
    at a centre returns that very cell.
    """
    i = (torch.arange(RES_THETA_H, dtype=torch.float64) + 0.5) / RES_THETA_H
    theta_h = i * i * (math.pi / 2)
    theta_d = (torch.arange(RES_THETA_D, dtype=torch.float64) + 0.5) / RES_THETA_D * (math.pi / 2)
    phi_d = (torch.arange(RES_PHI_D, dtype=torch.float64) + 0.5) / RES_PHI_D * math.pi
    th, td, pd = torch.meshgrid(theta_h, theta_d, phi_d, indexing="ij")
    zeros = torch.zeros(N_CELLS, dtype=torch.float64)
    return coords.HalfDiff(th.reshape(-1).to(dtype), zeros.to(dtype), td.reshape(-1).to(dtype), pd.reshape(-1).to(dtype))


@lru_cache(maxsize=2)
def grid_directions(dtype=torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """Direction pairs (N_CELLS, 3) at the cell centres, in table order.

    Cached (about 70 MB in fp64): every caller gets the same tensors, so never modify
    them in place.
    """
    g = grid_angles(torch.float64)
    wi, wo = coords.from_half_diff(g.theta_h, g.phi_h, g.theta_d, g.phi_d)
    return wi.to(dtype), wo.to(dtype)


@lru_cache(maxsize=1)
def grid_above_horizon() -> torch.Tensor:
    """(N_CELLS,) bool mask of the cell centres whose two directions are above the horizon.

    Cached, like `grid_directions`: never modify it in place.
    """
    return coords.above_horizon(*grid_directions(torch.float64))
