"""NBRDF weights in the formats people already have, to and from a `Network`.

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

A model file is written by the representation its encoding belongs to (`representation_for`),
found through the registry like any plugin; it records only what is true of a converted
network: its architecture, encoding, units and source file, no training parameters.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from .. import modelio
from ..plugins import registry
from ..errors import DataError, ModelFileError, PluginError
from .keras_h5 import read_nbrdf_h5
from .layouts import check_finite, check_hidden, flatten, from_torch_state, to_torch_state, unflatten
from .network import FEATURES, PUBLISHED_HIDDEN, Network
from ..atomic import replacing

H5_SUFFIXES = (".h5", ".hdf5")
VECTOR_SUFFIXES = (".npy",)
TORCH_SUFFIXES = (".pt", ".pth")
MODEL_SUFFIXES = (".safetensors",)
READABLE = H5_SUFFIXES + VECTOR_SUFFIXES + TORCH_SUFFIXES + MODEL_SUFFIXES
WRITABLE = VECTOR_SUFFIXES + TORCH_SUFFIXES + MODEL_SUFFIXES


def representation_for(features: str) -> str:
    """The registered representation that fits and saves networks of this input encoding:
    the one whose spec declares it as `network_features` (a plugin that fails to load is
    passed over); a PluginError where none or several do."""
    check_features(features)
    found = []
    for name in registry.names("representations"):
        try:
            spec = registry.get("representations", name)
        except PluginError:
            continue
        if getattr(spec, "network_features", "") == features:
            found.append(name)
    if len(found) != 1:
        which = f"{len(found)} do ({', '.join(found)})" if found else "none does"
        raise PluginError(f"networks of input encoding {features!r} need one registered representation whose spec "
                          f"declares network_features={features!r}; {which}")
    return found[0]


def check_features(features: str) -> str:
    if features not in FEATURES:
        raise ModelFileError(f"unknown input encoding features={features!r}; expected one of {', '.join(FEATURES)}")
    return features


def _suffix(path: Path, allowed: tuple[str, ...], verb: str) -> str:
    suffix = path.suffix.lower()
    if suffix not in allowed:
        raise ModelFileError(f"{path}: cannot {verb} {suffix or 'a suffix-less file'}; expected one of {', '.join(allowed)}")
    return suffix


def _named(path: Path, exc: Exception) -> str:
    """The error's message, led by the file's name unless it already names it."""
    text = str(exc)
    return text if str(path) in text else f"{path}: {text}"


# --------------------------------------------------------------------------- reading


def read_network(path: str | os.PathLike, *, hidden: Sequence[int] = PUBLISHED_HIDDEN, raw_units: bool = False,
                 features: str = "rusinkiewicz") -> Network:
    """Read network weights from any format in the table above; `source` is the file.

    `hidden` gives the layer widths of a flat `.npy` vector and of an `.h5` file (state
    dicts and brdfbench models carry their own); `raw_units` and `features` describe files
    that do not record them (all but brdfbench models). Raises ModelFileError naming the
    file for a malformed file or a NaN/Inf weight.
    """
    path = Path(path)
    suffix = _suffix(path, READABLE, "read network weights from")
    if not path.is_file():
        raise ModelFileError(f"{path}: no such network file")
    if suffix in MODEL_SUFFIXES:
        network = _read_model(path)
    else:
        network = Network(weights=_read_weights(path, suffix, check_hidden(hidden, str(path))),
                          features=check_features(features), raw_units=bool(raw_units), source=str(path))
    check_finite(network.weights, str(path))
    return network


def _read_weights(path: Path, suffix: str, hidden: tuple[int, ...]) -> dict[str, torch.Tensor]:
    if suffix in H5_SUFFIXES:
        try:
            arrays = read_nbrdf_h5(path, hidden=hidden)
        except DataError as exc:  # one error type for every weight format
            raise ModelFileError(str(exc)) from None
        return {k: torch.from_numpy(v) for k, v in arrays.items()}
    if suffix in VECTOR_SUFFIXES:
        return unflatten(_load_npy(path), hidden, where=str(path))
    state = modelio.load_torch_weights(path)  # weights_only=True: refuses anything needing pickle
    if isinstance(state, torch.Tensor):
        return unflatten(state, hidden, where=str(path))
    if isinstance(state, Mapping):
        return from_torch_state(state, where=str(path))
    raise ModelFileError(f"{path}: holds a {type(state).__name__}, expected a state_dict or a weight vector")


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
    """The `network` of a brdfbench model file (a neural representation exposes one)."""
    try:
        name, model = modelio.load(path)
    except ModelFileError as exc:
        raise ModelFileError(_named(path, exc)) from None
    if not hasattr(model, "network"):
        raise ModelFileError(f"{path}: a {name!r} model, not a neural BRDF (nbrdf or naive_mlp)")
    network = model.network
    if network is None:
        raise ModelFileError(f"{path}: the {name!r} model holds no fitted weights")
    if not isinstance(network, Network):
        raise ModelFileError(f"{path}: the {name!r} model's network is a {type(network).__name__}, not an NBRDF Network")
    return dataclasses.replace(network, source=str(path))


# --------------------------------------------------------------------------- writing


def to_model(network: Network):
    """A fitted model holding these weights, of the representation registered for the
    network's encoding (`representation_for`), made by its `from_network`."""
    name = representation_for(network.features)
    return registry.get("representations", name).load().from_network(network)


def write_network(network: Network, path: str | os.PathLike) -> Path:
    """Write weights in the format of `path`'s suffix, atomically (see the table above)."""
    path = Path(path)
    suffix = _suffix(path, WRITABLE, "write network weights to")
    check_finite(network.weights, "weights to write")
    if suffix in MODEL_SUFFIXES:
        model = to_model(network)  # before any directory is made: an unknown encoding writes nothing
        path.parent.mkdir(parents=True, exist_ok=True)
        return modelio.save(model, representation_for(network.features), path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp:
        if suffix in VECTOR_SUFFIXES:
            with open(tmp, "wb") as f:
                np.save(f, flatten(network.weights), allow_pickle=False)
        else:
            torch.save(to_torch_state(network.weights), tmp)
    return path
