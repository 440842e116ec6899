"""Reader of the published NBRDF weight files: Keras 2.2 `save_weights` HDF5.

The release (Sztrajman et al. 2021) stores each material as dense layers `dense_1` …
`dense_L`, their kernels (in, out) and biases at `dense_i/dense_i/kernel:0` and `bias:0`.
Only those float datasets are read; the companion `.json` model config is never opened
(its Lambda layer is marshalled Python bytecode, which must not be unmarshalled or run).
Anything else stored in the file (a dataset or a link, such as an extra layer's weights)
is refused rather than ignored: the network read would not be the one the file holds.
Groups without data (the release's weightless `lambda_1` layer) are allowed.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from ..errors import DataError
from .network import PUBLISHED_HIDDEN, layer_sizes


def layout(hidden=PUBLISHED_HIDDEN) -> dict[str, tuple[str, tuple[int, ...]]]:
    """weight name -> (HDF5 dataset key, expected shape) of a Keras 6 → hidden… → 3 network."""
    sizes = layer_sizes(hidden)
    out = {}
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
        out[f"W{i}"] = (f"dense_{i}/dense_{i}/kernel:0", (n_in, n_out))
        out[f"b{i}"] = (f"dense_{i}/dense_{i}/bias:0", (n_out,))
    return out


#: The published release's layout (6 → 21 → 21 → 3, 675 weights).
LAYOUT = layout()


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


def _unexpected_entry(group: h5py.Group, expected: set[str], prefix: str = "") -> str | None:
    """The first dataset or link under `group` that is not one of the `expected` keys (or
    a group on the way to one), or None. Links are not followed."""
    for name in sorted(group):
        key = f"{prefix}{name}"
        link = group.get(name, getlink=True)
        if key in expected:
            continue
        if isinstance(link, h5py.HardLink) and isinstance(group[name], h5py.Group):
            found = _unexpected_entry(group[name], expected, key + "/")
            if found is not None:
                return found
        else:
            return key
    return None


def _refuse_extras(f: h5py.File, path: Path, hidden) -> None:
    expected = {key for key, _ in layout(hidden).values()}
    key = _unexpected_entry(f, expected)
    if key is None:
        return
    layer = key.split("/")[0]
    shape = "-".join(map(str, layer_sizes(hidden)))
    if layer.startswith("dense_") and not any(k.startswith(layer + "/") for k in expected):
        why = (f"layer {layer!r} is beyond the {len(hidden) + 1} dense layers of a {shape} network "
               "(a deeper network needs its hidden widths given)")
    else:
        why = f"not one of the weights of a {shape} network"
    raise DataError(f"{path}: unexpected entry {key!r}: {why}; refusing to ignore it")


def read_nbrdf_h5(path: str | os.PathLike, hidden=PUBLISHED_HIDDEN) -> dict[str, np.ndarray]:
    """The weight arrays (float32) of an NBRDF `.h5` file: W1, b1, W2, b2, W3, b3 for the
    published 6 → 21 → 21 → 3 networks (other `hidden` sizes: one more pair per layer).

    Raises `DataError` naming the file (and dataset key) for an unreadable or non-HDF5
    file, a missing dataset, a wrong shape or dtype, non-finite weights, or a dataset the
    layout does not have (such as an extra layer).
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
        keys = layout(hidden)
        for name, (key, shape) in keys.items():
            try:
                weights[name] = _read_dataset(f, path, key, shape)
            except DataError:
                raise
            except (OSError, RuntimeError, ValueError, TypeError, KeyError) as exc:
                raise _fail(path, key, f"cannot read ({exc})") from None
        try:
            _refuse_extras(f, path, hidden)
        except DataError:
            raise
        except (OSError, RuntimeError, ValueError, TypeError, KeyError) as exc:
            raise _fail(path, None, f"cannot list its contents ({exc})") from None
    return weights
