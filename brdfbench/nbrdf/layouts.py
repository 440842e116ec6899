"""Weight layouts of other code, to and from the Keras layout of `network`.

- the flattened vector of hyperdiffusion work (675 values for 6-21-21-3): fc1.weight,
  fc1.bias, fc2.weight, … with torch nn.Linear (out, in) shapes, row-major;
- a torch state dict {fc1.weight, fc1.bias, …} (an nn.Linear stack, maybe under a prefix).

Every reader checks shapes, dtypes and finiteness, and raises `ModelFileError` naming
`where` (the file) and the offending key.
"""

from __future__ import annotations

import numbers
import re
from typing import Mapping, Sequence

import numpy as np
import torch

from ..errors import ModelFileError
from . import network
from .network import PUBLISHED_HIDDEN


def check_finite(weights: Mapping[str, torch.Tensor], where: str) -> None:
    """ModelFileError naming `where` and the weight if any weight holds NaN or Inf."""
    for name, t in weights.items():
        bad = int((~torch.isfinite(torch.as_tensor(t))).sum())
        if bad:
            raise ModelFileError(f"{where}: weight {name!r} holds {bad} non-finite (NaN/Inf) value(s)")


def check_hidden(hidden, where: str = "hidden") -> tuple[int, ...]:
    """Hidden layer widths as a tuple of positive ints, or a ModelFileError naming them."""
    try:
        widths = tuple(hidden)
    except TypeError:
        widths = ()
    if not widths or not all(isinstance(h, numbers.Integral) and not isinstance(h, bool) and h >= 1 for h in widths):
        raise ModelFileError(f"{where}: hidden sizes {hidden!r} must be a non-empty list of positive integers")
    return tuple(int(h) for h in widths)


# -- the flattened vector ------------------------------------------------------------------
def flatten(weights: Mapping[str, torch.Tensor]) -> np.ndarray:
    """The float32 vector fc1.weight (out, in), fc1.bias, fc2.weight, … (row-major)."""
    parts = []
    for i in range(1, network.n_layers(weights) + 1):
        parts += [weights[f"W{i}"].detach().T.reshape(-1), weights[f"b{i}"].detach().reshape(-1)]
    return torch.cat(parts).to(torch.float32).numpy()


def unflatten(vector, hidden: Sequence[int] = PUBLISHED_HIDDEN, *, where: str = "vector") -> dict[str, torch.Tensor]:
    """Keras-layout weights from a flattened vector of a 6 → hidden… → 3 network."""
    hidden = check_hidden(hidden, where)
    if isinstance(vector, torch.Tensor):
        v = vector.detach()
    else:
        array = np.asarray(vector)
        if array.dtype.kind != "f":
            raise ModelFileError(f"{where}: weight vector has dtype {array.dtype}, expected floating point")
        v = torch.from_numpy(array.astype(array.dtype.newbyteorder("="), copy=False))  # any byte order
    if v.ndim != 1:
        raise ModelFileError(f"{where}: expected a 1-D weight vector, got shape {tuple(v.shape)}")
    if not v.dtype.is_floating_point:
        raise ModelFileError(f"{where}: weight vector has dtype {v.dtype}, expected floating point")
    expected = network.n_weights(hidden)
    if v.numel() != expected:
        raise ModelFileError(f"{where}: weight vector has {v.numel()} values, expected {expected} "
                             f"for a 6-{'-'.join(map(str, hidden))}-3 network (fc1.weight, fc1.bias, … row-major)")
    v = v.to(torch.float32)
    out, at = {}, 0
    for name, shape in network.weight_shapes(hidden).items():
        n = int(np.prod(shape))
        chunk = v[at:at + n]
        out[name] = chunk.reshape(shape[::-1]).T.contiguous() if name.startswith("W") else chunk.clone()
        at += n
    check_finite(out, where)
    return out


# -- torch state dicts ----------------------------------------------------------------------
def to_torch_state(weights: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """{fc1.weight (out, in), fc1.bias, …}: the layout of an nn.Linear stack."""
    state = {}
    for i in range(1, network.n_layers(weights) + 1):
        state[f"fc{i}.weight"] = weights[f"W{i}"].detach().T.contiguous()
        state[f"fc{i}.bias"] = weights[f"b{i}"].detach().clone()
    return state


_FC_KEY = re.compile(r"^(?P<prefix>.*?)fc(?P<i>\d+)\.(?P<kind>weight|bias)$")


def from_torch_state(state: Mapping[str, torch.Tensor], *, where: str = "state_dict") -> dict[str, torch.Tensor]:
    """Keras-layout weights from {fc1.weight, fc1.bias, …} (a common prefix such as `net.`
    is allowed); the hidden sizes come from the shapes, which must chain 6 → … → 3."""
    found: dict[int, dict[str, torch.Tensor]] = {}
    prefixes = set()
    for key, value in state.items():
        match = _FC_KEY.match(str(key))
        if match is None:
            continue
        if not isinstance(value, torch.Tensor):
            raise ModelFileError(f"{where}: {key!r} is a {type(value).__name__}, expected a tensor")
        bad = int((~torch.isfinite(value)).sum()) if value.dtype.is_floating_point else 0
        if bad:
            raise ModelFileError(f"{where}: {key!r} holds {bad} non-finite (NaN/Inf) value(s)")
        prefixes.add(match["prefix"])
        found.setdefault(int(match["i"]), {})[match["kind"]] = value
    if len(prefixes) > 1:
        raise ModelFileError(f"{where}: fc layers under several prefixes ({', '.join(sorted(map(repr, prefixes)))}); "
                             "save the state_dict of one network")
    if not found:
        keys = ", ".join(map(repr, list(state)[:6])) or "none"
        raise ModelFileError(f"{where}: no fc1.weight/fc1.bias… keys (found {keys})")
    n_layers = max(found)
    weights, width = {}, network.N_INPUTS
    for i in range(1, n_layers + 1):
        for kind in ("weight", "bias"):
            if kind not in found.get(i, {}):
                raise ModelFileError(f"{where}: missing fc{i}.{kind}")
        w, b = found[i]["weight"], found[i]["bias"]
        n_out = network.N_OUTPUTS if i == n_layers else (w.shape[0] if w.ndim == 2 else -1)
        if w.ndim != 2 or tuple(w.shape) != (n_out, width):
            raise ModelFileError(f"{where}: fc{i}.weight has shape {tuple(w.shape)}, expected ({n_out if n_out > 0 else 'width'}, {width})")
        if tuple(b.shape) != (n_out,):
            raise ModelFileError(f"{where}: fc{i}.bias has shape {tuple(b.shape)}, expected ({n_out},)")
        if not (w.dtype.is_floating_point and b.dtype.is_floating_point):
            raise ModelFileError(f"{where}: fc{i} holds {w.dtype}/{b.dtype}, expected floating point")
        weights[f"W{i}"] = w.to(torch.float32).T.contiguous()
        weights[f"b{i}"] = b.to(torch.float32).clone()
        width = n_out
    check_finite(weights, where)
    return weights
