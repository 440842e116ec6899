"""Peak resident memory of this process over one step (fit, evaluation).

On Linux, writing 5 to /proc/self/clear_refs resets the kernel's high-water mark
(VmHWM), so each step's peak is its own rather than the process's lifetime peak. Where
that is not available the figure is the lifetime peak (getrusage), which only grows.

`harness.memory_limit`: `parse_size` reads the key's value; the supervisor watches a
worker's resident memory (`process_rss`, `process_peak`, from /proc/<pid>/status).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from ..errors import ConfigError

_CLEAR = Path("/proc/self/clear_refs")
_STATUS = Path("/proc/self/status")


def reset_peak() -> bool:
    """Start a new peak; False where the platform cannot (the peak is then the lifetime's)."""
    try:
        _CLEAR.write_text("5")
        return True
    except OSError:
        return False


def peak_rss() -> int | None:
    """Bytes of the peak resident set since the last `reset_peak`, or None where unknown."""
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return int(peak if sys.platform == "darwin" else peak * 1024)
    except (ImportError, OSError):
        return None


# --------------------------------------------------------------------------- harness.memory_limit

#: Units of a size string, in bytes (case-insensitive; "B" alone is bytes).
_UNITS = {"": 1, "b": 1, "k": 1000, "kb": 1000, "m": 1000**2, "mb": 1000**2, "g": 1000**3, "gb": 1000**3,
          "t": 1000**4, "tb": 1000**4, "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40}
SIZE_FORMS = 'a size such as "1500MiB", "2GiB", "1.5 GB", a whole number of bytes, or null (no limit)'


def parse_size(value, key: str = "harness.memory_limit") -> int | None:
    """Bytes of a size: "1500MiB", "2GiB", "1.5 GB", "800M" (decimal units k/M/G/T, binary
    KiB/MiB/GiB/TiB), a whole number of bytes, or None (no limit). Anything else, zero or
    below, is a ConfigError naming `key`, the value and the forms it takes."""
    import re
    from fractions import Fraction

    def bad(why: str = ""):
        return ConfigError(f"{key}={value!r}{why}: must be {SIZE_FORMS}")

    if value is None:
        return None
    if isinstance(value, bool):
        raise bad()
    if isinstance(value, int):
        number, unit = value, ""
    elif isinstance(value, float):
        if not value.is_integer():
            raise bad(" is not a whole number of bytes")
        number, unit = value, ""
    elif isinstance(value, str):
        match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE]([+-]?[0-9]+))?\s*([A-Za-z]*)\s*", value)
        if match is None or match.group(3).lower() not in _UNITS:
            raise bad()
        exponent = int(match.group(2) or 0)
        if abs(exponent) > 30:
            raise bad(" is out of range")
        number = Fraction(match.group(1)) * Fraction(10) ** exponent  # exact: no float rounding of large counts
        unit = match.group(3).lower()
    else:
        raise bad()
    size = Fraction(number) * _UNITS[unit]
    if size < 1:
        raise bad(" is not above zero")
    return round(size)


def format_size(n: int | float, whole: bool = False) -> str:
    """`n` bytes in MiB for messages: "1500 MiB", "1430.5 MiB" (`whole`: "1431 MiB", rounded up, so that a peak
    just over a limit never reads as the limit itself)."""
    mib = n / 2**20
    if whole:
        return f"{math.ceil(mib)} MiB"
    return f"{mib:.0f} MiB" if abs(mib - round(mib)) < 0.05 or mib >= 10000 else f"{mib:.1f} MiB"


PROC = Path("/proc")


def _status_kib(pid: int, field: str) -> int | None:
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(field):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _children(pid: int) -> list[int]:
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tasks:
        try:
            with open(f"/proc/{pid}/task/{tid}/children", "rb") as f:
                out += [int(c) for c in f.read().split()]
        except (OSError, ValueError):
            pass
    return out


def process_rss(pid: int, children: bool = True) -> int | None:
    """Bytes resident of process `pid` (VmRSS), plus its descendants' where `children`
    (pages they share are counted in each); None where /proc cannot say."""
    own = _status_kib(pid, b"VmRSS:")
    if own is None:
        return None
    total = own
    if children:
        todo, seen = _children(pid), {pid}
        while todo:
            child = todo.pop()
            if child in seen:
                continue
            seen.add(child)
            kib = _status_kib(child, b"VmRSS:")
            if kib is not None:  # a child that has just exited counts nothing
                total += kib
                todo += _children(child)
    return total * 1024


def process_peak(pid: int) -> int | None:
    """Bytes of process `pid`'s resident high-water mark (VmHWM) since its last reset."""
    kib = _status_kib(pid, b"VmHWM:")
    return None if kib is None else kib * 1024


def reset_process_peak(pid: int) -> bool:
    """Start a new high-water mark of process `pid` (as `reset_peak` does for this one)."""
    try:
        with open(f"/proc/{pid}/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False
