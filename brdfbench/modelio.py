"""Saving and loading fitted representations and generators without pickle.

One `.safetensors` file per model: the tensors of `state_dict()`, and in the safetensors
header metadata a JSON document with the plugin name, its params, its metadata and the
package version. Loading parses that header and the raw tensor bytes only: it never runs
code. A pickle or a torch.save archive is refused with a clear error, and so is a header
that does not fit a registered representation (unknown name, params its constructor does
not take, tensors its `from_state` needs but the file lacks): a `ModelFileError` naming
the file. Generators are saved the same way (`save_generator` / `load_generator`), under
their own format tag, so a generator file never loads as a representation or back.
"""

from __future__ import annotations

import inspect
import json
import os
import traceback
from pathlib import Path

import safetensors.torch
import torch

from . import __version__
from .plugins import registry
from .atomic import replacing
from .errors import BrdfbenchError, ModelFileError, PluginError
from .protocols.representation import Representation

_FORMAT = "brdfbench.model/1"
#: group -> (format tag, header key naming the plugin, the word for it in messages)
_KINDS = {
    "representations": (_FORMAT, "representation"),
    "generators": ("brdfbench.generator/1", "generator"),
}


def _sniff_refusal(path: Path, head: bytes) -> str | None:
    if head[8:9] == b"{":  # safetensors: a little-endian u64 header length, then the JSON header
        return None  # (that length may start with the bytes of a pickle's protocol mark)
    if head[:1] == b"\x80" and len(head) > 1 and head[1] <= 5:
        return "is a Python pickle; models are never unpickled (save them with brdfbench.modelio.save)"
    if head[:4] == b"PK\x03\x04":
        return "is a zip archive (torch.save format, which holds pickles); models load from safetensors only"
    return None


def save(model: Representation, name: str, path: str | os.PathLike) -> Path:
    """Write `model` (registered as `name`) to `path` atomically."""
    return _save(model, name, path, "representations")


def save_generator(generator, name: str, path: str | os.PathLike) -> Path:
    """Write a fitted generator (registered as `name`) to `path` atomically."""
    return _save(generator, name, path, "generators")


def _save(model, name: str, path: str | os.PathLike, group: str) -> Path:
    path = Path(path)
    fmt, key = _KINDS[group]
    header = {
        "format": fmt,
        key: name,
        "params": model.params,
        "metadata": model.metadata(),
        "brdfbench_version": __version__,
    }
    tensors = {k: v.detach().contiguous().cpu() for k, v in model.state_dict().items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    with replacing(path) as tmp:
        safetensors.torch.save_file(tensors, str(tmp), metadata={"brdfbench": json.dumps(header)})
    return path


def load(path: str | os.PathLike) -> tuple[str, Representation]:
    """Read a model file; returns (representation name, model)."""
    return _load(path, "representations")


def load_generator(path: str | os.PathLike):
    """Read a generator file; returns (generator name, fitted generator)."""
    return _load(path, "generators")


def holds_generator(path: str | os.PathLike) -> bool:
    """Whether a safetensors file's brdfbench header says it holds a generator (reads the header only)."""
    try:
        with safetensors.safe_open(str(path), framework="pt") as f:
            header = json.loads((f.metadata() or {}).get("brdfbench", "{}"))
    except Exception:  # not readable as one: `load` says why
        return False
    return isinstance(header, dict) and header.get("format") == _KINDS["generators"][0]


def _load(path: str | os.PathLike, group: str):
    fmt, kind = _KINDS[group]
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(9)
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot read model file ({exc.strerror})") from None
    refusal = _sniff_refusal(path, head)
    if refusal:
        raise ModelFileError(f"{path}: {refusal}")
    try:
        with safetensors.safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            # Fresh, aligned copies: tensors viewing the file's buffer at arbitrary offsets make
            # MKL pick other kernels, and a loaded model would differ from the saved one in the last bit.
            tensors = {k: f.get_tensor(k).clone(memory_format=torch.contiguous_format) for k in f.keys()}
    except Exception as exc:
        raise ModelFileError(f"{path}: not a valid safetensors model file ({exc})") from None
    try:
        header = json.loads(meta["brdfbench"])
    except (KeyError, ValueError, TypeError) as exc:
        raise ModelFileError(f"{path}: safetensors file lacks brdfbench metadata (key {exc})") from None
    if not isinstance(header, dict):
        raise ModelFileError(f"{path}: brdfbench metadata must be a JSON object")
    other = [k for g, (f, k) in _KINDS.items() if g != group and header.get("format") == f]
    if other:
        raise ModelFileError(f"{path}: holds a {other[0]}, not a {kind}")
    try:
        if header.get("format") != fmt:
            raise KeyError("format")
        name, params, extra = header[kind], header["params"], header["metadata"]
    except KeyError as exc:
        raise ModelFileError(f"{path}: safetensors file lacks brdfbench metadata (key {exc})") from None
    for key, value, typ in ((kind, name, str), ("params", params, dict), ("metadata", extra, dict)):
        if not isinstance(value, typ):
            raise ModelFileError(f"{path}: brdfbench metadata key {key!r} must be a {typ.__name__}, got {value!r}")
    cls = _plugin_class(path, name, group, kind)
    _check_params(path, name, cls, params, kind)
    return name, _rebuild(path, name, cls, params, tensors, extra, kind)


def _plugin_class(path: Path, name: str, group: str, kind: str) -> type:
    """The class registered as `name`; an unknown name is the file's fault, named with the known ones."""
    try:
        spec = registry.get(group, name)
    except PluginError as exc:
        raise ModelFileError(f"{path}: the file names {kind} {name!r}, which is not registered: {exc}") from None
    return spec.load()


def _check_params(path: Path, name: str, cls: type, params: dict, kind: str = "representation") -> None:
    """Refuse params the constructor does not take (or lacks), naming them and what it takes."""
    try:
        signature = inspect.signature(cls)
    except (TypeError, ValueError):  # no introspectable signature: let the constructor judge
        return
    taken = [p.name for p in signature.parameters.values() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    takes = ", ".join(taken) if taken else "no params"
    if not any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
        unknown = [k for k in params if k not in taken]
        if unknown:
            raise ModelFileError(
                f"{path}: {kind} {name!r} takes no param(s) {', '.join(map(repr, unknown))}; "
                f"it takes: {takes}. The file was saved by another {kind} or version"
            )
    try:
        signature.bind(**params)
    except TypeError as exc:
        raise ModelFileError(f"{path}: params {params} do not fit {kind} {name!r} ({exc}); it takes: {takes}") from None


class _Tensors(dict):
    """The file's tensors; remembers which ones `from_state` asked for and the file lacks."""

    def __init__(self, tensors: dict[str, torch.Tensor]):
        super().__init__(tensors)
        self.missing: list[str] = []

    def __missing__(self, key):
        self.missing.append(key)
        raise KeyError(key)


def _expected_tensors(cls: type, params: dict) -> list[str]:
    """Tensor names a fresh model of `cls` has (a hint for the error message only)."""
    try:
        return list(cls(**params).state_dict())
    except Exception:
        return []


def _rebuild(path: Path, name: str, cls: type, params: dict, tensors: dict, extra: dict,
             kind: str = "representation"):
    """`cls.from_state`, with a malformed or mismatched file reported as a ModelFileError naming it."""
    held = _Tensors(tensors)
    try:
        return cls.from_state(params, held, extra)
    except BrdfbenchError as exc:  # the file's values refused (a ConfigError from the constructor too): name the file
        message = str(exc)
        raise ModelFileError(message if str(path) in message else f"{path}: {message}") from None
    except (KeyError, TypeError, ValueError, IndexError, RuntimeError) as exc:
        holds = ", ".join(map(repr, tensors)) or "none"
        if held.missing:
            missing = list(dict.fromkeys([*held.missing, *(k for k in _expected_tensors(cls, params) if k not in tensors)]))
            raise ModelFileError(
                f"{path}: lacks tensor(s) {', '.join(map(repr, missing))} that {kind} {name!r} needs; "
                f"the file holds: {holds}. Was it saved by another {kind}?"
            ) from None
        detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        raise ModelFileError(
            f"{path}: {kind} {name!r} cannot be rebuilt from this file ({detail}); the file holds tensors: {holds}"
        ) from None


#: What `load_torch_weights` takes, for its refusals.
TORCH_ACCEPTED = "a torch .pt file of tensors only (a state_dict saved with torch.save), .npy, .h5 or .safetensors"


def load_torch_weights(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Load a torch state dict with weights_only=True (no arbitrary code), for importers.

    A refusal is one line of our own: torch's advice to retry with weights_only=False is
    the wrong advice beside a file that may carry code."""
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise ModelFileError(f"{path}: no such file") from None
    except Exception as exc:
        text = str(exc)
        if "GLOBAL" in text or "Unsupported global" in text:
            raise ModelFileError(f"{path}: holds pickled Python objects besides tensors and was not loaded "
                                 f"(nothing in it ran); accepted: {TORCH_ACCEPTED}") from None
        raise ModelFileError(f"{path}: not a torch file of tensors (its contents could not be read as one); "
                             f"accepted: {TORCH_ACCEPTED}") from None
