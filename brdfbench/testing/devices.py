"""What both conformance kits check of a plugin's devices (`brdfbench.device.Placed`)."""

from __future__ import annotations

import unittest

import torch

from ..errors import ConfigError
from ..device import cuda_count

#: Device types a plugin may declare (torch.device types brdfbench can resolve or may later).
KNOWN_DEVICES = frozenset({"cpu", "cuda"})
#: A fit on a GPU may differ from the CPU fit (other summation orders); its accuracy on the
#: reference material must agree with the CPU fit's within this share (or DEVICE_FIT_ABS).
DEVICE_FIT_REL, DEVICE_FIT_ABS = 0.05, 2e-3
#: The same fitted model evaluated on a GPU and on the CPU: relative agreement.
DEVICE_EVAL_RTOL = 1e-5


class NoDevice(unittest.SkipTest):
    """A device check that cannot run here (no such device, or the plugin declares none):
    reported as skipped by the kit and by pytest."""


def gpu() -> torch.device:
    """cuda:0, or NoDevice where torch sees none."""
    if not cuda_count():
        raise NoDevice("no CUDA device here: the GPU checks run where torch sees one")
    return torch.device("cuda", 0)


def assert_declared(cls: type, fresh) -> None:
    """`cls.devices` names known device types, the CPU among them; `fresh` (a new plugin of
    the class) starts on the CPU, and its `to` refuses a GPU the class does not declare."""
    declared = cls.devices
    assert isinstance(declared, (frozenset, set)) and "cpu" in declared, (
        f"{cls.__name__}.devices must be a set of device types including 'cpu', got {declared!r}")
    unknown = set(declared) - KNOWN_DEVICES
    assert not unknown, (f"{cls.__name__}.devices names unknown device type(s) {sorted(unknown)}; "
                         f"known: {sorted(KNOWN_DEVICES)}")
    assert fresh.device == torch.device("cpu"), f"a new {cls.__name__} must start on the CPU, got {fresh.device}"
    if "cuda" not in declared:
        try:
            fresh.to("cuda:0")
        except ConfigError:
            pass
        else:
            raise AssertionError(f"{cls.__name__}.to('cuda:0') was accepted but 'cuda' is not in its devices")
