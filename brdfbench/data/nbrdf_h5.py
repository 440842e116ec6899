"""A published NBRDF network (Sztrajman et al. 2021) as a MERL table, for the dataset.

The release's files are read by `brdfbench.nbrdf.keras_h5`; the network (6 → 21 → 21 → 3
on the Rusinkiewicz encoding, output in 1/sr, not cosine-weighted) is
`brdfbench.nbrdf.network`'s. This module evaluates it on the MERL grid.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch

from .. import merl
from ..nbrdf.network import forward, rusinkiewicz_input

#: Rows per chunk when evaluating the whole MERL grid (bounds peak memory to ~100 MB).
_CHUNK = 1 << 18


@lru_cache(maxsize=1)
def _grid_input() -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """Network inputs (M, 6) float32 at the M above-horizon MERL cell centres, their flat
    cell indices (M,), and the (90, 90, 180) above-horizon mask.

    Built once in float64 from `merl.grid_directions()` and cached (~30 MB): it is the
    same for every material.
    """
    wi, wo = merl.grid_directions(torch.float64)
    above = merl.grid_above_horizon()
    idx = torch.nonzero(above).squeeze(1)
    x = rusinkiewicz_input(wi[idx], wo[idx]).to(torch.float32)
    return x, idx, above.numpy().reshape(merl.SHAPE)


def grid_outputs(weights: dict[str, np.ndarray | torch.Tensor]) -> np.ndarray:
    """The network's float32 outputs (1/sr) at the above-horizon MERL cell centres, (M, 3),
    in the order of `grid_cells()`.

    Inputs are built in float64 from `merl.grid_directions()` (via `coords.to_half_diff`),
    then rounded to float32; the network runs in float32, the precision it was trained
    and published in (float64 would differ by fp32 rounding only).
    """
    x, _, _ = _grid_input()
    weights = {k: torch.as_tensor(v) for k, v in weights.items()}
    out = torch.empty(x.shape[0], 3, dtype=torch.float32)
    with torch.no_grad():
        for start in range(0, x.shape[0], _CHUNK):
            sl = slice(start, start + _CHUNK)
            out[sl] = forward(weights, x[sl])
    return out.numpy()


def grid_cells() -> int:
    """How many MERL cells have both centre directions above the horizon (rows of `grid_outputs`)."""
    return int(_grid_input()[1].shape[0])


def table_from_outputs(outputs: np.ndarray) -> merl.MerlTable:
    """The MERL table of `grid_outputs`: cells at or below the horizon are invalid."""
    _, idx, valid = _grid_input()
    values = np.zeros((3, merl.N_CELLS), dtype=np.float32)
    values[:, idx.numpy()] = np.asarray(outputs).T
    return merl.MerlTable.from_values(values.reshape(3, *merl.SHAPE), valid)


def nbrdf_table(weights: dict[str, np.ndarray | torch.Tensor]) -> merl.MerlTable:
    """The network (output in 1/sr) evaluated at the 90×90×180 MERL cell centres, as a MERL
    table (see `grid_outputs`). Cells whose centre directions are at or below the horizon
    are marked invalid (and the network is not evaluated there)."""
    return table_from_outputs(grid_outputs(weights))
