"""Random direction sets the harnesses evaluate on, cached because they are reused per material."""

from __future__ import annotations

import math
from functools import lru_cache

import torch


def uniform_hemisphere(n: int, generator: torch.Generator, dtype=torch.float64) -> torch.Tensor:
    """n directions uniform in solid angle over the upper hemisphere."""
    u = torch.rand(n, 2, generator=generator, dtype=torch.float64)
    z = u[:, 0]
    r = torch.sqrt(torch.clamp(1 - z * z, min=0.0))
    phi = 2 * math.pi * u[:, 1]
    return torch.stack((r * torch.cos(phi), r * torch.sin(phi), z), dim=-1).to(dtype)


@lru_cache(maxsize=4)
def random_pairs(n: int, seed: int, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """n (ωi, ωo) pairs, each uniform over the hemisphere, deterministic in `seed`."""
    g = torch.Generator().manual_seed(seed)
    return uniform_hemisphere(n, g, dtype), uniform_hemisphere(n, g, dtype)
