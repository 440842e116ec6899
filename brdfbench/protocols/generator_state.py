"""Reading a generator's saved state back: the checks every generator's `from_state` shares,
so that each refusal is one line naming the generator and the tensor or metadata key.

- `check_tensor`: a saved tensor's presence, shape, dtype and finiteness;
- the NBRDF layout of a generator that learns from weight vectors (hidden widths, input
  features, raw_units and the vector's width): `weight_layout` records it at a fit,
  `read_layout` reads it back from a file's metadata, checked, and `check_layout` refuses a
  weight set of another layout than the one a fitted or loaded generator holds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch

from ..errors import ConfigError, ModelFileError
from .generator import WeightSet
from ..nbrdf.layouts import check_hidden
from ..nbrdf.network import FEATURES, n_weights

#: The keys of a saved NBRDF layout.
LAYOUT_KEYS = ("hidden", "features", "raw_units", "width")


def check_tensor(owner: str, tensors: Mapping[str, torch.Tensor], name: str, shape: Sequence[int | None],
                 dtype: torch.dtype, *, nonnegative: bool = False) -> torch.Tensor:
    """tensors[name], checked for presence, shape (None: any extent), dtype and finiteness."""
    if name not in tensors:
        raise ModelFileError(f"{owner}: the model file lacks tensor {name!r}")
    t = tensors[name]
    if t.ndim != len(shape) or any(s is not None and t.shape[i] != s for i, s in enumerate(shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ModelFileError(f"{owner}: tensor {name!r} has shape {tuple(t.shape)}, expected {want}")
    if t.dtype != dtype:
        raise ModelFileError(f"{owner}: tensor {name!r} has dtype {t.dtype}, expected {dtype}")
    if not torch.isfinite(t).all():
        raise ModelFileError(f"{owner}: tensor {name!r} has non-finite values")
    if nonnegative and (t < 0).any():
        raise ModelFileError(f"{owner}: tensor {name!r} has negative values")
    return t


def weight_layout(ws: WeightSet) -> dict[str, Any]:
    """The NBRDF layout of a weight set, as JSON-able metadata."""
    return {"hidden": list(ws.hidden), "features": ws.features, "raw_units": bool(ws.raw_units),
            "width": int(ws.vectors.shape[1])}


def check_layout(owner: str, expected: Mapping[str, Any] | None, ws: WeightSet) -> None:
    """Refuse a weight set whose layout differs from the one a fitted or loaded model holds
    (None: the model holds none yet)."""
    if expected is None:
        return
    got = weight_layout(ws)
    if got != dict(expected):
        raise ConfigError(f"{owner}: this generator holds a model of {expected['width']}-value weight vectors "
                          f"(hidden {expected['hidden']}, {expected['features']}); the weight set has "
                          f"{got['width']} (hidden {got['hidden']}, {got['features']}): create a new generator")


def read_layout(owner: str, layout: Any, where: str = "metadata 'layout'") -> dict[str, Any]:
    """The NBRDF layout saved in a file's metadata (`where` names it in errors), checked:
    every key of LAYOUT_KEYS present, hidden widths positive integers, features a known
    encoding, raw_units a bool, and width the weight count of that network."""
    if not isinstance(layout, Mapping):
        raise ModelFileError(f"{owner}: {where} must hold {', '.join(LAYOUT_KEYS)}, got {layout!r}")
    missing = [k for k in LAYOUT_KEYS if k not in layout]
    if missing:
        raise ModelFileError(f"{owner}: {where} must hold {', '.join(LAYOUT_KEYS)}; it lacks {', '.join(missing)}")
    hidden = check_hidden(layout["hidden"], f"{owner}: {where}")
    features, raw_units, width = layout["features"], layout["raw_units"], layout["width"]
    if features not in FEATURES:
        raise ModelFileError(f"{owner}: {where} has features={features!r}, expected one of {list(FEATURES)}")
    if not isinstance(raw_units, bool):
        raise ModelFileError(f"{owner}: {where} has raw_units={raw_units!r}, expected true or false")
    if isinstance(width, bool) or not isinstance(width, int) or width != n_weights(hidden):
        raise ModelFileError(f"{owner}: {where} says width {width!r}, a network with hidden {list(hidden)} has "
                             f"{n_weights(hidden)} weights")
    return {"hidden": list(hidden), "features": features, "raw_units": raw_units, "width": width}
