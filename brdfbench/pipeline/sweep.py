"""A run from its jobs to its report: every job checked before any work, each run (plan →
execute → record), then the reports of their results folders written once.

`run_sweep(jobs)` is all of it in one call. Hydra's adapter (`brdfbench.hydra.app`), whose
launchers start the jobs themselves, takes the same steps one at a time: `check_jobs`
before the first job, `run_one` for each job (with what `check_jobs` loaded, where the job
runs in this process), `finish` after the last.

A job is checked once per process. Cells run in a worker process with a hard time limit: a
plugin that raises, hangs, crashes or is killed becomes a recorded failure row and the
sweep goes on; bad data (a malformed MERL file) stops the job with an error naming it.
Cells already in the store are skipped, so an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import uuid
from pathlib import Path
from typing import Any, Callable, Sequence

from ..errors import BrdfbenchError, os_error
from ..report import write_reports
from ..store.protocol import open_store
from . import plan
from .config import RunConfig
from .environment import ActiveMarker
from .execute import execute, job_state
from .progress import Progress
from .record import JobRecord, Recorder
from .worker import apply_threads, shared_worker

__all__ = ["InvalidSweep", "check_jobs", "finish", "run_job", "run_one", "run_sweep", "writable"]

log = logging.getLogger(__name__)

class InvalidSweep(BrdfbenchError):
    """Jobs that would fail before doing any work; `lines` are what to print, one each."""

    def __init__(self, lines: list[str]):
        super().__init__("\n".join(lines))
        self.lines = lines


def run_sweep(jobs: Sequence[RunConfig]) -> int:
    """Run `jobs` in this process, one after another: all checked first (a bad one stops the
    sweep before any work, naming it), then each run, then the reports of their results
    folders. Returns the exit status: 0, 1 where a cell failed, 2 where a job is invalid or
    stopped with an error."""
    try:
        ready = check_jobs([(job.label, job) for job in jobs])
        for folder in sorted({job.results_dir for job in jobs}):
            why = writable(folder)
            if why:
                raise InvalidSweep([f"brdfbench: error: results_dir={folder}: {why}"])
    except InvalidSweep as exc:
        for line in exc.lines:
            print(line, file=sys.stderr, flush=True)
        return 2
    summaries = [run_one(job, checked, {"job": str(num), "overrides": [job.label]})
                 for num, (job, checked) in enumerate(ready)]
    return finish(summaries, len(jobs))


def check_jobs(jobs: Sequence[tuple[str, RunConfig | str]], keep: bool = True) -> list[tuple[RunConfig, plan.Checked | None]]:
    """Check every job before any runs: (config, what its check loaded) of each, in order.
    `jobs` are (its name in messages, its config or why it has none). `keep=False` lets each
    check's plugins and data go (jobs run in other processes check themselves there).
    Raises InvalidSweep naming every job that fails."""
    ready: list[tuple[RunConfig, plan.Checked | None]] = []
    problems: list[tuple[int, str, str]] = []
    for num, (name, job) in enumerate(jobs):
        if isinstance(job, str):
            problems.append((num, name, job))
            continue
        try:
            checked = plan.check(job)
        except BrdfbenchError as exc:
            problems.append((num, name, str(exc)))
            continue
        except Exception as exc:  # a plugin's own exception: its first line
            problems.append((num, name, next((line.strip() for line in str(exc).splitlines() if line.strip()),
                                             type(exc).__name__)))
            continue
        ready.append((job, checked if keep else None))
    if problems:
        raise InvalidSweep(_invalid(problems, len(jobs)))
    return ready


def _invalid(problems: list[tuple[int, str, str]], expected: int) -> list[str]:
    """A lone job's error, or every job's for the same reason (a key on the command line),
    once; else one line per job and the count."""
    if expected == 1 or (len(problems) == expected and len({p[2] for p in problems}) == 1):
        return [f"brdfbench: error: {problems[0][2]}"]
    return [f"brdfbench: error: job {num} ({name}): {error}" for num, name, error in problems] + \
        [f"brdfbench: {len(problems)} of {expected} job(s) are invalid; nothing was run"]


def run_one(job: RunConfig | Callable[[], RunConfig], checked: plan.Checked | None = None,
            summary: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one job (`job` built now where it is a builder) and fill in its `summary`, which
    `finish` reads: its results folder and store, its counts and label, or the error that
    stopped it (printed here, in one line, as it stopped)."""
    summary = {} if summary is None else summary
    try:
        cfg = job() if callable(job) else job
        summary.update(results_dir=str(cfg.results_dir), store=cfg.store, store_params=cfg.store_params)
        counts = run_job(cfg, checked)
        summary.update(counts, label=cfg.label)
        print(f"{cfg.label}: {counts['done']} done, {counts['skipped']} already in the store, "
              f"{counts['failed']} failed", flush=True)
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
        summary.update(error=str(exc), printed=True)
    except OSError as exc:  # the results folder could not be written (read-only, a full disk)
        message = os_error(exc, "writing the results")
        print(f"brdfbench: error: {message}", file=sys.stderr, flush=True)
        summary.update(error=message, printed=True)
    return summary


def run_job(cfg: RunConfig, checked: plan.Checked | None = None) -> dict[str, int]:
    """Run one job: plan → execute → record; returns counts of cells done, skipped and
    failed. `checked` is the job's check where the caller made it (a sweep's start), so the
    job is not checked again in this process."""
    checked = plan.check(cfg) if checked is None else checked
    store = open_store(cfg.store, cfg.results_dir, cfg.store_params)
    job_plan = plan.make_plan(cfg, checked, store.done_cells)
    progress = Progress(cfg, job_plan.total, job_plan.skipped,
                        unit="set" if checked.harness_cls.scope == "set" else "material")
    record = JobRecord(Recorder(store, job_plan, uuid.uuid4().hex[:12]), progress)
    try:
        if cfg.isolate:
            _run_isolated(cfg, job_plan, record)
        elif job_plan.tasks:
            _run_inline(cfg, job_plan, record)
    finally:
        progress.close()
    return record.counts


def _run_isolated(cfg: RunConfig, job_plan: plan.Plan, record: JobRecord) -> None:
    worker = shared_worker()
    for task in job_plan.tasks:
        record.environment(worker.ensure().threads, worker.device)
        outcome = worker.run(cfg, task, record.cell, record.note, record.environment)
        # a hang or a crash: the task's unfinished cells fail with its cause (and none is ever lost)
        record.unfinished(task, outcome.message or "the worker finished its task without a result for this material")


_INLINE_WARNED: set[str] = set()  # warnings of in-process runs given once per process


def _run_inline(cfg: RunConfig, job_plan: plan.Plan, record: JobRecord) -> None:
    import torch

    log.warning("isolate=false: cells run in this process with no time limit")
    if cfg.harness.memory_limit is not None and "memory_limit" not in _INLINE_WARNED:
        _INLINE_WARNED.add("memory_limit")
        log.warning("isolate=false: harness.memory_limit is not enforced (only a worker process can be stopped)")
    state = job_state(cfg, job_plan.checked)  # the plan's check: the job is not checked again
    if cfg.threads:
        apply_threads(cfg.threads)
    record.environment(torch.get_num_threads(), state.recorded_device)
    marker = ActiveMarker()

    def emit(message: tuple) -> None:
        if message[0] == "cell":
            record.cell(message[1:])
        elif message[0] == "phase" and message[3] is not None:
            record.note(message[3])

    with marker:
        for task in job_plan.tasks:
            execute(cfg, task, state, emit, marker.count)


def finish(summaries: list[dict[str, Any]], expected: int | None = None) -> int:
    """The end of a sweep: write the reports of the summaries' results folders, print the
    totals; returns the exit status (2: a job stopped, left no summary, or a report failed;
    1: a cell failed; else 0).

    Every error is printed once: a lone job's own error (it printed it as it stopped) is not
    repeated, and a report failing on the same store error says nothing new."""
    code = 0
    said = {s["error"] for s in summaries if s.get("error") and s.get("printed") and len(summaries) == 1}
    quiet = bool(said)  # a lone job's error (a full disk, a damaged store) said why the report fails too
    stores = {(s["results_dir"], s.get("store", "sqlite"), json.dumps(s.get("store_params") or {}, sort_keys=True))
              for s in summaries if s.get("results_dir")}
    for folder, store, params in sorted(stores):
        try:
            paths = write_reports(Path(folder), store, json.loads(params))
            print(f"leaderboard: {paths[0]}", flush=True)
        except Exception as exc:  # a damaged store (pandas, sqlite) or a full disk: one line, exit 2
            message = _report_error(exc, folder)
            if not quiet and message not in said:
                print(f"brdfbench: error: {message}", file=sys.stderr, flush=True)
                said.add(message)
            code = 2
    failed = sum(int(s.get("failed", 0)) for s in summaries)
    errors = [s for s in summaries if s.get("error")]
    missing = 0 if expected is None else max(0, expected - len(summaries))
    if len(summaries) > 1 or missing:
        done = sum(int(s.get("done", 0)) for s in summaries)
        skipped = sum(int(s.get("skipped", 0)) for s in summaries)
        print(f"sweep: {len(summaries)} jobs, {done} cells done, {skipped} already in the store, {failed} failed"
              + (f"; {len(errors)} job(s) stopped with an error" if errors else "")
              + (f"; {missing} job(s) left no summary (killed?)" if missing else ""), flush=True)
    for s in errors:
        if len(summaries) == 1 and s["error"] in said:
            continue
        prefix = f"job {s.get('job', '?')} ({' '.join(s.get('overrides', []))}): " if len(summaries) > 1 else ""
        print(f"brdfbench: error: {prefix}{s['error']}", file=sys.stderr, flush=True)
    if errors or missing or code:
        return 2
    return 1 if failed else 0


def _report_error(exc: Exception, folder: str) -> str:
    """One line for a report that could not be written."""
    if isinstance(exc, BrdfbenchError):
        return str(exc)
    if isinstance(exc, OSError):
        return os_error(exc, f"writing the leaderboard of {folder}")
    first = (str(exc).splitlines() or [""])[0]
    return f"{folder}: the leaderboard could not be written: {type(exc).__name__}: {first}"


def writable(folder: Path) -> str | None:
    """Why `folder` (created if missing) cannot take a run's files, or None where it can.

    Checked before any job starts, so a read-only or full results folder is one line
    rather than a traceback halfway through. Folders this made are removed again when it
    fails."""
    made = []
    probe = None
    try:
        for parent in reversed([folder, *folder.parents]):
            if not parent.exists():
                parent.mkdir()
                made.append(parent)
        probe = folder / f".brdfbench-probe-{uuid.uuid4().hex}"
        with open(probe, "wb") as fh:  # some room, not just an inode: a nearly full disk fails here
            fh.write(b"\0" * 65536)
            fh.flush()
            os.fsync(fh.fileno())
        probe.unlink()
        return None
    except OSError as exc:
        if probe is not None:
            try:
                probe.unlink(missing_ok=True)
            except OSError:
                pass
        for path in reversed(made):
            try:
                path.rmdir()
            except OSError:
                pass
        return f"nothing can be written there ({exc.strerror or exc})"
