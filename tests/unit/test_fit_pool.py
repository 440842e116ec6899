"""Side-by-side fits when a helper dies: whenever it dies (before or after the other fits
were submitted), only the fit that killed it fails; the others run again alone."""

from __future__ import annotations

import concurrent.futures as cf
from concurrent.futures.process import BrokenProcessPool
from types import SimpleNamespace

import numpy as np
import pytest

from brdfbench.pipeline import fit_pool

VICTIM = "b"


class Model:
    params: dict = {}


class BreaksOnTheVictim:
    """A pool whose helper dies on VICTIM's fit: that future fails, and every submit after it
    raises (as a real pool does once broken), when `breaks_at_submit`."""

    def __init__(self, breaks_at_submit: bool):
        self.broken, self.breaks_at_submit = False, breaks_at_submit

    def submit(self, fn, cls, params, target, seed, env, cwd):
        if self.broken:
            raise BrokenProcessPool("a child process terminated abruptly")
        future = cf.Future()
        if target.name == VICTIM:
            future.set_exception(BrokenProcessPool("a child process terminated abruptly"))
            self.broken = self.breaks_at_submit
        else:
            future.set_result((True, f"fitted {target.name}"))
        return future


@pytest.mark.parametrize("breaks_at_submit", [False, True])
def test_only_the_fit_that_killed_its_helper_fails(monkeypatch, breaks_at_submit):
    monkeypatch.setattr(fit_pool, "ready", lambda cls, processes: BreaksOnTheVictim(breaks_at_submit))
    monkeypatch.setattr(fit_pool, "helper_pids", lambda: [])
    monkeypatch.setattr(fit_pool, "shutdown", lambda: None)
    monkeypatch.setattr(fit_pool, "_death", lambda: "segmentation fault (SIGSEGV)")
    targets = [SimpleNamespace(name=n, category="c", source="s", table=SimpleNamespace(raw=np.zeros(3)))
               for n in ("a", VICTIM, "c", "d")]
    out, _ = fit_pool.fit_parallel(Model(), targets, seed=0, processes=2)
    assert [ok for ok, _ in out] == [True, False, True, True]
    assert [v for ok, v in out if ok] == ["fitted a", "fitted c", "fitted d"]
    died = out[1][1]
    assert isinstance(died, fit_pool.HelperDied) and "segmentation fault (SIGSEGV)" in str(died)


class _Reaped:
    """A helper that the pool's manager thread has reaped but whose exit status it has not yet
    recorded: a join from another thread finds no status until the manager's cleanup ends."""

    def __init__(self):
        self.exitcode = None

    def join(self, timeout=None):
        pass


def test_the_exit_status_is_read_after_the_pools_cleanup(monkeypatch):
    import signal
    import threading
    import time

    helper = _Reaped()

    def cleanup():  # the manager thread: terminate_broken, then the joins that record the status
        time.sleep(0.3)
        helper.exitcode = -signal.SIGSEGV

    manager = threading.Thread(target=cleanup)
    monkeypatch.setattr(fit_pool, "_POOL", SimpleNamespace(_processes={1: helper}, _executor_manager_thread=manager))
    manager.start()
    assert fit_pool._death() == "segmentation fault (SIGSEGV)"
