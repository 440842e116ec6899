"""The log-relative, cosine-weighted mapping of MERL values that PCA over BRDFs works in.

After Nielsen, Jensen and Ramamoorthi (2015): over the cells with both directions above
the horizon (`domain`), a value ρ maps to x = ln((ρ·w + ε) / (ρ_ref·w + ε)) with
w = cosθi·cosθo and ε = 1e-3, relative to a reference BRDF ρ_ref (a median over a
training set). Raw values are dominated by the specular peak; in this space the peak and
the diffuse floor weigh alike. Shared by the `pca` representation, the PCA generators and
the AugMERL dataset's interpolation.
"""

from __future__ import annotations

from functools import lru_cache

import torch

from . import merl

EPSILON = 1e-3


@lru_cache(maxsize=1)
def domain() -> tuple[torch.Tensor, torch.Tensor]:
    """Flat indices of the MERL cells with both directions above the horizon, and their
    w = cosθi·cosθo (fp64)."""
    wi, wo = merl.grid_directions()
    cells = torch.nonzero(merl.grid_above_horizon()).squeeze(1)
    return cells, (wi[cells, 2] * wo[cells, 2])


def to_mapped(values: torch.Tensor, reference: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """x = ln((ρ·w + ε) / (ρ_ref·w + ε)), elementwise (broadcast)."""
    return torch.log((values * w + EPSILON) / (reference * w + EPSILON))


def from_mapped(mapped: torch.Tensor, reference: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """The inverse of `to_mapped`, clamped at 0 (a reconstruction may undershoot ρ = 0)."""
    return (((reference * w + EPSILON) * torch.exp(mapped) - EPSILON) / w).clamp_min(0.0)


def top_eigen(gram: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The k largest eigenvalues of a symmetric (Gram) matrix, descending, and their eigenvectors (columns)."""
    eigvals, eigvecs = torch.linalg.eigh(gram)
    order = torch.argsort(eigvals, descending=True)[:k]
    return eigvals[order], eigvecs[:, order]
