"""MERL `.binary` tables: reading, writing, validation and lookup.

Follows the reference reader (Matusik et al., BRDFRead.cpp) exactly: a header of three
int32 dims (90, 90, 180), then float64 values channel-major (all R, then G, then B), each
channel scaled by 1/1500, 1.15/1500, 1.66/1500; θh indexed by square-root warping; φd
folded by reciprocity into [0, π). Negative cells mark invalid measurements.
"""

from __future__ import annotations

import math
import os
import weakref
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from . import coords
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
        raw = np.asarray(values, dtype=np.float64) / _SCALES
        if valid is not None:
            raw = np.where(valid[None], raw, INVALID_RAW)
        return cls(raw)

    @cached_property
    def values(self) -> np.ndarray:
        return self.raw * _SCALES

    @cached_property
    def valid(self) -> np.ndarray:
        """(90, 90, 180) mask of cells valid in all three channels."""
        return np.all(self.raw >= 0, axis=0)

    def lookup(self, wi: torch.Tensor, wo: torch.Tensor, mode: str = "nearest") -> torch.Tensor:
        """BRDF values (N, 3) float64 at direction pairs (raw × channel scales, negatives
        included), as the reference returns them."""
        if mode == "nearest":
            return lookup_nearest(self.values, wi, wo)
        if mode == "trilinear":
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


# --------------------------------------------------------------------------- indexing


def theta_half_index(theta_h: torch.Tensor) -> torch.Tensor:
    """Reference θh index: int(sqrt(θh / (π/2) · 90 · 90)), 0 for θh <= 0, clamped to [0, 89].

    The square root is numpy's (IEEE, correctly rounded, as C's sqrt): torch's float64
    sqrt on AVX-512 CPUs can be 1 ulp off, which moves θh right below a cell edge
    (sqrt(k² − ulp) rounds to k) into the wrong cell.
    """
    t = theta_h.double()
    x = torch.clamp(t / (math.pi / 2.0) * RES_THETA_H * RES_THETA_H, min=0.0)
    warped = torch.from_numpy(np.sqrt(x.detach().cpu().numpy())).to(t.device)
    idx = torch.clamp(warped.long(), 0, RES_THETA_H - 1)
    return torch.where(t <= 0, torch.zeros_like(idx), idx)


def theta_diff_index(theta_d: torch.Tensor) -> torch.Tensor:
    """Reference θd index: int(θd / (π/2) · 90), clamped to [0, 89]."""
    return torch.clamp((theta_d.double() / (math.pi * 0.5) * RES_THETA_D).long(), 0, RES_THETA_D - 1)


def fold_phi_diff(phi_d: torch.Tensor) -> torch.Tensor:
    """φd in [0, 2π) folded by reciprocity (φd ~ φd + π) into [0, π].

    As the reference: its atan2 gives φd in [−π, π] and only negatives move up by π, so
    φd = π itself stays π (and lands in the last cell, 179, after clamping), while
    φd in (π, 2π) — the reference's negatives — maps to φd − π.
    """
    p = phi_d.double()
    return torch.where(p > math.pi, p - math.pi, p)


def phi_diff_index(phi_d: torch.Tensor) -> torch.Tensor:
    """Reference φd index: int(φd / π · 360 / 2) after folding, clamped to [0, 179]."""
    p = fold_phi_diff(phi_d)
    return torch.clamp((p / math.pi * (2 * RES_PHI_D) / 2).long(), 0, RES_PHI_D - 1)


def cell_indices(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Reference (θh, θd, φd) cell indices of each pair (int64); see `reuse_directions`."""
    known = _reused(wi, wo, "cells")
    return known if known is not None else direction_data(wi, wo, "cells")


DIRECTION_DATA = ("cells", "flat", "continuous")


def direction_data(wi: torch.Tensor, wo: torch.Tensor, kind: str) -> tuple[torch.Tensor, ...]:
    """What the lookups derive from the directions alone, always computed afresh: "cells",
    the reference cell indices; "flat", (`flat_index` of them,); "continuous",
    `continuous_indices` of the angles."""
    if kind not in DIRECTION_DATA:
        raise ValueError(f"unknown direction data {kind!r}; expected one of {', '.join(DIRECTION_DATA)}")
    hd = coords.to_half_diff(wi.double(), wo.double())
    if kind == "continuous":
        return continuous_indices(hd.theta_h, hd.theta_d, hd.phi_d)
    cells = theta_half_index(hd.theta_h), theta_diff_index(hd.theta_d), phi_diff_index(hd.phi_d)
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
    known = _reused(wi, wo, "flat")
    return gather_cells(values, known[0] if known is not None else flat_index(*cell_indices(wi, wo)))


def continuous_indices(theta_h, theta_d, phi_d):
    """Fractional cell coordinates whose integer parts are the reference indices; cell centres sit at i + 0.5."""
    th = torch.sqrt(torch.clamp(theta_h.double() / (math.pi / 2.0), min=0.0)) * RES_THETA_H
    td = theta_d.double() / (math.pi / 2.0) * RES_THETA_D
    pd = fold_phi_diff(phi_d) / math.pi * RES_PHI_D
    return th, td, pd


def lookup_trilinear(values: np.ndarray, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """Trilinear interpolation between cell centres; φd wraps (period π); invalid cells get zero weight."""
    known = _reused(wi, wo, "continuous")
    th, td, pd = known if known is not None else direction_data(wi, wo, "continuous")
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


# --------------------------------------------------------------------------- reused directions
#
# A harness evaluates every material at the same directions. It registers the tensors it
# passes to models, with a function giving their direction data (computed once per process
# on all of its directions), so table lookups on exactly those tensors skip the angle and
# index computation. An entry holds weak references and is matched by identity (`is`), so a
# freed tensor whose id is reused never matches; it is dropped when a tensor changes in place.

MAX_REUSED = 64  # registered pairs kept; the oldest goes first


@dataclass(eq=False)
class _Reused:
    wi: weakref.ref
    wo: weakref.ref
    versions: tuple[int, int]
    provide: Callable[[str], tuple[torch.Tensor, ...]]


_REUSED: dict[int, _Reused] = {}


def reuse_directions(wi: torch.Tensor, wo: torch.Tensor,
                     provide: Callable[[str], tuple[torch.Tensor, ...]]) -> None:
    """Register (wi, wo): lookups on these very tensors, while unmodified, take their
    direction data from `provide(kind)`, which must return `direction_data(wi, wo, kind)`."""
    key = id(wi)
    forget = lambda ref, key=key: _forget(key, ref)  # noqa: E731
    _REUSED.pop(key, None)
    _REUSED[key] = _Reused(weakref.ref(wi, forget), weakref.ref(wo, forget), (wi._version, wo._version), provide)
    while len(_REUSED) > MAX_REUSED:
        _REUSED.pop(next(iter(_REUSED)))


def _forget(key: int, ref: weakref.ref) -> None:
    entry = _REUSED.get(key)
    if entry is not None and (ref is entry.wi or ref is entry.wo):
        del _REUSED[key]


def _reused(wi: torch.Tensor, wo: torch.Tensor, kind: str):
    entry = _REUSED.get(id(wi))
    if entry is None or entry.wi() is not wi or entry.wo() is not wo:
        return None
    if (wi._version, wo._version) != entry.versions:
        del _REUSED[id(wi)]
        return None
    return entry.provide(kind)


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
