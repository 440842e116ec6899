"""The compute device of a run: the `device` key, what it resolves to, and how it is described.

`device` is run control (it never enters a configuration's hash): `auto` (the first CUDA
device torch sees, else the CPU), `cpu`, `cuda` (the first CUDA device) or `cuda:N`. A
plugin runs on the resolved device where its class declares that device's type in
`devices` (see `brdfbench.protocols.representation.Representation.to`), else on the CPU; every row records
the device its figures were measured on (`describe`).
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import ClassVar

import torch

from .errors import ConfigError

KEY = "device"
CHOICES = ("auto", "cpu", "cuda", "cuda:N")
_CUDA_N = re.compile(r"^cuda:(\d+)$")
CPU = torch.device("cpu")


def cuda_count() -> int:
    """CUDA devices torch can use here (0 without a CUDA build or a driver)."""
    try:
        return torch.cuda.device_count() if torch.cuda.is_available() else 0
    except Exception:  # a broken driver reads as no GPU
        return 0


def available() -> list[str]:
    """The devices this machine offers, e.g. ["cpu", "cuda:0"]."""
    return ["cpu", *(f"cuda:{i}" for i in range(cuda_count()))]


def resolve(spec: object, key: str = KEY) -> torch.device:
    """The torch device a `device` value names; a ConfigError naming `key`, the value and
    what exists for a value this machine cannot honour (never a silent CPU run)."""
    text = str(spec).strip().lower() if isinstance(spec, (str, torch.device)) else None
    here = ", ".join(available())
    if text == "auto":
        return torch.device("cuda", 0) if cuda_count() else CPU
    if text == "cpu":
        return CPU
    match = _CUDA_N.match(text or "")
    if text == "cuda" or match:
        n = cuda_count()
        index = int(match.group(1)) if match else 0
        if n == 0:
            why = "torch was built without CUDA" if torch.version.cuda is None else "torch sees no CUDA device"
            raise ConfigError(f"{key}={spec!r}: {why} on this machine (devices here: {here}); use {key}=cpu or auto")
        if index >= n:
            raise ConfigError(f"{key}={spec!r}: this machine has {n} CUDA device(s) (devices here: {here})")
        return torch.device("cuda", index)
    raise ConfigError(f"{key}={spec!r}: expected one of {', '.join(CHOICES)} (devices here: {here})")


def check_spec(spec: object, key: str = KEY) -> str:
    """`spec` as written, after checking this machine can honour it."""
    resolve(spec, key)
    return str(spec).strip().lower()


def for_plugin(device: torch.device, cls: type) -> torch.device:
    """Where a plugin class runs when the job asks for `device`: there if the class declares
    its type in `devices`, else the CPU."""
    declared = getattr(cls, "devices", frozenset({"cpu"}))
    return device if device.type in declared else CPU


@lru_cache(maxsize=8)
def describe(device: torch.device) -> str:
    """What the device is, for the record: the CPU is "cpu"; a GPU its model, memory,
    compute capability, driver, CUDA and torch versions."""
    if device.type != "cuda":
        return "cpu"
    index = device.index if device.index is not None else torch.cuda.current_device()
    props = torch.cuda.get_device_properties(index)
    parts = [props.name, f"{props.total_memory / 2**30:.1f} GiB", f"CC {props.major}.{props.minor}"]
    driver = _driver_version()
    if driver:
        parts.append(f"driver {driver}")
    parts += [f"CUDA {torch.version.cuda}", f"torch {torch.__version__}"]
    return ", ".join(parts)


def _driver_version() -> str:
    try:
        text = open("/proc/driver/nvidia/version", encoding="utf-8").readline()
    except OSError:
        return ""
    match = re.search(r"Kernel Module\s+(?:for \S+\s+)?([\d.]+)", text)
    return match.group(1) if match else ""


def name(device: torch.device) -> str:
    """"cpu" or "cuda:N"."""
    if device.type == "cuda":
        return f"cuda:{device.index if device.index is not None else torch.cuda.current_device()}"
    return str(device)


def synchronize(device: torch.device) -> None:
    """Wait for the device's queued work (a no-op on the CPU): call before reading a timer."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


_OOM = getattr(torch, "OutOfMemoryError", torch.cuda.OutOfMemoryError)


def on_host(evaluate, device: torch.device):
    """`evaluate(wi, wo)` of a model on `device` as a function of CPU tensors returning CPU
    values (for code that reads values on the host: lobe slices, renderers)."""
    if device.type == "cpu":
        return evaluate
    return lambda wi, wo: evaluate(wi.to(device), wo.to(device)).cpu()


def out_of_memory(exc: BaseException) -> bool:
    """True for a device allocation that failed (torch's own error, or a kernel's)."""
    return isinstance(exc, _OOM) or (isinstance(exc, RuntimeError) and "out of memory" in str(exc))


def memory_message(exc: BaseException, device: torch.device) -> str:
    """A failure row's words for a device out of memory: the device and what was asked for."""
    text = str(exc)
    asked = re.search(r"Tried to allocate ([\d.]+ [KMGT]?i?B)", text)
    total = re.search(r"total capacity of ([\d.]+ [KMGT]?i?B)", text)
    where = name(device)
    if device.type == "cuda":
        where += f" ({torch.cuda.get_device_name(device)})"
    out = f"out of memory on {where}"
    if asked:
        out += f": asked for {asked.group(1)}"
    if total:
        out += f" of {total.group(1)}"
    return out


class Placed:
    """The device half of the plugin protocols (representations and generators).

    A plugin class lists in `devices` the device types it runs on; "cpu" is always one.
    `to(device)` moves what the plugin holds (fitted weights, a trained basis) and makes it
    do its later work there: `fit`, `fit_many`, `train` and sampling compute on
    `self.device`, and what they return lives there; `eval(wi, wo)` takes inputs on
    `self.device` and returns values on the inputs' device. Saving reads `state_dict()`
    wherever it lives; loading builds on the CPU (`to` after it). The pipeline calls `to`
    for a job whose `device` the class declares, and leaves other plugins on the CPU.
    """

    devices: ClassVar[frozenset[str]] = frozenset({"cpu"})

    @property
    def device(self) -> torch.device:
        """Where the plugin computes (the CPU unless moved by `to`)."""
        return self.__dict__.get("_device", CPU)

    def to(self, device: "torch.device | str"):
        """Compute on `device` from now on, with any held tensors moved there; returns self."""
        device = torch.device(device)
        if device.type == "cuda" and device.index is None:
            device = torch.device("cuda", torch.cuda.current_device())
        if device.type not in self.devices:
            raise ConfigError(f"{type(self).__name__} runs on {', '.join(sorted(self.devices))}, not {device}")
        self._move(device)
        self._device = device
        return self

    def _move(self, device: torch.device) -> None:
        """Move held tensors to `device` (subclasses that hold tensors and run off the CPU)."""
