"""NBRDF weights in the formats people already have, to and from brdfbench models.

| suffix | format | read | write |
| --- | --- | --- | --- |
| `.h5`, `.hdf5` | Keras `save_weights` (the published release), kernels (in, out) | yes | no |
| `.npy` | the flattened vector of hyperdiffusion work (675 for 6-21-21-3): fc1.weight, fc1.bias, fc2.weight, … with torch (out, in) shapes, row-major | yes | yes |
| `.pt`, `.pth` | a torch state_dict {fc1.weight, fc1.bias, …} (or that flat vector as one tensor), loaded with weights_only=True | yes | yes |
| `.safetensors` | a brdfbench model file (`nbrdf` or `naive_mlp`; modelio) | yes | yes |

Nothing here runs code from a file: HDF5 datasets are read as arrays (the release's JSON
with its marshalled Lambda is never opened), `.npy` with allow_pickle=False, torch files
with weights_only=True, safetensors by its header. Vectors and state dicts carry no
units: `raw_units=True` says the network outputs raw (unscaled) MERL values, which the
model multiplies by the MERL channel scales; the release's networks output 1/sr.
"""

from __future__ import annotations

import numbers
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from brdfbench import merl, modelio
from brdfbench.data.nbrdf_h5 import read_nbrdf_h5
from brdfbench.errors import DataError, ModelFileError

from . import mlp

H5_SUFFIXES = (".h5", ".hdf5")
VECTOR_SUFFIXES = (".npy",)
TORCH_SUFFIXES = (".pt", ".pth")
MODEL_SUFFIXES = (".safetensors",)
READABLE = H5_SUFFIXES + VECTOR_SUFFIXES + TORCH_SUFFIXES + MODEL_SUFFIXES
WRITABLE = VECTOR_SUFFIXES + TORCH_SUFFIXES + MODEL_SUFFIXES
DEFAULT_HIDDEN = (21, 21)
_RAW_SCALES = torch.tensor(merl.CHANNEL_SCALES, dtype=torch.float32)


@dataclass(frozen=True)
class Network:
    """Weights in the Keras layout (W1 (in, out), b1, …), their input encoding and units."""

    weights: dict[str, torch.Tensor]
    features: str = "rusinkiewicz"
    raw_units: bool = False

    @property
    def hidden(self) -> list[int]:
        return mlp.hidden_of(self.weights)


def _check_finite(weights: Mapping[str, torch.Tensor], where: str) -> None:
    for name, t in weights.items():
        bad = int((~torch.isfinite(t)).sum())
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


def check_features(features: str) -> str:
    if features not in mlp.FEATURES:
        raise ModelFileError(f"unknown input encoding features={features!r}; expected one of {', '.join(mlp.FEATURES)}")
    return features


# -- the flattened vector ------------------------------------------------------------------
def flatten(weights: Mapping[str, torch.Tensor]) -> np.ndarray:
    """The float32 vector fc1.weight (out, in), fc1.bias, fc2.weight, … (row-major)."""
    n_layers = sum(1 for k in weights if k.startswith("W"))
    parts = []
    for i in range(1, n_layers + 1):
        parts += [weights[f"W{i}"].detach().T.reshape(-1), weights[f"b{i}"].detach().reshape(-1)]
    return torch.cat(parts).to(torch.float32).numpy()


def unflatten(vector, hidden: Sequence[int] = DEFAULT_HIDDEN, *, where: str = "vector") -> dict[str, torch.Tensor]:
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
    expected = mlp.n_weights(hidden)
    if v.numel() != expected:
        raise ModelFileError(f"{where}: weight vector has {v.numel()} values, expected {expected} "
                             f"for a 6-{'-'.join(map(str, hidden))}-3 network (fc1.weight, fc1.bias, … row-major)")
    v = v.to(torch.float32)
    out, at = {}, 0
    for name, shape in mlp.weight_shapes(hidden).items():
        n = int(np.prod(shape))
        chunk = v[at:at + n]
        out[name] = chunk.reshape(shape[::-1]).T.contiguous() if name.startswith("W") else chunk.clone()
        at += n
    _check_finite(out, where)
    return out


# -- torch state dicts ----------------------------------------------------------------------
def to_torch_state(weights: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """{fc1.weight (out, in), fc1.bias, …}: the layout of an nn.Linear stack."""
    n_layers = sum(1 for k in weights if k.startswith("W"))
    state = {}
    for i in range(1, n_layers + 1):
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
    weights, width = {}, mlp.N_INPUTS
    for i in range(1, n_layers + 1):
        for kind in ("weight", "bias"):
            if kind not in found.get(i, {}):
                raise ModelFileError(f"{where}: missing fc{i}.{kind}")
        w, b = found[i]["weight"], found[i]["bias"]
        n_out = mlp.N_OUTPUTS if i == n_layers else (w.shape[0] if w.ndim == 2 else -1)
        if w.ndim != 2 or tuple(w.shape) != (n_out, width):
            raise ModelFileError(f"{where}: fc{i}.weight has shape {tuple(w.shape)}, expected ({n_out if n_out > 0 else 'width'}, {width})")
        if tuple(b.shape) != (n_out,):
            raise ModelFileError(f"{where}: fc{i}.bias has shape {tuple(b.shape)}, expected ({n_out},)")
        if not (w.dtype.is_floating_point and b.dtype.is_floating_point):
            raise ModelFileError(f"{where}: fc{i} holds {w.dtype}/{b.dtype}, expected floating point")
        weights[f"W{i}"] = w.to(torch.float32).T.contiguous()
        weights[f"b{i}"] = b.to(torch.float32).clone()
        width = n_out
    _check_finite(weights, where)
    return weights


# -- files -----------------------------------------------------------------------------------
def _suffix(path: Path, allowed: tuple[str, ...], verb: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise ModelFileError(f"{path}: cannot {verb} {suffix or 'a suffix-less file'}; expected one of {', '.join(allowed)}")
    return suffix


def read_network(path: str | os.PathLike, *, hidden: Sequence[int] = DEFAULT_HIDDEN, raw_units: bool = False,
                 features: str = "rusinkiewicz") -> Network:
    """Read network weights from any format in the table above.

    `hidden` gives the layer widths of a flat `.npy` vector and of an `.h5` file (state
    dicts and brdfbench models carry their own); `raw_units` and `features` describe files
    that do not record them (all but brdfbench models).
    """
    path = Path(path)
    suffix = _suffix(path, READABLE, "read network weights from")
    if not path.is_file():
        raise ModelFileError(f"{path}: no such network file")
    if suffix in MODEL_SUFFIXES:
        return _read_model(path)
    check_features(features)
    hidden = check_hidden(hidden, str(path))
    if suffix in H5_SUFFIXES:
        try:
            arrays = read_nbrdf_h5(path, hidden=hidden)
        except DataError as exc:  # one error type for every weight format
            raise ModelFileError(str(exc)) from None
        weights = {k: torch.from_numpy(v) for k, v in arrays.items()}
    elif suffix in VECTOR_SUFFIXES:
        weights = unflatten(_load_npy(path), hidden, where=str(path))
    else:
        state = modelio.load_torch_weights(path)  # weights_only=True: refuses anything needing pickle
        if isinstance(state, torch.Tensor):
            weights = unflatten(state, hidden, where=str(path))
        elif isinstance(state, Mapping):
            weights = from_torch_state(state, where=str(path))
        else:
            raise ModelFileError(f"{path}: holds a {type(state).__name__}, expected a state_dict or a weight vector")
    return Network(weights=weights, features=features, raw_units=raw_units)


def _load_npy(path: Path) -> np.ndarray:
    """A plain numeric array from a .npy file; never unpickles, never opens an archive."""
    try:
        with open(path, "rb") as f:
            array = np.load(f, allow_pickle=False)
    except ValueError as exc:
        raise ModelFileError(f"{path}: not a plain numeric .npy array ({exc}); object arrays are never unpickled") from None
    except (OSError, EOFError) as exc:
        raise ModelFileError(f"{path}: cannot read as .npy ({exc or 'empty file'})") from None
    if not isinstance(array, np.ndarray):  # np.load returns an archive for .npz content
        raise ModelFileError(f"{path}: holds an .npz archive, expected one .npy array")
    return array


def _read_model(path: Path) -> Network:
    name, model = modelio.load(path)
    if not hasattr(model, "features") or not hasattr(model, "weights"):
        raise ModelFileError(f"{path}: a {name!r} model, not a neural BRDF (nbrdf or naive_mlp)")
    weights = model.weights
    if not weights:
        raise ModelFileError(f"{path}: the {name!r} model holds no fitted weights")
    raw = bool(torch.allclose(model.output_scale, _RAW_SCALES))
    return Network(weights=weights, features=model.features, raw_units=raw)


def to_model(network: Network, **params):
    """A fitted `nbrdf` / `naive_mlp` model holding these weights (params: constructor overrides)."""
    from .nbrdf import NaiveMLP, NBRDF

    cls = NBRDF if check_features(network.features) == "rusinkiewicz" else NaiveMLP
    model = cls(**{**params, "hidden": network.hidden, "raw_units": network.raw_units})
    model.weights = {k: v.clone() for k, v in network.weights.items()}
    return model


def write_network(network: Network, path: str | os.PathLike, **params) -> Path:
    """Write weights in the format of `path`'s suffix, atomically (see the table above)."""
    from brdfbench.atomic import replacing

    path = Path(path)
    suffix = _suffix(path, WRITABLE, "write network weights to")
    _check_finite(network.weights, "weights to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix in MODEL_SUFFIXES:
        model = to_model(network, **params)
        return modelio.save(model, model.plugin_name, path)
    with replacing(path) as tmp:
        if suffix in VECTOR_SUFFIXES:
            with open(tmp, "wb") as f:
                np.save(f, flatten(network.weights), allow_pickle=False)
        else:
            torch.save(to_torch_state(network.weights), tmp)
    return path
