"""Cells in a worker process with a hard wall-clock limit.

The supervisor (main process) sends a worker one task at a time and reads its messages
(see `execute`). Each step's time limit is enforced from outside: when a step overruns,
the worker is killed (SIGKILL), never interrupted by a signal in the plugin's thread;
when the worker dies (a segfault, `os._exit`, the out-of-memory killer), the supervisor
reads the cause from its exit status. Either way the task's unfinished materials become
failure rows naming the cause, and the next task gets a fresh worker.

Under `harness.memory_limit` the supervisor also reads the worker's resident memory from
/proc/<pid>/status about every `MEMORY_POLL_S` seconds while it waits (VmRSS of the worker
and its child processes, and the worker's own high-water mark VmHWM, which catches a spike
between two looks); over the limit, the worker is killed (SIGKILL) and the task's
unfinished cells fail naming the limit and the peak reached. A worker that lives on over
the limit between tasks (caches) is replaced by a fresh one before the next task.

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

from ..plugins import registry
from ..errors import BrdfbenchError
from .config import RunConfig
from .memory import format_size, process_peak, process_rss, reset_process_peak
from .plan import Task
from .processes import die_with_parent as _die_with_parent, exit_cause, sync_environment as _sync_environment
from . import fit_pool
from .environment import ActiveMarker

log = logging.getLogger(__name__)

#: Seconds a fresh worker may take to import torch and brdfbench before it is given up.
START_TIMEOUT_S = 300.0
#: The least time a job's setup in the worker (plugins, data, harness) is allowed.
SETUP_MIN_S = 120.0
#: Seconds between the supervisor's looks at a worker's resident memory (harness.memory_limit).
MEMORY_POLL_S = 0.05

@dataclass
class Outcome:
    """How a task ended: "done", "timeout", "memory" (over harness.memory_limit) or "died",
    with the words for all but the first."""

    status: str
    message: str = ""


class Worker:
    """One worker process; `run(job, task, on_cell)` returns the task's Outcome."""

    def __init__(self):
        self.process = None
        self.conn = None
        self.threads = 0
        self.device = ("cpu", "cpu")  # (name, description) of the device the current job computes on
        self.tasks = 0  # tasks sent to this worker process (0: a fresh one)
        self.draining = False  # reading what a killed worker had sent

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
        self.tasks = 0
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

    def stop(self, kill: bool = False, drain: Callable[[tuple], object] | None = None) -> None:
        """End the worker: ask it to return (or, `kill`, SIGKILL it). `drain` is given each
        message it sent before it ended that was not yet read (e.g. cells finished just
        before a kill)."""
        if self.process is None:
            return
        if kill:
            self.process.kill()
            if drain is not None:
                self.process.join()
                self.draining = True
                try:
                    while self.conn.poll(0):
                        drain(self.conn.recv())
                except (OSError, EOFError):  # the last message, cut short by the kill
                    pass
                finally:
                    self.draining = False
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
            on_device: Callable[[int, tuple[str, str]], None] = lambda threads, device: None) -> Outcome:
        """Send `task` to the worker and wait for it: each cell goes to `on_cell`, each phase's
        note to `on_note`, and the device the job computes on (with the worker's thread count)
        to `on_device` before its first cell."""
        self.ensure()
        limit = self._memory_limit(job)
        if limit is not None:
            early = self._fit_memory(limit)
            if early is not None:
                return early
        self.tasks += 1
        envelope = (dict(os.environ), os.getcwd(), registry.snapshot(), job, task)
        if limit is not None:
            reset_process_peak(self.process.pid)  # the task's peak, not one left from an earlier task
        self.conn.send(envelope)
        timeout = job.harness.timeout_s
        deadline_budget = None if timeout is None else max(timeout, SETUP_MIN_S)
        what = f"setting up {job.label}"
        deadline = None if deadline_budget is None else time.monotonic() + deadline_budget
        fatal = None
        peak = 0
        next_look = 0.0

        def handle(msg) -> Outcome | None:
            nonlocal deadline_budget, what, deadline, fatal
            kind = msg[0]
            if kind == "phase":
                deadline_budget, what = msg[1], msg[2]
                deadline = None if msg[1] is None else time.monotonic() + msg[1]
                if msg[3] is not None:
                    on_note(msg[3])
            elif kind == "cell":
                try:
                    on_cell(msg[1:])
                except BaseException:  # the cell could not be recorded (a full disk): the task's later
                    if not self.draining:  # messages would be read by the next task, so the worker goes
                        self.stop(kill=True)
                    raise
            elif kind == "threads":
                self.threads = msg[1]
            elif kind == "device":  # sent before the job's first cell
                self.device = msg[1]
                on_device(self.threads, msg[1])
            elif kind == "fatal":  # raised once the worker has finished the task (its "done" follows)
                fatal = msg[1]
            elif kind == "done":
                if fatal is not None:
                    raise fatal
                return Outcome("done")
            return None

        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            if limit is not None:
                wait = MEMORY_POLL_S if wait is None else min(wait, MEMORY_POLL_S)
            try:
                ready = self.conn.poll(wait)
            except (OSError, EOFError):
                ready = True
            if limit is not None and time.monotonic() >= next_look:
                next_look = time.monotonic() + MEMORY_POLL_S
                peak = max(peak, process_rss(self.process.pid) or 0, process_peak(self.process.pid) or 0)
                if peak > limit:
                    ended: list[Outcome] = []  # a "done" sent just before the kill: the task had finished
                    self.stop(kill=True, drain=lambda msg: ended.extend(o for o in [handle(msg)] if o is not None))
                    if ended:
                        return ended[0]
                    return Outcome("memory", f"memory limit {format_size(limit)} exceeded (peak {format_size(peak, whole=True)}) "
                                             f"while {what}: worker stopped")
            if not ready:
                if deadline is None or time.monotonic() < deadline:
                    continue  # a look at the memory, not the end of the step's time
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
            outcome = handle(msg)
            if outcome is not None:
                return outcome

    def _memory_limit(self, job: RunConfig) -> int | None:
        """The job's harness.memory_limit in bytes, None where it has none or /proc cannot enforce it."""
        limit = job.harness.memory_limit
        if limit is not None and process_rss(self.process.pid, children=False) is None:
            _warn_once("proc", "harness.memory_limit=%s is not enforced: this platform has no /proc/<pid>/status "
                               "to read a worker's resident memory from", format_size(limit))
            return None
        return limit

    def _fit_memory(self, limit: int) -> Outcome | None:
        """Before a task: a worker that lives on over the limit (caches of earlier tasks) is
        replaced by a fresh one; a fresh one already over it is stopped, failing the task."""
        rss = process_rss(self.process.pid) or 0
        if rss > limit and self.tasks:
            log.info("the worker process holds %s, over harness.memory_limit=%s: starting a fresh one",
                     format_size(rss), format_size(limit))
            self.stop()
            self._start()
            rss = process_rss(self.process.pid) or 0
        if rss > limit:
            _warn_once(("fresh", limit), "harness.memory_limit=%s is below the resident memory of a fresh worker "
                                         "process (%s): every cell under it fails", format_size(limit), format_size(rss, whole=True))
            self.stop(kill=True)
            return Outcome("memory", f"memory limit {format_size(limit)} exceeded (peak {format_size(rss, whole=True)}) "
                                     "while starting the worker process: worker stopped")
        return None


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


_WARNED: set = set()


def _warn_once(key, message: str, *args) -> None:
    if key not in _WARNED:
        _WARNED.add(key)
        log.warning(message, *args)


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


def _worker_main(conn) -> None:
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the supervisor, which stops us

    try:
        _serve(conn)
    finally:  # its fit helpers would hold the exit (multiprocessing joins a process's children)
        fit_pool.shutdown()


def _serve(conn) -> None:
    """Run the tasks the supervisor sends until it sends None or goes away."""
    import torch

    from .execute import execute, job_state  # lazy: safetensors

    marker = ActiveMarker()
    default_threads = torch.get_num_threads()
    conn.send(("threads", default_threads))
    states: dict = {}
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
