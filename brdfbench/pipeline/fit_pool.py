"""Fits of several materials at once, each in its own single-threaded process.

A representation whose class sets `fits_in_parallel` (its `fit` runs on one thread, or
holds the GIL in Python code such as an L-BFGS loop) has the materials of a task fitted
side by side by `processes` helper processes of the worker, one material each at a time,
instead of one after another on a core or two. Each fit starts from `torch.manual_seed(seed)`
on one torch thread, as a task of one material fitted in the worker does, so the fitted
models are the same. The helpers are started with `spawn`, die with the worker (even when
it is killed), and live on across the worker's tasks and jobs while their count fits.
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import contextlib
import multiprocessing as mp
import os
import pickle
import signal
import tempfile
import traceback
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .memory import process_peak, reset_process_peak
from .processes import die_with_parent, exit_cause, sync_environment

#: Where the tables are shared with the helpers: memory, where the system has it.
_SHM = "/dev/shm"
_POOL: cf.ProcessPoolExecutor | None = None
_SIZE = 0
_WARM: set[type] = set()  # classes whose module the live helpers have imported


def _init_helper() -> None:
    die_with_parent()
    import torch

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the supervisor
    torch.set_num_threads(1)


@dataclass(frozen=True)
class _Target:
    """A material as a helper receives it: its table's file values in a file the helper maps
    (read-only, no copy) instead of tens of megabytes through a pipe."""

    name: str
    category: str
    source: str
    path: str

    def material(self):
        from ..merl import MerlTable  # lazy: torch
        from ..protocols.representation import Material  # lazy: torch

        raw = np.asarray(np.load(self.path, mmap_mode="r"))
        return Material(self.name, MerlTable(raw), self.category, self.source)


def _fit_one(cls: type, params: dict[str, Any], target: _Target, seed: int, env: dict[str, str], cwd: str):
    """One material's fit in a helper, in the caller's environment variables and folder: the
    fitted model, or the exception it raised (kept where it pickles, else its text), so that
    one failed fit fails its material only."""
    import torch

    try:
        sync_environment(env, cwd)
        material = target.material()
        torch.manual_seed(seed)
        return True, cls(**params).fit(material, seed=seed)
    except Exception as exc:  # returned, not raised: the caller decides what it means
        try:
            pickle.dumps(exc)
            return False, exc
        except Exception:
            return False, RuntimeError("".join(traceback.format_exception_only(type(exc), exc)).strip())


#: Thread pools of the native libraries a helper loads (scipy's and numpy's OpenBLAS, OpenMP,
#: MKL) get one thread: read when the library loads, so set in the environment the helper
#: starts with. (Measured on two cores: two helpers whose OpenBLAS kept its default two
#: spinning threads each fitted three times slower than one fit alone.)
ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMEXPR_NUM_THREADS": "1"}


@contextlib.contextmanager
def _helper_environment():
    saved = {k: os.environ.get(k) for k in ONE_THREAD}
    os.environ.update(ONE_THREAD)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _ready(cls: type) -> None:
    """Nothing: unpickling `cls` imports its module, so that the fits time no imports."""


def ready(cls: type, processes: int) -> cf.ProcessPoolExecutor:
    """The helpers, `processes` of them, started (in the one-thread environment) and with
    `cls`'s module imported: start-up is not part of the fits' time."""
    global _POOL, _SIZE
    if _POOL is None or _SIZE != processes or getattr(_POOL, "_broken", False):
        shutdown()
        _POOL = cf.ProcessPoolExecutor(processes, mp_context=mp.get_context("spawn"), initializer=_init_helper)
        _SIZE = processes
    if cls not in _WARM:
        with _helper_environment():  # a helper starts on a submit that finds none idle
            cf.wait([_POOL.submit(_ready, cls) for _ in range(processes)])
        _WARM.add(cls)
    return _POOL


def shutdown() -> None:
    """Stop the helpers (the next parallel fit starts new ones)."""
    global _POOL, _SIZE
    if _POOL is not None:
        _POOL.shutdown(wait=True, cancel_futures=True)
    _POOL, _SIZE = None, 0
    _WARM.clear()


atexit.register(shutdown)


def helper_pids() -> list[int]:
    """Process ids of the live helpers (for their memory)."""
    return [] if _POOL is None else [p.pid for p in list(getattr(_POOL, "_processes", {}).values()) if p.pid]


class HelperDied(RuntimeError):
    """A fit's helper process ended (a crash, os._exit, the out-of-memory killer)."""


_LOST = object()  # a fit whose helper died before it returned


def fit_parallel(model, targets: Sequence, seed: int, processes: int) -> tuple[list[tuple[bool, Any]], int]:
    """(per target: (True, fitted model) or (False, the exception), the helpers' summed peak
    resident bytes during these fits). `model` is an unfitted instance: its class and params
    are what each helper builds. Where a helper dies, every fit that had not returned runs
    again alone in a fresh helper, so that only a fit that kills its helper fails (naming how
    it ended)."""
    with tempfile.TemporaryDirectory(prefix="brdfbench-fit-", dir=_SHM if os.path.isdir(_SHM) else None) as folder:
        shared: list[_Target] = []

        def share(i: int) -> _Target:
            if i == len(shared):
                path = os.path.join(folder, f"{i}.npy")
                np.save(path, targets[i].table.raw)
                shared.append(_Target(targets[i].name, targets[i].category, targets[i].source, path))
            return shared[i]

        out, peak, _ = _round(model, range(len(targets)), share, seed, processes)
        for i in [i for i, r in enumerate(out) if r is _LOST]:
            again, p, cause = _round(model, [i], share, seed, 1)
            peak = max(peak, p)
            out[i] = again[0] if again[0] is not _LOST else (
                False, HelperDied(f"a fit helper process died ({cause}) while fitting this material"))
    return out, peak


def _round(model, indices, share, seed: int, processes: int) -> tuple[list, int, str | None]:
    """The fits of `indices` on `processes` helpers: their outcomes (_LOST where a helper
    died first), the helpers' summed peak memory, and how the helper that died ended (None
    where none did)."""
    pool = ready(type(model), max(1, processes))
    for pid in helper_pids():  # helpers started later count their whole life, their start included
        reset_process_peak(pid)
    futures: list[cf.Future | None] = []
    with _helper_environment():
        # each fit starts as soon as its table is shared, so a helper may die (and break the
        # pool) before the last is submitted: those not submitted are lost like the others
        env, cwd = dict(os.environ), os.getcwd()
        for i in indices:
            target = share(i)
            try:
                futures.append(pool.submit(_fit_one, type(model), dict(model.params), target, seed, env, cwd))
            except BrokenProcessPool:
                futures.append(None)
    out: list = []
    cause = None
    for future in futures:
        try:
            if future is None:
                raise BrokenProcessPool("the pool broke before this fit was submitted")
            out.append(future.result())
        except BrokenProcessPool:
            cause = cause or _death()
            out.append(_LOST)
        except Exception as exc:  # the model or its result did not pickle, and the like
            out.append((False, exc))
    peak = sum(process_peak(pid) or 0 for pid in helper_pids())
    if cause is not None:
        shutdown()
    return out, peak, cause


def _death() -> str:
    """Words for how the first helper that ended on its own ended."""
    # the pool's manager thread reaps the dead helper and terminates the rest; a join from
    # this thread meanwhile can lose the race for the exit status (the child is already
    # reaped, so it reads as none), so its cleanup is awaited first
    manager = getattr(_POOL, "_executor_manager_thread", None)
    if manager is not None:
        manager.join(timeout=30)
    for p in list(getattr(_POOL, "_processes", {}).values()):
        p.join(timeout=1)
        if p.exitcode not in (None, 0, -signal.SIGTERM):  # the pool ends the others with SIGTERM
            return exit_cause(p.exitcode)
    return "no exit status"
