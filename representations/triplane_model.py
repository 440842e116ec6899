"""The tripleplane model's arithmetic (Xu et al. 2024, as Timonen et al. Eq. 5 and Sec. 3 describe
it): latent textures over the disk-projected half and difference vectors, read with
interpolation, their features concatenated and decoded by a small SiLU MLP to log f.

Every function works on a stack of M materials (textures (M, …), weights (M, in, out)) and
a batch of B direction pairs shared by all of them, so one code path serves evaluation
(M = 1) and batched fitting.

Coordinates: a disk-projected unit vector ω has r = |ω⊥| = sin θ and φ = atan2(ω⊥y, ω⊥x).
- The half texture is radial, over r_h = sin θh: the model is isotropic, as NBRDF's
  encoding is (φh dropped); MERL and RGL-isotropic materials do not depend on φh.
- The difference texture is polar, over r_d = sin θd and φ = φd mod π: swapping ωi and ωo
  turns d into (−dx, −dy, dz), φd into φd + π, so the read is reciprocal by construction.
- Radial nodes sit at r = i / (R − 1): node 0 is the pole, one vector for every φ (the
  paper's "repeat padding in r, broadcasting the first element for all φ"), so the read is
  continuous where φ is undefined. The φ axis has P nodes at φ = j·π / P, read circularly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from brdfbench import coords, flops
from brdfbench.nbrdf.network import MAX_LOG_VALUE, n_layers

N_OUTPUTS = 3
D_PERIOD = math.pi  # φd is read modulo π
#: Coordinate arithmetic per pair: half vector 12, ωi rotated into its frame 18, r_h and
#: r_d (hypot) 3 each, φd (atan2) 1 and its wrap 2.
COORD_FLOPS = 12 + 18 + 3 + 3 + 1 + 2


@dataclass(frozen=True)
class Shape:
    """Sizes of a tripleplane model."""

    h_res: int  # radial nodes of the half texture
    d_res: tuple[int, int]  # (radial nodes, φ nodes) of the difference texture
    channels: tuple[int, int]  # feature channels (C_h, C_d)
    hidden: tuple[int, ...]  # the decoder's hidden widths
    latent: int = 0  # D_s of the gating (texels hold C × D_s matrices times one latent z_s); 0: none
    warps: int = 0  # components of each texture's radial warp; 0: none

    @property
    def layer_sizes(self) -> list[int]:
        return [sum(self.channels), *self.hidden, N_OUTPUTS]

    def tensor_shapes(self) -> dict[str, tuple[int, ...]]:
        """name → shape of one material's tensors."""
        c_h, c_d = self.channels
        r_d, p_d = self.d_res
        g = (self.latent,) if self.latent else ()
        out = {"H": (self.h_res, c_h, *g), "D_pole": (c_d, *g), "D": (r_d - 1, p_d, c_d, *g)}
        if self.latent:
            out["z_s"] = (self.latent,)
        for tex in ("h", "d") if self.warps else ():
            out[f"warp_{tex}_alpha"] = (self.warps,)
            out[f"warp_{tex}_weight"] = (self.warps,)
        sizes = self.layer_sizes
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
            out[f"W{i}"] = (a, b)
            out[f"b{i}"] = (b,)
        return out

    def texture_floats(self) -> int:
        c_h, c_d = self.channels
        r_d, p_d = self.d_res
        return (self.h_res * c_h + c_d * (1 + (r_d - 1) * p_d)) * max(1, self.latent)

    def mlp_floats(self) -> int:
        sizes = self.layer_sizes
        return sum(a * b + b for a, b in zip(sizes[:-1], sizes[1:])) + self.latent + 4 * self.warps

    def flops(self) -> int:
        """Per evaluation, by brdfbench.flops' rules: coordinates, the radial warps (per
        component a log-multiply-exp and a weighted add: 5, plus the log of r: 1), one linear
        and one bilinear texture read, the gating (a C × D_s matrix times z_s, skipped for
        D_s = 1 as Timonen et al. skip it for uniform materials: z_s folds into the texels), the
        SiLU decoder, exp and its clamp per channel."""
        c_h, c_d = self.channels
        g = max(1, self.latent)
        warp = 2 * (1 + 5 * self.warps) if self.warps else 0
        gating = flops.dense(g, c_h + c_d, bias=False) if self.latent > 1 else 0
        return (COORD_FLOPS + warp + flops.linear_read(c_h * g) + flops.bilinear_read(c_d * g) + gating
                + flops.mlp(self.layer_sizes, "silu") + 2 * N_OUTPUTS)


def texture_coords(wi: torch.Tensor, wo: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(r_h, r_d, φd mod π) of direction pairs, in their dtype."""
    hd = coords.to_half_diff(wi, wo)
    return torch.sin(hd.theta_h), torch.sin(hd.theta_d), torch.remainder(hd.phi_d, D_PERIOD)


def _radial(r: torch.Tensor, nodes: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Lower node index and fraction of r ∈ [0, 1] on `nodes` nodes (r: (B,) or (M, B))."""
    u = (r.clamp(0.0, 1.0) * (nodes - 1))
    i0 = torch.floor(u).clamp(max=nodes - 2)
    return i0.long(), u - i0


def _select(grid: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """grid (M, N, C) at index (B,) or (M, B) → (M, B, C). index_select on the flattened
    grid: its gradient accumulates in a fixed order, so fits are deterministic on threads."""
    m, n, c = grid.shape
    index = index.expand(m, -1) + (torch.arange(m, device=index.device) * n)[:, None]
    return grid.reshape(m * n, c).index_select(0, index.reshape(-1)).reshape(m, -1, c)


def read_radial(tex: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """(M, B, C) features of a radial texture (M, R, C) at r ((B,) or per material (M, B)),
    linear between nodes."""
    i0, t = _radial(r, tex.shape[1])
    t = t.to(tex.dtype)[..., None]
    a, b = _select(tex, i0), _select(tex, i0 + 1)
    return a + (b - a) * t


def read_polar(pole: torch.Tensor, rings: torch.Tensor, r: torch.Tensor, phi: torch.Tensor,
               period: float = D_PERIOD) -> torch.Tensor:
    """(M, B, C) features of a polar texture at (r, φ): pole (M, C) at r = 0, rings
    (M, R − 1, P, C) at r = i/(R − 1), i ≥ 1; bilinear, circular in φ. r may be (B,) or
    per material (M, B); φ is (B,)."""
    m, n_rings, p, c = rings.shape
    grid = torch.cat((pole[:, None, None, :].expand(m, 1, p, c), rings), dim=1).reshape(m, (n_rings + 1) * p, c)
    i0, t = _radial(r, n_rings + 1)
    v = torch.remainder(phi, period) * (p / period)
    j = torch.floor(v)
    s = (v - j).to(rings.dtype)[..., None]
    j0 = torch.remainder(j.long(), p)
    j1 = torch.remainder(j0 + 1, p)
    t = t.to(rings.dtype)[..., None]
    a0, a1 = _select(grid, i0 * p + j0), _select(grid, i0 * p + j1)
    b0, b1 = _select(grid, (i0 + 1) * p + j0), _select(grid, (i0 + 1) * p + j1)
    lo = a0 + (a1 - a0) * s
    hi = b0 + (b1 - b0) * s
    return lo + (hi - lo) * t


#: r below this reads as this inside a warp's logarithm (r^α's gradient in α is r^α·ln r:
#: finite there); r = 0 itself warps to 0.
WARP_R_MIN = 1e-12
#: Timonen et al. bound every warp exponent from below by 1/2 (α = 1/2 is Dupuy and Jacob's warp).
WARP_ALPHA_MIN = 0.5


def warp(r: torch.Tensor, alpha: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Timonen et al. Eq. 7, r' = Σ_k w_k r^{α_k}, per material: r (B,), alpha and weight (M, K) → (M, B)."""
    log_r = torch.log(r.clamp(min=WARP_R_MIN)).to(alpha.dtype)
    powers = torch.exp(alpha[:, None, :] * log_r[None, :, None])
    powers = torch.where((r > 0)[None, :, None], powers, torch.zeros_like(powers))  # 0^α = 0 exactly
    return (weight[:, None, :] * powers).sum(dim=-1)


def decode(weights: list[tuple[torch.Tensor, torch.Tensor]], x: torch.Tensor) -> torch.Tensor:
    """log f (M, B, 3) from features x (M, B, C): dense layers (M, in, out) + (M, 1, out), SiLU between."""
    h = x
    for k, (w, b) in enumerate(weights):
        h = torch.baddbmm(b, h, w)
        if k < len(weights) - 1:
            h = torch.nn.functional.silu(h)
    return h


def log_value(tensors: dict[str, torch.Tensor], r_h, r_d, phi) -> torch.Tensor:
    """log f (M, B, 3) of stacked tensors (every name with a leading M axis; biases (M, 1, out)).
    With warps, each texture is read at its warped radius; with a latent z_s, each texel's
    C × D_s matrix is multiplied by it (the gating)."""
    if "warp_h_alpha" in tensors:
        r_h = warp(r_h, tensors["warp_h_alpha"], tensors["warp_h_weight"])
        r_d = warp(r_d, tensors["warp_d_alpha"], tensors["warp_d_weight"])
    h, pole, rings = tensors["H"], tensors["D_pole"], tensors["D"]
    m = h.shape[0]
    fh = read_radial(h.reshape(m, h.shape[1], -1), r_h)
    fd = read_polar(pole.reshape(m, -1), rings.reshape(*rings.shape[:3], -1), r_d, phi)
    if "z_s" in tensors:
        z = tensors["z_s"]
        g = z.shape[1]
        fh = torch.einsum("mbcs,ms->mbc", fh.reshape(*fh.shape[:2], fh.shape[2] // g, g), z)
        fd = torch.einsum("mbcs,ms->mbc", fd.reshape(*fd.shape[:2], fd.shape[2] // g, g), z)
    layers = [(tensors[f"W{i}"], tensors[f"b{i}"]) for i in range(1, n_layers(tensors) + 1)]
    return decode(layers, torch.cat((fh, fd), dim=-1))


def to_value(g: torch.Tensor) -> torch.Tensor:
    """f = exp(g), the exponential last; clamped so fp32 stays finite."""
    return torch.exp(torch.clamp(g, max=MAX_LOG_VALUE))
