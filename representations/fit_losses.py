"""The objectives an analytic fit can minimise: the benchmark's own, and the metrics the
literature's published fits were made with, so that a model refitted with its authors'
metric can be compared with their published parameters.

- `l1_log_cos` (default): |log(1 + f̂ cosθi) − log(1 + f cosθi)| averaged over RGB and over
  MERL cells drawn uniformly from the valid ones: the benchmark's accuracy metric.
- `ngan_l2`: the squared difference of cosine-weighted values, ((f̂ − f) cosθi)², over
  direction pairs uniform in solid angle on both hemispheres (Ngan, Durand and Matusik,
  "Experimental Analysis of BRDF Models", EGSR 2005; the weighting as BBM implements it,
  sinθi sinθo over a spherical grid).
- `low_e1`: the same squared difference with ωi uniform in solid angle and θo uniform in
  angle at φo = 0, an isotropic BRDF's plane of incidence sampled in angle (Löw, Kronander,
  Ynnerman and Unger, "BRDF Models for Accurate and Efficient Rendering of Glossy Surfaces",
  ACM TOG 2012, metric E1; weighting as in BBM's implementation).
- `low_e2`: Löw et al.'s metric E2 under the same sampling: (log(1 + f̂ cosθi) −
  log(1 + f cosθi))².

Target values at sampled directions are read from the MERL table by its reference reader's
nearest cell; pairs landing on invalid cells are dropped. Bagher et al.'s fitting metric
is not offered: its definition is not available here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from brdfbench import merl
from brdfbench.coords import spherical_to_vector

DEFAULT_LOSS = "l1_log_cos"


@dataclass(frozen=True)
class FitLoss:
    """How pairs are drawn ("cells", "solid_angle", "incidence_plane"), what is compared
    (log1p(f cosθi) or f cosθi) and with which power (1: L1, smoothed for the optimiser; 2)."""

    name: str
    sampling: str
    log: bool
    power: int


LOSSES = {
    "l1_log_cos": FitLoss("l1_log_cos", "cells", log=True, power=1),
    "ngan_l2": FitLoss("ngan_l2", "solid_angle", log=False, power=2),
    "low_e1": FitLoss("low_e1", "incidence_plane", log=False, power=2),
    "low_e2": FitLoss("low_e2", "incidence_plane", log=True, power=2),
}
FIT_LOSSES = tuple(LOSSES)


def _hemisphere(n: int, g: torch.Generator) -> torch.Tensor:
    """Directions uniform in solid angle on the upper hemisphere (cosθ uniform in (0, 1])."""
    cos_t = 1.0 - torch.rand(n, generator=g, dtype=torch.float64)
    return spherical_to_vector(torch.acos(cos_t), 2.0 * math.pi * torch.rand(n, generator=g, dtype=torch.float64))


def sample_pairs(loss: FitLoss, n: int, seed: int, usable: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """(ωi, ωo, flat MERL cell index) of `n` pairs drawn (seeded) as `loss` samples them,
    keeping only pairs whose nearest cell is usable; fewer than `n` only where few are."""
    g = torch.Generator().manual_seed(seed)
    kept_i, kept_o, kept_c, have = [], [], [], 0
    for _ in range(16):
        m = 2 * n
        wi = _hemisphere(m, g)
        if loss.sampling == "solid_angle":
            wo = _hemisphere(m, g)
        else:  # θo uniform in [0, π/2) at φo = 0
            theta_o = 0.5 * math.pi * torch.rand(m, generator=g, dtype=torch.float64)
            wo = spherical_to_vector(theta_o, torch.zeros(m, dtype=torch.float64))
        keep = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        wi, wo = wi[keep], wo[keep]
        flat = merl.flat_index(*merl.cell_indices(wi, wo)).numpy()
        ok = usable[flat]
        kept_i.append(wi[torch.from_numpy(ok)])
        kept_o.append(wo[torch.from_numpy(ok)])
        kept_c.append(flat[ok])
        have += int(ok.sum())
        if have >= n:
            break
    wi, wo, cells = torch.cat(kept_i)[:n], torch.cat(kept_o)[:n], np.concatenate(kept_c)[:n]
    return wi, wo, cells


def compared(loss: FitLoss, f: torch.Tensor, cos_i: torch.Tensor) -> torch.Tensor:
    """What the loss compares: log1p(f cosθi) or f cosθi."""
    return torch.log1p(f * cos_i) if loss.log else f * cos_i
