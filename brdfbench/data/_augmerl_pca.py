"""AugMERL's PCA over RGB-permuted materials, in kernel form on the base set's channels.

The observations are the 6n permuted materials: observation o = 6m + p is base material
m with its channels permuted by `PERMUTATIONS[p]`, i.e. the 3P-vector
[x_{m,π(0)}, x_{m,π(1)}, x_{m,π(2)}] of its channels mapped log-relative (`brdfbench.logrel`)
on the P cells of the logrel domain. Nothing of size 6n × 3P is ever built: every permuted
observation is a rearrangement of the base's 3n mapped channel vectors x_{m,c}, so

- the reference (per-cell median) and the mean are pooled over channels (see
  `pooled_reference` and `pooled_mean`);
- the 6n × 6n Gram matrix of the centred observations is assembled from the 3n × 3n Gram
  matrix g of the centred base channel vectors y_{m,c}:
  G[(m,π),(m',π')] = Σ_c g[(m,π(c)),(m',π'(c))];
- with G = U Λ Uᵀ, observation o has coefficients c_o = Λ_k^{1/2} U_k[o] on the top-k
  basis v_j = Σ_o ỹ_o U[o,j] / √λ_j, and a point c of coefficient space reconstructs to
  μ + Σ_o α_o ỹ_o with α = U_k Λ_k^{-1/2} c; for c = (1 − t) c_a + t c_b this is
  α = U_k ((1 − t) U_k[a] + t U_k[b])ᵀ. Output channel c then weighs base vector (m, c')
  by β[c, (m,c')] = Σ_{π: π(c) = c'} α_(m,π) (`channel_weights`).

All functions take plain tensors of any width P, so tests can check them against an
explicit-basis PCA on a small P.

Devices: the two products over all P cells, `base_gram` (3n × 3n × P, fp64) and
`reconstruct` (3 × 3n × P per mix), run where they are told or where their inputs are
(`base_gram(centred, device)` moves one block of cells at a time); the rest is small or
selects values (medians) and runs on the CPU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .. import logrel

#: The six channel permutations: destination channel c takes source channel p[c]; the
#: first is the identity. Named by the source letters, e.g. (1, 2, 0) is "gbr".
PERMUTATIONS: tuple[tuple[int, int, int], ...] = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
PERMUTATION_NAMES = tuple("".join("rgb"[i] for i in p) for p in PERMUTATIONS)
#: Cells per block of the chunked passes (bounds fp64 temporaries to ~100 MB at n = 100).
CHUNK = 1 << 15
#: Base vectors summed in fp32 before an fp64 accumulation (`reconstruct`).
ROW_BLOCK = 24
#: Eigenvalues below this share of the largest are null (the rank).
RANK_TOL = 1e-10
#: Eigenvalues this close (share of the largest) are one degenerate cluster, never split.
DEGENERATE_TOL = 1e-9


def source_rows(n: int) -> torch.Tensor:
    """(6n, 3) long: row of the base channel matrix that observation o's channel c comes from."""
    perms = torch.tensor(PERMUTATIONS, dtype=torch.long)  # (6, 3)
    return (3 * torch.arange(n)[:, None, None] + perms[None]).reshape(6 * n, 3)


def pooled_reference(values: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """(P,) float32 reference: the median over all base channel values valid at each cell.

    Why this is the per-channel median over the permuted set: at a cell, destination
    channel c of the 6n permuted materials holds v_{m,π(c)} for every base material m
    valid there and every π; as π runs over the 6 permutations, π(c) takes each source
    channel exactly twice. So every channel sees the same multiset, each base channel
    value twice. Doubling a sorted list s_1..s_N into s_1,s_1,…,s_N,s_N moves its middle
    positions N−1 and N (0-based, 2N elements) to s_⌊(N−1)/2⌋ and s_⌊N/2⌋: the lower
    median (torch's) and the mean-of-middles median are those of the undoubled list.
    `values` is (3n, P) (rows 3m + c), `valid` (n, P); a cell no material is valid at gets
    0, as the `pca` representation does.
    """
    n3, p = values.shape
    out = torch.empty(p, dtype=torch.float32)
    for start in range(0, p, CHUNK):
        sl = slice(start, start + CHUNK)
        block = values[:, sl].float().clone()
        block[~valid[:, sl].repeat_interleave(3, dim=0)] = float("nan")
        out[sl] = torch.nanmedian(block, dim=0).values
    return torch.nan_to_num(out, nan=0.0).clamp_min(0.0)


def map_channels_(values: torch.Tensor, valid: torch.Tensor, reference: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Map (3n, P) float32 values log-relative to `reference` in place; invalid cells sit at
    the reference (x = 0), as in the `pca` representation. Returns `values`."""
    ref = reference.double()
    for m in range(valid.shape[0]):
        rows = values[3 * m : 3 * m + 3]
        mapped = logrel.to_mapped(rows.double(), ref, w)
        rows.copy_(torch.where(valid[m], mapped, 0.0).float())
    return values


def pooled_mean(channels: torch.Tensor) -> torch.Tensor:
    """(P,) float32 mean of the 3n base channel vectors, summed in fp64.

    The mean of the 6n permuted observations is this vector in each of its three channel
    blocks: destination channel c averages x_{m,π(c)} over (m, π), and π(c) takes each
    source channel twice."""
    out = torch.empty(channels.shape[1], dtype=torch.float32)
    for start in range(0, channels.shape[1], CHUNK):
        sl = slice(start, start + CHUNK)
        out[sl] = channels[:, sl].double().mean(dim=0).float()
    return out


def centre_(channels: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """Subtract the pooled mean from every row, in place (fp32). Returns `channels`."""
    channels -= mean
    return channels


def base_gram(centred: torch.Tensor, device: torch.device | str | None = None) -> torch.Tensor:
    """(3n, 3n) fp64 Gram matrix of the centred base channel vectors, a block of cells at a
    time, accumulated on `device` (default: centred's; each block moves there as it is
    used); returned on the CPU."""
    device = centred.device if device is None else torch.device(device)
    g = torch.zeros(centred.shape[0], centred.shape[0], dtype=torch.float64, device=device)
    for start in range(0, centred.shape[1], CHUNK):
        block = centred[:, start : start + CHUNK].to(device).double()
        g += block @ block.T
    return g.cpu()


def permuted_gram(g: torch.Tensor) -> torch.Tensor:
    """(6n, 6n) Gram matrix of the centred permuted observations from the base's (3n, 3n) one.

    Assembled by index permutation, so it commutes exactly with relabelling the channels
    (its eigenvalues come in exact pairs for S3's two-dimensional representation)."""
    rows = source_rows(g.shape[0] // 3)
    return sum(g[rows[:, c][:, None], rows[:, c][None, :]] for c in range(3))


@dataclass(frozen=True)
class Components:
    """Top eigenpairs of the permuted Gram matrix: `eigvals` (k,), `eigvecs` (6n, k), the
    numerical `rank` and the `k` asked for."""

    eigvals: torch.Tensor
    eigvecs: torch.Tensor
    rank: int
    k_asked: int

    @property
    def k(self) -> int:
        return int(self.eigvals.shape[0])


def components(gram: torch.Tensor, k: int) -> Components:
    """The top k eigenpairs, k capped at the rank and lowered so as not to split a degenerate
    pair (a split pair's kept vector would be rounding noise, not a basis)."""
    eigvals, eigvecs = logrel.top_eigen(gram, gram.shape[0])
    top = float(eigvals[0]) if eigvals.numel() else 0.0
    rank = int((eigvals > RANK_TOL * top).sum()) if top > 0 else 0
    if rank == 0:
        raise ValueError("the permuted materials do not vary: the PCA has no component")
    kept = min(int(k), rank)
    while 1 < kept < eigvals.shape[0] and float(eigvals[kept - 1] - eigvals[kept]) <= DEGENERATE_TOL * top:
        kept -= 1
    return Components(eigvals[:kept].clone(), eigvecs[:, :kept].contiguous(), rank, int(k))


def coefficients(comp: Components) -> torch.Tensor:
    """(6n, k) PCA coefficients of every permuted observation: U_k Λ_k^{1/2}."""
    return comp.eigvecs * comp.eigvals.clamp_min(0.0).sqrt()


def mix_weights(comp: Components, a: int, b: int, t: float) -> torch.Tensor:
    """(6n,) kernel weights α of the reconstruction of (1 − t)·c_a + t·c_b."""
    u = comp.eigvecs
    return u @ ((1.0 - t) * u[a] + t * u[b])


def point_weights(comp: Components, coeffs: torch.Tensor) -> torch.Tensor:
    """(6n,) kernel weights α = U_k Λ_k^{-1/2} c of an arbitrary coefficient vector c (k,)."""
    return comp.eigvecs @ (coeffs.double() / comp.eigvals.sqrt())


def channel_weights(alpha: torch.Tensor) -> torch.Tensor:
    """(3, 3n) weights of the base channel vectors per output channel: β[c, s(o, c)] += α_o."""
    rows = source_rows(alpha.shape[0] // 6)
    beta = torch.zeros(3, 3 * (alpha.shape[0] // 6), dtype=torch.float64)
    for c in range(3):
        beta[c].index_add_(0, rows[:, c], alpha.double())
    return beta


def reconstruct(beta: torch.Tensor, centred: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """(3, P) fp64 mapped channels μ + β·Y.

    Y stays fp32 (an fp64 copy would be 2.6 GB at n = 100, and a 3-row product is bound by
    reading Y): each block of ROW_BLOCK base vectors is summed in fp32, the blocks in fp64,
    so rounding grows with the block, not with 3n. Computed where `centred` lives (with
    `mean` there too); the result lives there."""
    out = mean.double().expand(3, -1).clone()
    b = beta.float().to(centred.device)
    for start in range(0, centred.shape[0], ROW_BLOCK):
        rows = slice(start, start + ROW_BLOCK)
        out += (b[:, rows] @ centred[rows]).double()
    return out


def pack_mask(mask: torch.Tensor) -> torch.Tensor:
    """(rows, P) bool → (rows, ⌈P/8⌉) uint8, for a compact cache file."""
    return torch.from_numpy(np.packbits(mask.numpy(), axis=1))


def unpack_mask(packed: torch.Tensor, width: int) -> torch.Tensor:
    return torch.from_numpy(np.unpackbits(packed.numpy(), axis=1, count=width).astype(bool))
