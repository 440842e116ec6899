"""BRDF-space distances between two sets of materials over the full 90×90×180 MERL grid, as
the distances the distributional metrics (`distributional`) are computed from (seed 003
eq. 6 and eq. 36; seed 000 eq. 4.12 for the cosine-weighted form):

- `l1`: mean |f − f'| (1/sr),
- `l1_log`: mean |log(1 + f) − log(1 + f')|,
- `l1_log_cos`: mean |log(1 + f cos θi) − log(1 + f' cos θi)|,

the mean taken over RGB and over the cells valid in every table of both sets (a cell one
table lacks is left out for all pairs, so every entry of a matrix averages the same
cells). Members are MERL-layout value arrays (3, 90, 90, 180) in 1/sr (negative = invalid,
as `MerlTable.values`), `MerlTable`s, or cell sources read lazily (`MerlFileCells`,
`RepresentationCells`, or any object with `grid_cells`). The grid is walked in chunks of cells: per chunk,
each set's transformed values are stacked and the pairwise L1 sums taken by a compiled
kernel (numba, both cores), all in fp64, so memory stays at a chunk of every member beside
the members themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from brdfbench import merl

KINDS = ("l1", "l1_log", "l1_log_cos")
#: Cells per chunk: 3 channels × this × (|A| + |B|) fp64 values are live at once.
CHUNK_CELLS = 1 << 15


class CellSource(Protocol):
    """A member read lazily: its values (3, len(cells)) float64, 1/sr (negative = invalid), at
    flat grid cells. Sets too large to hold as tables (240 full tables are 8.4 GB in fp64) are
    passed as sources: memory then stays at one chunk of every member."""

    def grid_cells(self, cells: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class MerlFileCells:
    """A MERL `.binary` file, memory-mapped: chunks are read from disk as they are needed."""

    path: Path

    def __post_init__(self):
        merl.read_binary(self.path)  # validated once, up front (header, size, finiteness)

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        raw = np.memmap(self.path, dtype="<f8", mode="r", offset=merl.HEADER_BYTES, shape=(3, merl.N_CELLS))
        return np.asarray(raw[:, cells]) * np.asarray(merl.CHANNEL_SCALES)[:, None]


@dataclass(frozen=True)
class RepresentationCells:
    """A fitted representation evaluated (fp64) at the grid's cell centres, chunk by chunk."""

    model: object

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        wi, wo = merl.grid_directions(torch.float64)
        idx = torch.from_numpy(np.asarray(cells))
        with torch.no_grad():
            f = self.model.eval(wi[idx], wo[idx])
        return f.detach().to(torch.float64).numpy().T


class _Array:
    def __init__(self, values: np.ndarray):
        self.flat = values.reshape(3, -1)

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        return np.asarray(self.flat[:, cells], dtype=np.float64)


def _source(member, where: str) -> CellSource:
    if hasattr(member, "grid_cells"):
        return member
    v = member.values if hasattr(member, "values") and not isinstance(member, np.ndarray) else member
    v = np.asarray(v)
    if v.shape != (3, *merl.SHAPE):
        raise ValueError(f"{where}: expected MERL values of shape (3, {', '.join(map(str, merl.SHAPE))}), "
                         f"a MerlTable or a cell source, got {v.shape}")
    return _Array(v)


def _chunk(source: CellSource, cells: np.ndarray, where: str, finite: bool) -> np.ndarray:
    """A member's values at `cells`; `finite`: every one must be finite (cells the caller chose)."""
    v = source.grid_cells(cells)
    if v.shape != (3, len(cells)):
        raise ValueError(f"{where}: a chunk of {len(cells)} cells came back with shape {v.shape}")
    if finite and not np.isfinite(v).all():
        raise ValueError(f"{where}: non-finite values at the grid cells (exclude and count the member instead)")
    return v


def _valid(v: np.ndarray) -> np.ndarray:
    """Cells (columns) valid in a member's chunk: every channel ≥ 0 and finite."""
    return (v >= 0).all(axis=0) & np.isfinite(v).all(axis=0)


def _cos_theta_i() -> np.ndarray:
    wi, _ = merl.grid_directions(torch.float64)
    return wi[:, 2].clamp_min(0).numpy()


def _transform(kind: str) -> Callable[[np.ndarray, np.ndarray | None, np.ndarray], None]:
    """transform(f (3, K), cos (K,) or None, out (3, K)): the values a distance compares,
    written into `out` (a row of the stacked chunk: no intermediate copy)."""
    def log_in_place(out):
        t = torch.from_numpy(out)  # torch's log1p: vectorised and on both cores, about 4x numpy's here
        torch.log1p(t, out=t)

    if kind == "l1":
        return lambda f, c, out: np.copyto(out, f)
    if kind == "l1_log":
        return lambda f, c, out: (np.copyto(out, f), log_in_place(out))
    if kind == "l1_log_cos":
        return lambda f, c, out: (np.multiply(f, c, out=out), log_in_place(out))
    raise ValueError(f"unknown BRDF distance {kind!r}: one of {', '.join(KINDS)}")


def _stacked(raw: list[np.ndarray], sel, c, transform) -> np.ndarray:
    """(members, 3·K) float64: each member's chunk at `sel`, transformed, one row each."""
    k = raw[0].shape[1] if isinstance(sel, slice) else int(np.count_nonzero(sel))
    out = np.empty((len(raw), 3 * k), dtype=np.float64)
    for row, v in zip(out, raw):
        transform(v[:, sel], c, row.reshape(3, k))
    return out


def common_valid_cells(*sets: Sequence, chunk_cells: int = 1 << 20) -> np.ndarray:
    """Flat indices of the cell centres above the horizon that are valid (every channel ≥ 0
    and finite) in every member of the sets."""
    keep = merl.grid_above_horizon().numpy().copy()
    everything = np.arange(merl.N_CELLS)
    for s, members in enumerate(sets):
        for i, m in enumerate(members):
            src = _source(m, f"set {s}, member {i}")
            for start in range(0, merl.N_CELLS, chunk_cells):
                idx = everything[start:start + chunk_cells]
                keep[idx] &= _valid(src.grid_cells(idx))
    return np.flatnonzero(keep)


def distance_matrix(a: Sequence, b: Sequence | None = None, kind: str = "l1", *, cells: np.ndarray | None = None,
                    chunk_cells: int = CHUNK_CELLS, progress: Callable[[int, int], None] | None = None) -> np.ndarray:
    """(len(a), len(b)) float64 distances of kind `kind` (b = a when None); `cells` overrides
    the common valid cells; `progress(done, total)` is called after each chunk."""
    transform = _transform(kind)
    b_is_a = b is None
    b = a if b is None else b
    if len(a) == 0 or len(b) == 0:
        raise ValueError(f"a distance matrix needs members in both sets (got {len(a)} and {len(b)})")
    if chunk_cells < 1:
        raise ValueError(f"chunk_cells must be at least 1, got {chunk_cells}")
    va = [_source(m, f"set a, member {i}") for i, m in enumerate(a)]
    vb = va if b_is_a else [_source(m, f"set b, member {i}") for i, m in enumerate(b)]
    chosen = cells is not None
    # One pass over the grid: where the caller chose no cells, each chunk's common valid
    # cells are found from the very values read for it, so no member is read twice.
    walk = np.asarray(cells) if chosen else np.flatnonzero(merl.grid_above_horizon().numpy())
    cos = _cos_theta_i() if kind == "l1_log_cos" else None
    total = np.zeros((len(va), len(vb)), dtype=np.float64)
    used = 0
    for start in range(0, len(walk), chunk_cells):
        idx = walk[start:start + chunk_cells]
        raw_a = [_chunk(v, idx, f"set a, member {i}", chosen) for i, v in enumerate(va)]
        raw_b = raw_a if b_is_a else [_chunk(v, idx, f"set b, member {i}", chosen) for i, v in enumerate(vb)]
        keep = np.ones(len(idx), dtype=bool)
        if not chosen:
            for v in raw_a if b_is_a else raw_a + raw_b:
                keep &= _valid(v)
            if not keep.any():
                continue
        sel = slice(None) if keep.all() else keep  # no copy of a chunk every cell of which counts
        c = None if cos is None else cos[idx[sel]]
        xa = _stacked(raw_a, sel, c, transform)
        xb = xa if b_is_a else _stacked(raw_b, sel, c, transform)
        l1_sums(xa, xb, total, b_is_a)
        used += int(keep.sum())
        if progress is not None:
            progress(min(start + chunk_cells, len(walk)), len(walk))
    if used == 0:
        raise ValueError("no MERL cell is valid in every member of both sets: nothing to compare")
    if b_is_a:
        total = np.triu(total, 1) + np.triu(total, 1).T  # the kernel fills the upper triangle
    return total / (3 * used)


#: Values per sub-block of the kernel: four members' blocks (a tile: each value of the other
#: set read once serves four sums) stay in L1 while every other member's block streams past.
BLOCK = 1024


@lru_cache(maxsize=1)
def _kernel():
    """The pairwise-L1 kernel, compiled once (numba, cached on disk where it can be).

    numba's own thread pool ("workqueue"), not its OpenMP layer: that one shares torch's
    OpenMP runtime and resets its thread count, after which torch's reductions in the same
    process sum in another order (a last-bit change in every later figure)."""
    import numba

    numba.config.THREADING_LAYER = "workqueue"

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def kernel(xa, xb, out, symmetric, block):
        n, k = xa.shape
        m = xb.shape[0]
        tiles = (n + 3) // 4
        # Blocks outermost: every tile sweeps one block of every member while that block
        # (members × block values) sits in the shared cache, so each value comes from memory
        # once, not once per tile. Each sum still adds its blocks in order: same figures.
        for b0 in range(0, k, block):
            b1 = min(b0 + block, k)
            for p in numba.prange(tiles):
                # tiles interleaved from both ends: a triangle's long and short rows
                # alternate, so the threads' shares of the work stay even
                t = p // 2 if p % 2 == 0 else tiles - 1 - p // 2
                i0 = t * 4
                full = i0 + 3 < n
                for j in range(i0 + 1 if symmetric else 0, m):
                    b = xb[j]
                    if full:
                        a0, a1, a2, a3 = xa[i0], xa[i0 + 1], xa[i0 + 2], xa[i0 + 3]
                        s0 = s1 = s2 = s3 = 0.0
                        for c in range(b0, b1):
                            v = b[c]
                            s0 += abs(a0[c] - v)
                            s1 += abs(a1[c] - v)
                            s2 += abs(a2[c] - v)
                            s3 += abs(a3[c] - v)
                        out[i0, j] += s0
                        if not symmetric or j > i0 + 1:
                            out[i0 + 1, j] += s1
                        if not symmetric or j > i0 + 2:
                            out[i0 + 2, j] += s2
                        if not symmetric or j > i0 + 3:
                            out[i0 + 3, j] += s3
                    else:
                        for r in range(i0, n):
                            if not symmetric or j > r:
                                a = xa[r]
                                acc = 0.0
                                for c in range(b0, b1):
                                    acc += abs(a[c] - b[c])
                                out[r, j] += acc

    return kernel


def l1_sums(xa: np.ndarray, xb: np.ndarray, out: np.ndarray, symmetric: bool = False) -> None:
    """out[i, j] += Σ_c |xa[i, c] − xb[j, c]| in fp64 (only j > i where `symmetric`: xb is xa),
    summed in blocks in any order (the compiler may vectorise the sum)."""
    xa = np.ascontiguousarray(xa, dtype=np.float64)
    xb = xa if symmetric else np.ascontiguousarray(xb, dtype=np.float64)
    if xa.shape[1] != xb.shape[1] or out.shape != (xa.shape[0], xb.shape[0]):
        raise ValueError(f"l1_sums: shapes {xa.shape}, {xb.shape} and out {out.shape} do not match")
    _kernel()(xa, xb, out, symmetric, BLOCK)
