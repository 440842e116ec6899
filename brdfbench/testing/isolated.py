"""The conformance kit run in a worker process, one check at a time, under a time limit.

`brdfbench check` certifies code it does not trust: a plugin that segfaults, ends the
process (`os._exit`) or hangs must fail the check it is in, not take the command down.
The check names are enumerated by the first worker from the kit (`representation_checks`,
`generator_checks`, `sampler_checks`, `metric_checks`, `harness_checks`, `dataset_checks`:
the plugin is never imported by the command itself); the checks run in order in one
spawned worker, which keeps the kit's context (the fitted model) from one check to the
next. When the worker dies or a check overruns `timeout_s` (the worker is then killed
with SIGKILL, which a plugin cannot ignore), that check fails naming the cause and a
fresh worker goes on with the next one.

The worker is started as the benchmark's cell workers are (`brdfbench.pipeline.worker`):
`spawn`, the caller's environment variables, working folder and in-process plugin
registrations, and it dies with its parent.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from dataclasses import dataclass
from typing import Callable

from ..plugins import registry
from ..pipeline.processes import die_with_parent as _die_with_parent
from ..pipeline.processes import exit_cause
from ..pipeline.processes import sync_environment as _sync_environment
from ..pipeline.worker import START_TIMEOUT_S, _main_module_hidden
from ..sampling.chi2 import Unresolvable
from . import datasets as dataset_kit
from . import generators as generator_kit
from . import harnesses as harness_kit
from . import kit as representation_kit
from . import metrics as metric_kit
from . import samplers as sampler_kit
from .kit import DEFAULT_PAIRS, Check, ConformanceReport

#: Seconds a check may run by default (`brdfbench check --timeout`).
DEFAULT_TIMEOUT_S = 600.0
KINDS = ("representation", "generator", "sampler", "metric", "harness", "dataset")


def _checks(kind: str, name: str, n_pairs: int, full: bool, params: dict | None = None) -> tuple[list[Check], dict]:
    """The kit's checks for the plugin, and the constructor arguments (or config keys) they
    use; `params` override them."""
    if kind == "generator":
        spec = generator_kit._resolve(name)
        return generator_kit.generator_checks(spec, params=params, full=full), generator_kit.kit_params(spec, params, full=full)
    if kind == "sampler":
        return (sampler_kit.sampler_checks(sampler_kit._resolve(name), params=params, sweep="full" if full else "quick",
                                           n_pairs=n_pairs), dict(params or {}))
    if kind == "metric":
        return metric_kit.metric_checks(name, full=full), {}  # check_isolated refuses params for a metric
    if kind == "harness":
        return harness_kit.harness_checks(name, params=params, full=full), dict(params or {})
    if kind == "dataset":
        return dataset_kit.dataset_checks(name, params, full=full), dict(params or {})
    spec = representation_kit._resolve(name)
    return (representation_kit.representation_checks(spec, params=params, n_pairs=n_pairs, full=full),
            representation_kit.kit_params(spec, params, full))


def check_isolated(kind: str, name: str, *, n_pairs: int = DEFAULT_PAIRS, full: bool = False,
                   params: dict | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
                   on_result: Callable[[str, str, float], None] | None = None) -> ConformanceReport:
    """Run the kit on plugin `name` of `kind` (one of KINDS), each check in a worker process
    limited to `timeout_s`; a check the worker died or overran in is "failed" (or
    "xfailed", if declared) with the cause. `on_result(check, outcome, seconds)` is called
    as each check ends. The plugin is imported in the workers only: one that crashes on
    import fails the pseudo-check `load`, naming the cause."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    if params and kind == "metric":
        raise ValueError(f"a metric takes no parameters: {sorted(params)}")
    job = (kind, name, n_pairs, full, dict(params or {}))
    worker: _CheckWorker | None = _CheckWorker(job)
    started = time.monotonic()
    failure = worker.start()
    if failure is not None:
        report = ConformanceReport(name)
        report.outcomes["load"], report.details["load"] = "failed", failure
        if on_result:
            on_result("load", "failed", time.monotonic() - started)
        return report
    checks, spec_name, params = worker.checks, worker.spec_name, worker.params
    report = ConformanceReport(spec_name, params=params)
    finished = False
    try:
        for i, check in enumerate(checks):
            started = time.monotonic()
            if worker is None:
                worker = _CheckWorker(job)
                failure = worker.start()
                if failure is not None:  # no check can run: each one left says why
                    worker = None
                    for left in checks[i:]:
                        _fail(report, left, f"not run: {failure}")
                        if on_result:
                            on_result(left.name, report.outcomes[left.name], 0.0)
                    break
            outcome, detail, crashed = worker.run(check.name, timeout_s)
            if crashed:
                worker = None  # the next check gets a fresh worker
                _fail(report, check, detail)
            else:
                report.outcomes[check.name] = outcome
                if detail is not None:
                    report.details[check.name] = detail
            if on_result:
                on_result(check.name, report.outcomes[check.name], time.monotonic() - started)
        finished = True
    finally:
        if worker is not None:  # cut short (Ctrl-C): the worker may be mid-check, so it is killed
            worker.stop(kill=not finished)
    return report


@dataclass(frozen=True)
class _Listed:
    """A check as the worker lists it: its name and declared expected failure."""

    name: str
    xfail_reason: str | None


def _fail(report: ConformanceReport, check: _Listed, why: str) -> None:
    """Record `check` as failed (xfailed where declared) because of `why`, as the kit would."""
    report.outcomes[check.name] = "xfailed" if check.xfail_reason else "failed"
    report.details[check.name] = (f"expected: {check.xfail_reason}; " if check.xfail_reason else "") + why


class _CheckWorker:
    """One spawned worker holding one plugin's kit context; `run(check, timeout_s)` runs a
    check in it and returns (outcome, detail, crashed)."""

    def __init__(self, job: tuple):
        self.job = job
        self.process = None
        self.conn = None
        self.checks: list[_Listed] = []  # what the worker built, in order
        self.spec_name = job[1]
        self.params: dict = {}

    def start(self) -> str | None:
        """Start the worker and have it build the checks; None, or why it could not."""
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker_main, args=(child,), name="brdfbench-check", daemon=False)
        with _main_module_hidden():
            self.process.start()
        child.close()
        self.conn = parent
        parent.send((dict(os.environ), os.getcwd(), registry.snapshot(), self.job))
        try:
            if not parent.poll(START_TIMEOUT_S):
                self.stop(kill=True)
                return f"the worker process did not start within {START_TIMEOUT_S:g} s"
            msg = parent.recv()
        except (OSError, EOFError):
            cause = self._exit_cause()
            self.stop(kill=True)
            return f"worker died: {cause} while loading the plugin and building its checks"
        if msg[0] != "ready":
            self.stop(kill=True)
            return f"the worker process could not build the checks: {msg[1]}"
        _, listed, self.spec_name, self.params = msg
        self.checks = [_Listed(*c) for c in listed]
        return None

    def run(self, check: str, timeout_s: float) -> tuple[str | None, str | None, bool]:
        try:
            self.conn.send(check)
            ready = self.conn.poll(timeout_s)
        except (OSError, EOFError):
            ready = True  # the worker is gone: recv says so
        if not ready:
            self.stop(kill=True)
            return None, f"exceeded the time limit of {timeout_s:g} s (worker killed)", True
        try:
            _, outcome, detail = self.conn.recv()
        except (OSError, EOFError):
            cause = self._exit_cause()
            self.stop(kill=True)
            return None, f"worker died: {cause} during this check", True
        return outcome, detail, False

    def _exit_cause(self) -> str:
        self.process.join(timeout=10)
        return exit_cause(self.process.exitcode)

    def stop(self, kill: bool = False) -> None:
        """End the worker: ask it to return, or SIGKILL it (`kill`, or when it does not)."""
        if self.process is None:
            return
        if not kill:
            try:
                self.conn.send(None)
            except (OSError, EOFError):
                pass
            self.process.join(timeout=10)
        if self.process.is_alive():
            self.process.kill()
        self.process.join()
        self.conn.close()
        self.process = self.conn = None


# --------------------------------------------------------------------------- inside the worker


def _skips(kind: str) -> tuple[type[BaseException], ...]:
    """Exceptions a kind's checks raise to be reported skipped: a sampler's χ² cell that the
    dtype cannot resolve (`check_sampler` skips it too)."""
    return (Unresolvable,) if kind == "sampler" else ()


def _worker_main(conn) -> None:
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the parent, which kills us
    env, cwd, extra, (kind, name, n_pairs, full, params) = conn.recv()
    _sync_environment(env, cwd)
    registry.restore(extra)
    try:
        built, params = _checks(kind, name, n_pairs, full, params)
        checks = {c.name: c for c in built}
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which fails the checks
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    spec_name = built[0].spec_name if built else name
    conn.send(("ready", [(c.name, c.xfail_reason) for c in built], spec_name, params))
    while True:
        try:
            check = conn.recv()
        except (EOFError, OSError):
            return
        if check is None:
            return
        report = ConformanceReport(name)
        if check in checks:
            report.run(checks[check], skip=_skips(kind))
        else:
            report.outcomes[check] = "failed"
            report.details[check] = "the worker process found no such check"
        conn.send(("result", report.outcomes[check], report.details.get(check)))
