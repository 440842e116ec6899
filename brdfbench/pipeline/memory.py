"""Peak resident memory of this process over one step (fit, evaluation).

On Linux, writing 5 to /proc/self/clear_refs resets the kernel's high-water mark
(VmHWM), so each step's peak is its own rather than the process's lifetime peak. Where
that is not available the figure is the lifetime peak (getrusage), which only grows.
"""

from __future__ import annotations

import sys
from pathlib import Path

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
