"""BRDF-space distances between two sets of materials over the full 90×90×180 MERL grid, as
the distances the distributional metrics (`distributional`) are computed from (Zhou et al.
eq. 6 and eq. 36; Hu 2026 eq. 4.12 for the cosine-weighted form):

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

On a CUDA device (`device=`), or with `backend="torch"` anywhere, the same walk runs in
torch (`_torch_matrix`): per chunk of cells every member's values are stacked on the device
(each member's values cross to the device once: tables in their own dtype, representations
evaluated where they live), the cells not valid in every member are zeroed (they add
nothing to any sum, and are not counted), the transform applied in place, and the pairwise
L1 sums taken by `torch.cdist(p=1)` over column blocks small enough for the device's cache,
in fp64. Chunks are sized from `DEVICE_BYTES`, so device memory stays near that budget
whatever the number of members (plus the N × N result). It agrees with the numba kernel to
rounding (about 1e-14 relative; the sums run in another order).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from .. import merl

KINDS = ("l1", "l1_log", "l1_log_cos")
#: Cells per chunk: 3 channels × this × (|A| + |B|) fp64 values are live at once.
CHUNK_CELLS = 1 << 15
#: "auto": numba on the CPU, torch on a CUDA device; "torch" also runs on the CPU (CI checks
#: it against numba there).
BACKENDS = ("auto", "numba", "torch")
#: Device memory the torch path's chunks may take (the stacked chunk, its column-blocked
#: copy and the validity masks): chunks hold about DEVICE_BYTES / (|A ∪ B| · 3 · BYTES_PER_VALUE)
#: cells, at most `DEVICE_CHUNK_CELLS`.
DEVICE_BYTES = 2 << 30
BYTES_PER_VALUE = 20
DEVICE_CHUNK_CELLS = 1 << 18
#: Bytes of one set's column block in the torch path: small enough that a block of every
#: member stays in the GPU's L2 cache while each pair of rows is compared.
COLUMN_BLOCK_BYTES = 12 << 20
#: Bytes of the per-block pairwise sums taken in one call (column blocks × |A| × |B| fp64).
SUMS_BYTES = 256 << 20


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
        if self.device.type != "cpu":
            return self.on_device(torch.from_numpy(np.asarray(cells)), torch.device("cpu")).numpy()
        wi, wo = merl.grid_directions(torch.float64)
        idx = torch.from_numpy(np.asarray(cells))
        with torch.no_grad():
            f = self.model.eval(wi[idx], wo[idx])
        return f.detach().to(torch.float64).numpy().T

    @property
    def device(self) -> torch.device:
        """Where the representation evaluates (`Placed.device`; the CPU for a plain object)."""
        where = getattr(self.model, "device", None)
        return torch.device("cpu") if where is None else torch.device(where)

    def on_device(self, cells: torch.Tensor, device: torch.device) -> torch.Tensor:
        """(3, len(cells)) float64 on `device`: evaluated on the representation's own device
        (its inputs there, so a model on a GPU never computes on the host), then moved."""
        here = self.device
        wi, wo = _grid_directions_on(here)
        idx = cells.to(here)
        with torch.no_grad():
            f = self.model.eval(wi[idx], wo[idx])
        return f.detach().to(torch.float64).T.to(device)


class _Array:
    def __init__(self, values: np.ndarray):
        self.flat = values.reshape(3, -1)

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        return np.asarray(self.flat[:, cells], dtype=np.float64)

    def on_device(self, cells: torch.Tensor, device: torch.device) -> torch.Tensor:
        """The values at `cells` moved in their own float dtype (half the bytes of fp64 for a
        float32 table); the caller widens them to fp64 on the device, exactly."""
        v = self.flat[:, cells.numpy()]
        v = v if v.dtype in (np.float32, np.float64) else v.astype(np.float64)
        return torch.from_numpy(np.ascontiguousarray(v)).to(device)


class _Tensor:
    """A (3, 90, 90, 180) tensor member: gathered where it lives (a table already on a GPU
    never crosses to the host in the torch path)."""

    def __init__(self, values: torch.Tensor):
        self.flat = values.detach().reshape(3, -1)

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        idx = torch.from_numpy(np.asarray(cells)).to(self.flat.device)
        return self.flat[:, idx].to(torch.float64).cpu().numpy()

    def on_device(self, cells: torch.Tensor, device: torch.device) -> torch.Tensor:
        return self.flat[:, cells.to(self.flat.device)].to(device)


@lru_cache(maxsize=4)
def _grid_directions_on(device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """The fp64 grid directions on `device` (one copy per device; never modify in place)."""
    wi, wo = merl.grid_directions(torch.float64)
    return (wi, wo) if device.type == "cpu" else (wi.to(device), wo.to(device))


def _source(member, where: str) -> CellSource:
    if hasattr(member, "grid_cells"):
        return member
    if isinstance(member, torch.Tensor):
        if tuple(member.shape) != (3, *merl.SHAPE) or not member.is_floating_point():
            raise ValueError(f"{where}: expected MERL values of shape (3, {', '.join(map(str, merl.SHAPE))}), "
                             f"a MerlTable or a cell source, got a {member.dtype} tensor of shape {tuple(member.shape)}")
        return _Tensor(member)
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
                    chunk_cells: int | None = None, progress: Callable[[int, int], None] | None = None,
                    device: "torch.device | str | None" = None, backend: str = "auto") -> np.ndarray:
    """(len(a), len(b)) float64 distances of kind `kind` (b = a when None); `cells` overrides
    the common valid cells; `progress(done, total)` is called after each chunk. `device`
    (None: the CPU) is where the sums are taken: the CPU's numba kernel, or torch on a CUDA
    device; `backend="torch"` runs the torch path on the CPU too. `chunk_cells`: cells per
    chunk (default `CHUNK_CELLS` for numba, from `DEVICE_BYTES` for torch)."""
    transform = _transform(kind)
    device = torch.device("cpu") if device is None else torch.device(device)
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}: one of {', '.join(BACKENDS)}")
    if backend == "numba" and device.type != "cpu":
        raise ValueError(f"backend='numba' runs on the CPU, not {device}; use backend='torch' (or 'auto')")
    b_is_a = b is None
    b = a if b is None else b
    if len(a) == 0 or len(b) == 0:
        raise ValueError(f"a distance matrix needs members in both sets (got {len(a)} and {len(b)})")
    if chunk_cells is not None and chunk_cells < 1:
        raise ValueError(f"chunk_cells must be at least 1, got {chunk_cells}")
    va = [_source(m, f"set a, member {i}") for i, m in enumerate(a)]
    vb = va if b_is_a else [_source(m, f"set b, member {i}") for i, m in enumerate(b)]
    if backend == "torch" or device.type != "cpu":
        return _torch_matrix(va, None if b_is_a else vb, kind, cells, chunk_cells, progress, device)
    chunk_cells = CHUNK_CELLS if chunk_cells is None else chunk_cells
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


# --------------------------------------------------------------------------- the torch path


def _on_device(source: CellSource, idx: np.ndarray, idx_t: torch.Tensor, device: torch.device,
               where: str) -> torch.Tensor:
    """(3, len(idx)) float values of a member at `idx` on `device` (any float dtype: the
    caller widens to fp64 there). Tables and representations go straight to the device;
    any other source is read on the host, as the numba path reads it."""
    if isinstance(source, (_Array, _Tensor, RepresentationCells)):
        v = source.on_device(idx_t, device)
    else:
        v = torch.from_numpy(np.asarray(source.grid_cells(idx), dtype=np.float64)).to(device)
    if tuple(v.shape) != (3, len(idx)):
        raise ValueError(f"{where}: a chunk of {len(idx)} cells came back with shape {tuple(v.shape)}")
    return v


def _column_blocks(x: torch.Tensor, width: int) -> torch.Tensor:
    """(members, L) as (blocks, members, width), contiguous, the last block padded with zeros
    (|0 − 0| adds nothing to a sum)."""
    m, length = x.shape
    full, rest = divmod(length, width)
    out = x.new_zeros((full + (rest > 0), m, width))
    if full:
        out[:full] = x[:, :full * width].view(m, full, width).transpose(0, 1)
    if rest:
        out[full, :, :rest] = x[:, full * width:]
    return out


def _torch_matrix(va: list, vb: list | None, kind: str, cells: np.ndarray | None, chunk_cells: int | None,
                  progress: Callable[[int, int], None] | None, device: torch.device) -> np.ndarray:
    """`distance_matrix` in torch on `device` (vb None: va against itself); see the module
    docstring. The same walk, the same rule for the cells compared and the same transform
    as the numba path."""
    members = va if vb is None else va + vb
    na, nm = len(va), len(members)
    chosen = cells is not None
    walk = np.asarray(cells) if chosen else np.flatnonzero(merl.grid_above_horizon().numpy())
    if chunk_cells is None:
        chunk_cells = max(1, min(DEVICE_CHUNK_CELLS, DEVICE_BYTES // (nm * 3 * BYTES_PER_VALUE)))
    width = max(256, COLUMN_BLOCK_BYTES // (8 * nm))
    group = max(1, SUMS_BYTES // (8 * na * (nm - na if vb is not None else na)))
    cos = torch.from_numpy(_cos_theta_i()).to(device) if kind == "l1_log_cos" else None
    names = [f"set a, member {i}" for i in range(na)] + [f"set b, member {j}" for j in range(nm - na)]
    total = torch.zeros((na, nm - na if vb is not None else na), dtype=torch.float64, device=device)
    used = torch.zeros((), dtype=torch.int64, device=device)
    with torch.no_grad():
        for start in range(0, len(walk), chunk_cells):
            idx = np.ascontiguousarray(walk[start:start + chunk_cells])
            idx_t = torch.from_numpy(idx)
            stack = torch.empty((nm, 3, len(idx)), dtype=torch.float64, device=device)
            for i, source in enumerate(members):
                stack[i] = _on_device(source, idx, idx_t, device, names[i])
            if chosen:
                bad = ~torch.isfinite(stack).flatten(1).all(dim=1)
                if bool(bad.any()):
                    raise ValueError(f"{names[int(bad.nonzero()[0])]}: non-finite values at the grid cells "
                                     "(exclude and count the member instead)")
                used += len(idx)
            else:
                # a cell counts where every channel of every member is ≥ 0 and finite; the
                # others are zeroed in every member, so they add nothing to any pair's sum
                keep = (torch.isfinite(stack) & (stack >= 0)).flatten(0, 1).all(dim=0)
                stack.masked_fill_(~keep, 0.0)
                used += keep.sum()
            if kind == "l1_log_cos":
                stack.mul_(cos[idx_t.to(device)])
            if kind != "l1":
                stack.log1p_()
            x = stack.view(nm, -1)
            xa = _column_blocks(x[:na], width)
            xb = xa if vb is None else _column_blocks(x[na:], width)
            del stack, x
            for g in range(0, xa.shape[0], group):  # the per-block sums of a group of column blocks
                total += torch.cdist(xa[g:g + group], xb[g:g + group], p=1.0).sum(dim=0)
            del xa, xb
            if progress is not None:
                progress(min(start + chunk_cells, len(walk)), len(walk))
    used = int(used)
    if used == 0:
        raise ValueError("no MERL cell is valid in every member of both sets: nothing to compare")
    out = total.cpu().numpy()
    if vb is None:
        out = np.triu(out, 1) + np.triu(out, 1).T  # as the numba path: a zero diagonal, mirrored
    return out / (3 * used)


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
