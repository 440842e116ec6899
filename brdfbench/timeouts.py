"""A wall-clock limit for plugin calls, so a hung plugin becomes a recorded failure."""

from __future__ import annotations

import signal
import threading
import warnings
from contextlib import contextmanager


class PluginTimeout(Exception):
    pass


@contextmanager
def time_limit(seconds: float | None, what: str):
    """Raise PluginTimeout in the main thread after `seconds` (SIGALRM; no limit elsewhere)."""
    if not seconds or threading.current_thread() is not threading.main_thread() or not hasattr(signal, "SIGALRM"):
        if seconds:
            warnings.warn(f"no time limit for {what}: only enforced in the main thread on POSIX", stacklevel=2)
        yield
        return

    def _raise(signum, frame):
        raise PluginTimeout(f"{what} exceeded the time limit of {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, _raise)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
