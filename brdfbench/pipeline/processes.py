"""A child process's environment and end: the caller's variables and folder, dying with its
parent, and the words for its exit status."""

from __future__ import annotations

import os
import signal
import sys

_SIGNALS = {
    signal.SIGSEGV: "segmentation fault (SIGSEGV)",
    signal.SIGKILL: "killed by SIGKILL (the out-of-memory killer, or kill -9)",
    signal.SIGABRT: "aborted (SIGABRT)",
    signal.SIGBUS: "bus error (SIGBUS)",
    signal.SIGFPE: "floating-point exception (SIGFPE)",
    signal.SIGILL: "illegal instruction (SIGILL)",
    signal.SIGTERM: "terminated (SIGTERM)",
}


def exit_cause(code: int | None) -> str:
    """Words for a child process's exit status."""
    if code is None:
        return "no exit status"
    if code < 0:
        sig = -code
        try:
            return _SIGNALS.get(signal.Signals(sig), f"killed by signal {signal.Signals(sig).name}")
        except ValueError:
            return f"killed by signal {sig}"
    return f"exited with status {code} (the plugin ended the process, e.g. os._exit or sys.exit)"


def die_with_parent() -> None:
    """Linux: the kernel kills this process when its parent dies (even by SIGKILL)."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def sync_environment(env: dict[str, str], cwd: str) -> None:
    """Make this process's environment variables and working folder the caller's."""
    for key in set(os.environ) - set(env):
        del os.environ[key]
    os.environ.update(env)
    if os.getcwd() != cwd:
        os.chdir(cwd)
