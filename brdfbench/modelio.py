"""Saving and loading fitted representations without pickle.

One `.safetensors` file per model: the tensors of `state_dict()`, and in the safetensors
header metadata a JSON document with the plugin name, its params, its metadata and the
package version. Loading parses that header and the raw tensor bytes only: it never runs
code. A pickle or a torch.save archive is refused with a clear error.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import safetensors.torch
import torch

from . import __version__, registry
from .atomic import replacing
from .errors import ModelFileError
from .protocol import Representation

_FORMAT = "brdfbench.model/1"


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
    path = Path(path)
    header = {
        "format": _FORMAT,
        "representation": name,
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
        if header.get("format") != _FORMAT:
            raise KeyError("format")
        name, params, extra = header["representation"], header["params"], header["metadata"]
    except (KeyError, ValueError, TypeError) as exc:
        raise ModelFileError(f"{path}: safetensors file lacks brdfbench metadata (key {exc})") from None
    cls = registry.get("representations", name).load()
    return name, cls.from_state(params, tensors, extra)


def load_torch_weights(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Load a torch state dict with weights_only=True (no arbitrary code), for importers."""
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise ModelFileError(f"{path}: refused by torch.load(weights_only=True): {exc}") from None
