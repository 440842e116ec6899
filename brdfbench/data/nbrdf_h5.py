"""Reader and evaluator for the published NBRDF networks (Sztrajman et al. 2021).

The release stores each material as a Keras 2.2 `save_weights` HDF5 file with three
dense layers (6 → 21 → 21 → 3). Only those six float datasets are read; the companion
`.json` model config is never opened (its Lambda layer is marshalled Python bytecode,
which must not be unmarshalled or executed).

Network: x = [hx, hy, hz, dx, dy, dz] → relu(x W1 + b1) → relu(· W2 + b2) → · W3 + b3
→ exp(·) − 1, clamped at 0. The output is the RGB BRDF value in 1/sr (MERL units, the
MERL channel scales already applied), not cosine-weighted.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import h5py
import numpy as np
import torch

from .. import coords, merl
from ..errors import DataError

PUBLISHED_HIDDEN = (21, 21)


def layout(hidden=PUBLISHED_HIDDEN) -> dict[str, tuple[str, tuple[int, ...]]]:
    """weight name -> (HDF5 dataset key, expected shape) of a Keras 6 → hidden… → 3 network."""
    sizes = [6, *hidden, 3]
    out = {}
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
        out[f"W{i}"] = (f"dense_{i}/dense_{i}/kernel:0", (n_in, n_out))
        out[f"b{i}"] = (f"dense_{i}/dense_{i}/bias:0", (n_out,))
    return out


#: The published release's layout (6 → 21 → 21 → 3, 675 weights).
LAYOUT = layout()

#: The pre-exp value is clamped here so exp() stays finite even in fp32 (exp(80) ≈ 5.5e34
#: < fp32 max ≈ 3.4e38). Real materials never come near: a BRDF value of 1e6 is exp(13.8).
MAX_LOG_VALUE = 80.0

#: Rows per chunk when evaluating the whole MERL grid (bounds peak memory to ~100 MB).
_CHUNK = 1 << 18


def _fail(path, key: str | None, fault: str) -> DataError:
    where = f"{path}" if key is None else f"{path}: dataset {key!r}"
    return DataError(f"{where}: {fault}")


def _read_dataset(f: h5py.File, path: Path, key: str, shape: tuple[int, ...]) -> np.ndarray:
    # Refuse soft/external links anywhere along the key: data must live in this file.
    parts = key.split("/")
    for i in range(1, len(parts) + 1):
        sub = "/".join(parts[:i])
        link = f.get(sub, getlink=True)
        if link is None:
            raise _fail(path, key, f"missing (no {sub!r} in the file); not an NBRDF weights file")
        if not isinstance(link, h5py.HardLink):
            raise _fail(path, key, f"{sub!r} is a {type(link).__name__}, expected the data stored in the file itself")
    obj = f[key]
    if not isinstance(obj, h5py.Dataset):
        raise _fail(path, key, f"is a {type(obj).__name__}, expected a dataset")
    if obj.is_virtual or obj.external:
        raise _fail(path, key, "is a virtual or externally stored dataset; expected data stored in the file itself")
    if obj.dtype.kind != "f":
        raise _fail(path, key, f"has dtype {obj.dtype}, expected floating point")
    if tuple(obj.shape) != shape:
        raise _fail(path, key, f"wrong shape: expected {shape}, got {tuple(obj.shape)}")
    data = np.asarray(obj[()], dtype=np.float32)
    bad = ~np.isfinite(data)
    if bad.any():
        raise _fail(path, key, f"{int(bad.sum())} non-finite (NaN/Inf) weight(s)")
    return data


def read_nbrdf_h5(path: str | os.PathLike, hidden=PUBLISHED_HIDDEN) -> dict[str, np.ndarray]:
    """The weight arrays (float32) of an NBRDF `.h5` file: W1, b1, W2, b2, W3, b3 for the
    published 6 → 21 → 21 → 3 networks (other `hidden` sizes: one more pair per layer).

    Raises `DataError` naming the file (and dataset key) for an unreadable or non-HDF5
    file, a missing dataset, a wrong shape or dtype, or non-finite weights.
    """
    path = Path(path)
    if path.is_dir():
        raise _fail(path, None, "is a directory, not an NBRDF .h5 file")
    try:
        f = h5py.File(path, "r")
    except FileNotFoundError:
        raise _fail(path, None, "no such NBRDF .h5 file") from None
    except (OSError, ValueError) as exc:
        raise _fail(path, None, f"cannot open as HDF5 ({exc})") from None
    with f:
        weights = {}
        for name, (key, shape) in layout(hidden).items():
            try:
                weights[name] = _read_dataset(f, path, key, shape)
            except DataError:
                raise
            except (OSError, RuntimeError, ValueError, TypeError, KeyError) as exc:
                raise _fail(path, key, f"cannot read ({exc})") from None
    return weights


def nbrdf_input(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """Network input (N, 6) = [hx, hy, hz, dx, dy, dz] of direction pairs, in their dtype.

    h = (sin θh, 0, cos θh) (φh dropped: the networks are isotropic) and
    d = (sin θd cos φd, sin θd sin φd, cos θd) with φd in [0, 2π), angles from
    `coords.to_half_diff`.
    """
    hd = coords.to_half_diff(wi, wo)
    return nbrdf_input_from_angles(hd.theta_h, hd.theta_d, hd.phi_d)


def nbrdf_input_from_angles(theta_h: torch.Tensor, theta_d: torch.Tensor, phi_d: torch.Tensor) -> torch.Tensor:
    """The same input (N, 6) from Rusinkiewicz angles."""
    st_h, st_d = torch.sin(theta_h), torch.sin(theta_d)
    return torch.stack(
        (st_h, torch.zeros_like(st_h), torch.cos(theta_h), st_d * torch.cos(phi_d), st_d * torch.sin(phi_d), torch.cos(theta_d)),
        dim=-1,
    )


def nbrdf_forward(weights: dict[str, np.ndarray | torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """RGB BRDF values (N, 3) in 1/sr for inputs x (N, 6), computed in x's dtype.

    relu(x W1 + b1) → relu(· W2 + b2) → z = · W3 + b3 → expm1(min(z, MAX_LOG_VALUE)),
    clamped at 0. The clamp before the exponential keeps the output finite (see
    MAX_LOG_VALUE); expm1 is exp(z) − 1 without cancellation near z = 0.
    """
    if x.ndim != 2 or x.shape[-1] != 6 or not x.dtype.is_floating_point:
        raise ValueError(f"NBRDF input must be a floating (N, 6) tensor, got {tuple(x.shape)} {x.dtype}")
    w = {k: torch.as_tensor(weights[k]).to(device=x.device, dtype=x.dtype) for k in LAYOUT}
    h = torch.relu(x @ w["W1"] + w["b1"])
    h = torch.relu(h @ w["W2"] + w["b2"])
    z = torch.clamp(h @ w["W3"] + w["b3"], max=MAX_LOG_VALUE)
    return torch.clamp(torch.expm1(z), min=0.0)


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
    x = nbrdf_input(wi[idx], wo[idx]).to(torch.float32)
    return x, idx, above.numpy().reshape(merl.SHAPE)


def nbrdf_table(weights: dict[str, np.ndarray | torch.Tensor]) -> merl.MerlTable:
    """The network evaluated at the 90×90×180 MERL cell centres, as a MERL table.

    Inputs are built in float64 from `merl.grid_directions()` (via `coords.to_half_diff`),
    then rounded to float32; the network runs in float32, the precision it was trained
    and published in (float64 is ~4x slower and differs by fp32 rounding only). Cells
    whose centre directions are at or below the horizon are marked invalid (and the
    network is not evaluated there).
    """
    x, idx, valid = _grid_input()
    out = torch.zeros(merl.N_CELLS, 3, dtype=torch.float32)
    with torch.no_grad():
        for start in range(0, x.shape[0], _CHUNK):
            sl = slice(start, start + _CHUNK)
            out[idx[sl]] = nbrdf_forward(weights, x[sl])
    values = out.T.reshape(3, *merl.SHAPE).numpy()
    return merl.MerlTable.from_values(values, valid)
