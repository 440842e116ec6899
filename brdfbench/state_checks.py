"""Checks a plugin's `from_state` runs on the tensors of a model file before using them.

A model file is data from anywhere: a tensor may be missing, of another shape, NaN or
infinite, or out of its range (a negative albedo). `expect_tensor` refuses each with a
ModelFileError naming the tensor and what was expected; `modelio.load` adds the file's path.
The conformance kit's `load_refuses_broken_state` check holds every representation to it.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import torch

from .errors import ModelFileError


def expect_tensor(tensors: Mapping[str, torch.Tensor], name: str, shape: Sequence[int | None] | None = None, *,
                  owner: str = "model", nonneg: bool = False, required: bool = True) -> torch.Tensor | None:
    """`tensors[name]`, checked: floating point, finite, of `shape` (None: any size on that
    axis; shape None: any shape) and, with `nonneg`, no value below zero.

    A missing tensor raises KeyError where `required` (so `modelio.load` names every tensor
    the file lacks), else returns None."""
    if name not in tensors:
        if required:
            return tensors[name]  # a KeyError, recorded by the loader's mapping
        return None
    t = tensors[name]
    if not isinstance(t, torch.Tensor) or not t.dtype.is_floating_point:
        kind = t.dtype if isinstance(t, torch.Tensor) else type(t).__name__
        raise ModelFileError(f"{owner}: tensor {name!r} must hold floating-point values, got {kind}")
    if shape is not None:
        wanted = tuple(shape)
        if t.ndim != len(wanted) or any(w is not None and s != w for s, w in zip(t.shape, wanted)):
            text = "(" + ", ".join("any" if w is None else str(w) for w in wanted) + ("," if len(wanted) == 1 else "") + ")"
            raise ModelFileError(f"{owner}: tensor {name!r} has shape {tuple(t.shape)}, expected {text}")
    finite = torch.isfinite(t)
    if not finite.all():
        bad = int((~finite).sum())
        raise ModelFileError(f"{owner}: tensor {name!r} holds {bad} non-finite value(s) (NaN or infinite)")
    if nonneg and t.numel() and float(t.min()) < 0:
        raise ModelFileError(f"{owner}: tensor {name!r} holds a negative value ({float(t.min()):.6g}); "
                             "it must be at least 0")
    return t
