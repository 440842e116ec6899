"""Cells in a worker process with a hard wall-clock limit.

The supervisor (main process) sends a worker one task at a time and reads its messages
(see `execute`). Each step's time limit is enforced from outside: when a step overruns,
the worker is killed (SIGKILL), never interrupted by a signal in the plugin's thread;
when the worker dies (a segfault, `os._exit`, the out-of-memory killer), the supervisor
reads the cause from its exit status. Either way the task's unfinished materials become
failure rows naming the cause, and the next task gets a fresh worker.

A worker is started with `spawn` (a fresh interpreter: no inherited locks or threads from
torch, drjit or LLVM) and lives on across tasks and jobs of one process, keeping what a
job built (harness, simulators, direction sets). Each task carries the caller's
environment variables, working folder and in-process plugin registrations.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import multiprocessing as mp
import multiprocessing.util
import os
import signal
import sys
import time
from dataclasses import dataclass
from typing import Callable

from .. import registry
from ..errors import BrdfbenchError
from .config import RunConfig
from .plan import Task

log = logging.getLogger(__name__)

#: Seconds a fresh worker may take to import torch and brdfbench before it is given up.
START_TIMEOUT_S = 300.0
#: The least time a job's setup in the worker (plugins, data, harness) is allowed.
SETUP_MIN_S = 120.0

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
    """Words for a worker's exit status."""
    if code is None:
        return "no exit status"
    if code < 0:
        sig = -code
        try:
            return _SIGNALS.get(signal.Signals(sig), f"killed by signal {signal.Signals(sig).name}")
        except ValueError:
            return f"killed by signal {sig}"
    return f"exited with status {code} (the plugin ended the process, e.g. os._exit or sys.exit)"


@dataclass
class Outcome:
    """How a task ended: "done", "timeout" or "died", with the words for the last two."""

    status: str
    message: str = ""


class Worker:
    """One worker process; `run(job, task, on_cell)` returns the task's Outcome."""

    def __init__(self):
        self.process = None
        self.conn = None
        self.threads = 0
        self.device = ("cpu", "cpu")  # (name, description) of the device the current job computes on

    def _start(self) -> None:
        # a spawned child inherits the parent's start-method name: under joblib's loky workers
        # that is "loky", which a fresh interpreter cannot find; reset it to a standard one
        if mp.get_start_method(allow_none=True) not in (None, "fork", "spawn", "forkserver"):
            mp.set_start_method("spawn", force=True)
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker_main, args=(child,), name="brdfbench-worker", daemon=False)
        with _main_module_hidden():
            self.process.start()
        child.close()
        self.conn = parent
        if not parent.poll(START_TIMEOUT_S):
            self.stop(kill=True)
            raise BrdfbenchError(f"the worker process did not start within {START_TIMEOUT_S:g} s")
        try:
            self.threads = parent.recv()[1]
        except (OSError, EOFError):
            self.process.join(timeout=10)
            cause = exit_cause(self.process.exitcode)
            self.stop(kill=True)
            raise BrdfbenchError(f"the worker process failed to start: {cause}") from None

    def alive(self) -> bool:
        return self.process is not None and self.process.is_alive()

    def stop(self, kill: bool = False) -> None:
        if self.process is None:
            return
        if kill:
            self.process.kill()
        else:
            try:
                self.conn.send(None)
            except (OSError, EOFError):
                pass
        self.process.join(timeout=None if kill else 10)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.conn.close()
        self.process = self.conn = None

    def ensure(self) -> "Worker":
        """Start the worker unless it is running; returns self."""
        if not self.alive():
            if self.process is not None:
                self.stop(kill=True)
            self._start()
        return self

    def run(self, job: RunConfig, task: Task, on_cell: Callable[[tuple], None],
            on_note: Callable[[str], None] = lambda note: None,
            on_device: Callable[[tuple[str, str]], None] = lambda device: None) -> Outcome:
        self.ensure()
        envelope = (dict(os.environ), os.getcwd(), registry.snapshot(), job, task)
        self.conn.send(envelope)
        timeout = job.harness.timeout_s
        deadline_budget = None if timeout is None else max(timeout, SETUP_MIN_S)
        what = f"setting up {job.label}"
        deadline = None if deadline_budget is None else time.monotonic() + deadline_budget
        fatal = None
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                ready = self.conn.poll(wait)
            except (OSError, EOFError):
                ready = True
            if not ready:
                self.stop(kill=True)
                return Outcome("timeout", f"{what} exceeded the time limit of {deadline_budget:g} s "
                                          "(worker process killed)")
            try:
                msg = self.conn.recv()
            except (OSError, EOFError):
                self.process.join(timeout=10)
                cause = exit_cause(self.process.exitcode)
                self.stop(kill=True)
                return Outcome("died", f"worker process died while {what}: {cause}")
            kind = msg[0]
            if kind == "phase":
                deadline_budget, what = msg[1], msg[2]
                deadline = None if msg[1] is None else time.monotonic() + msg[1]
                if msg[3] is not None:
                    on_note(msg[3])
            elif kind == "cell":
                on_cell(msg[1:])
            elif kind == "threads":
                self.threads = msg[1]
            elif kind == "device":  # sent before the job's first cell
                self.device = msg[1]
                on_device(msg[1])
            elif kind == "fatal":  # raised once the worker has finished the task (its "done" follows)
                fatal = msg[1]
            elif kind == "done":
                if fatal is not None:
                    raise fatal
                return Outcome("done")


@contextlib.contextmanager
def _main_module_hidden():
    """Start the worker without re-running the caller's script: `spawn` imports `__main__`
    again in the child (a script without a `__name__ == "__main__"` guard would run twice);
    the worker needs nothing from it (plugins are named by import path)."""
    main = sys.modules.get("__main__")
    saved = {k: getattr(main, k) for k in ("__file__", "__spec__") if main is not None and hasattr(main, k)}
    try:
        for k in saved:
            setattr(main, k, None) if k == "__spec__" else delattr(main, k)
        yield
    finally:
        for k, v in saved.items():
            setattr(main, k, v)


_WORKER: Worker | None = None


def shared_worker() -> Worker:
    """This process's worker, started on first use and stopped at exit."""
    global _WORKER
    if _WORKER is None:
        _WORKER = Worker()
        atexit.register(_WORKER.stop)
        # multiprocessing's own exit handler joins non-daemonic children (as in a joblib/loky
        # worker, whose exit runs it first): stop ours before that join, or it waits forever
        mp.util.Finalize(None, _WORKER.stop, exitpriority=10)
    return _WORKER


# --------------------------------------------------------------------------- inside the worker


def _die_with_parent() -> None:
    """Linux: the kernel kills this worker when its supervisor dies (even by SIGKILL)."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass


def _sync_environment(env: dict[str, str], cwd: str) -> None:
    for key in set(os.environ) - set(env):
        del os.environ[key]
    os.environ.update(env)
    if os.getcwd() != cwd:
        os.chdir(cwd)


def _worker_main(conn) -> None:
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the supervisor, which stops us
    import torch

    from .environment import ActiveMarker
    from .execute import execute, job_state

    default_threads = torch.get_num_threads()
    conn.send(("threads", default_threads))
    states: dict = {}
    marker = ActiveMarker()
    while True:
        try:
            envelope = conn.recv()
        except (EOFError, OSError):
            return
        if envelope is None:
            return
        env, cwd, extra, job, task = envelope
        _sync_environment(env, cwd)
        registry.restore(extra)
        try:
            with marker:
                key = repr(job)
                if key not in states:
                    states.clear()  # one job's state at a time: what it built can be large
                    states[key] = job_state(job)
                conn.send(("threads", apply_threads(job.threads or default_threads)))
                conn.send(("device", states[key].recorded_device))
                execute(job, task, states[key], conn.send, marker.count)
        except BrdfbenchError as exc:
            conn.send(("fatal", _portable(exc)))
        conn.send(("threads", torch.get_num_threads()))
        conn.send(("done",))


def apply_threads(n: int) -> int:
    """Run torch (and numba, where loaded) on `n` threads; the count torch then uses."""
    import torch

    if torch.get_num_threads() != n:
        torch.set_num_threads(n)
    numba = sys.modules.get("numba")
    if numba is not None:
        try:
            numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
        except Exception:  # a numba without a threading layer: it keeps its own count
            pass
    return torch.get_num_threads()


def _portable(exc: BrdfbenchError) -> BrdfbenchError:
    """The error itself where it pickles, else a BrdfbenchError of its class name and message."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return BrdfbenchError(f"{type(exc).__name__}: {exc}")
