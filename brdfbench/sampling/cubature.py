"""Expected counts of Mitsuba's SphericalDomain cells, integrated adaptively from a pdf.

`mitsuba.chi2.ChiSquareTest.tabulate_pdf` integrates each cell of its (φ, −cos θ) grid
with a fixed ires × ires trapezoid rule. That is not enough where the density is not
smooth at the scale of a cell: at grazing ωi a reflection sampler's pdf has a
1/|ωi + ωo| peak on the horizon, and GGX α = 1 at θi = 89.9° is rejected with ires = 4, 8
and 16 (accepted from 32). `tabulate_expected` keeps ChiSquareTest's rule, cells and
integration points, and refines a cell into quarters, recursively, where its estimate
and the sum over its quarters disagree by more than a small fraction of the cell's
Poisson noise.
"""

from __future__ import annotations

import math
from typing import Callable

import torch

Tensor = torch.Tensor

#: SphericalDomain's parameter rectangle: x = φ ∈ [−π, π], y = −cos θ ∈ [−1, 1].
DOMAIN_LO = (-math.pi, -1.0)
DOMAIN_EXTENT = (2.0 * math.pi, 2.0)


def domain_shape(res: int) -> tuple[int, int]:
    """(cells along φ, cells along −cos θ), as ChiSquareTest sizes SphericalDomain (aspect 2)."""
    return max(int(res / 2), 1), res


def _trapezoid(pdf_fn: Callable, rects: Tensor, ires: int) -> Tensor:
    """Probability mass of each rectangle (M, 4) = (x0, y0, wx, wy) of the parameter domain:
    ChiSquareTest's rule, ires × ires trapezoid points nudged 1e-4 inside."""
    s = torch.arange(ires, dtype=torch.float64)
    frac = (s + 1e-4) * (1 - 2e-4) / (ires - 1)
    w1 = torch.where((s == 0) | (s == ires - 1), 0.5, 1.0) / (ires - 1)
    weights = (w1[:, None] * w1[None, :]).reshape(-1)  # (ires², ), y-major
    out = torch.empty(rects.shape[0], dtype=torch.float64)
    chunk = max(1, 2_000_000 // (ires * ires))
    for a in range(0, rects.shape[0], chunk):
        r = rects[a : a + chunk]
        x = r[:, 0:1] + frac[None, :] * r[:, 2:3]  # (m, ires)
        y = r[:, 1:2] + frac[None, :] * r[:, 3:4]
        phi = x[:, None, :].expand(-1, ires, ires)
        cos_t = -y[:, :, None].expand(-1, ires, ires)
        sin_t = torch.sqrt((1.0 - cos_t * cos_t).clamp(min=0.0))
        points = torch.stack((torch.cos(phi) * sin_t, torch.sin(phi) * sin_t, cos_t), dim=-1).reshape(-1, 3)
        values = pdf_fn(points).reshape(r.shape[0], ires * ires)
        out[a : a + chunk] = (values * weights).sum(-1) * (r[:, 2] * r[:, 3])
    return out


def _split(rects: Tensor) -> Tensor:
    """Each rectangle (M, 4) as its four quarters (4M, 4), quarters of one rectangle adjacent."""
    x0, y0, wx, wy = rects.unbind(-1)
    hx, hy = 0.5 * wx, 0.5 * wy
    quads = [torch.stack((x0 + i * hx, y0 + j * hy, hx, hy), dim=-1) for j in (0, 1) for i in (0, 1)]
    return torch.stack(quads, dim=1).reshape(-1, 4)


def tabulate_expected(
    pdf_fn: Callable, res: int, sample_count: int, *, ires: int = 4, tolerance: float = 0.05, max_depth: int = 8
) -> tuple[Tensor, int]:
    """Expected count of every SphericalDomain cell (index x + y·nx), and the pdf evaluations spent.

    Adaptive: a cell's (or part's) estimate by ChiSquareTest's own rule is compared with
    the sum over its quarters; where they differ by more than tolerance·√E·2^−depth
    (E: the cell's expected count, so a cell's total error stays ≲ tolerance·√E, a small
    fraction of its Poisson noise), the quarters are refined in turn, down to max_depth
    halvings (max_depth = −1: ChiSquareTest's fixed rule). `pdf_fn` maps unit vectors
    (M, 3) to densities (M,), float64.
    """
    nx, ny = domain_shape(res)
    wx, wy = DOMAIN_EXTENT[0] / nx, DOMAIN_EXTENT[1] / ny
    gx, gy = torch.meshgrid(torch.arange(nx, dtype=torch.float64), torch.arange(ny, dtype=torch.float64), indexing="xy")
    x0, y0 = DOMAIN_LO[0] + gx.reshape(-1) * wx, DOMAIN_LO[1] + gy.reshape(-1) * wy
    rects = torch.stack((x0, y0, torch.full_like(x0, wx), torch.full_like(y0, wy)), dim=-1)
    owner = torch.arange(nx * ny)
    coarse = _trapezoid(pdf_fn, rects, ires)
    evals = rects.shape[0] * ires * ires
    if max_depth < 0:  # ChiSquareTest's fixed rule, no refinement
        return coarse * sample_count, evals
    cell_count = coarse * sample_count
    total = torch.zeros(nx * ny, dtype=torch.float64)
    for depth in range(max_depth + 1):
        kids = _split(rects)
        fine = _trapezoid(pdf_fn, kids, ires).reshape(-1, 4)
        evals += kids.shape[0] * ires * ires
        fine_sum = fine.sum(-1)
        expected = torch.maximum(cell_count[owner], fine_sum * sample_count).clamp(min=1.0)
        err = (fine_sum - coarse).abs() * sample_count
        done = err <= tolerance * torch.sqrt(expected) * 2.0**-depth
        if depth == max_depth:
            done[:] = True
        total.index_add_(0, owner[done], fine_sum[done])
        more = ~done
        if not more.any():
            break
        rects = kids.reshape(-1, 4, 4)[more].reshape(-1, 4)
        owner = owner[more].repeat_interleave(4)
        coarse = fine[more].reshape(-1)
    return total * sample_count, evals
