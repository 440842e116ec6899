"""The sweep's bookends (a Hydra Callback, configured in config.yaml).

- Before the first job: compose every job of the sweep and validate it (plugins, keys,
  values, data), so a bad override in any job fails before any work, naming the job.
- After the last job: write the leaderboard once per results folder, print the sweep's
  totals, and exit non-zero when a job failed (2) or any cell failed (1).
Validation covers Hydra's basic sweeper (the default); other sweepers choose their jobs
as they go, and each of those jobs is validated when it starts.
"""

from __future__ import annotations

import json
import os
import sys
import uuid
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from . import parallelism
from .errors import BrdfbenchError
from .hydra_config import IN_PROCESS, JOB_SUMMARY, to_run_config

BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"
#: brdfbench's own: the basic sweeper plus a profile's sections (hydra_plugins/brdfbench_sweeper)
SECTION_SWEEPER = "hydra_plugins.brdfbench_sweeper.SectionSweeper"
#: Set for the jobs of a sweep (they inherit it, whichever launcher starts them), so the
#: end of the sweep reads its own jobs' summaries only.
SWEEP_ENV = "BRDFBENCH_SWEEP_ID"


def sweep_overrides(config: DictConfig) -> list[list[str]] | None:
    """Each job's overrides, as the sweeper will expand them: Hydra's basic sweeper, or
    brdfbench's, which adds a profile's sections (None for other sweepers)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    target = config.hydra.sweeper.get("_target_")
    task = list(config.hydra.overrides.task)
    def plain(node) -> dict:  # a DictConfig, or None / {} where the sweeper has no such key
        return OmegaConf.to_container(node, resolve=False) if OmegaConf.is_config(node) else dict(node or {})

    params = plain(config.hydra.sweeper.get("params"))
    if target == SECTION_SWEEPER:
        from hydra_plugins.brdfbench_sweeper import job_overrides

        sections = plain(config.hydra.sweeper.get("sections"))
        return job_overrides(params, sections, task)
    if target != BASIC_SWEEPER:
        return None
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()] + task)
    return [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]


def validate_jobs(config: DictConfig, config_name: str | None) -> list[tuple[int, list[str], str]]:
    """(job number, overrides, error) of every job that would fail before doing any work."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode

    from .pipeline.plan import check, precheck

    jobs = sweep_overrides(config)
    if jobs is None:
        return []
    loader = GlobalHydra.instance().config_loader()
    problems = []
    for num, overrides in enumerate(jobs):
        try:
            job_cfg = loader.load_configuration(config_name=config_name, overrides=overrides, run_mode=RunMode.MULTIRUN)
            job = to_run_config(job_cfg)
            # a job run in this process (the basic launcher) takes its validation with it
            (precheck if config.hydra.launcher.get("_target_", "").endswith("BasicLauncher") else check)(job)
        except BrdfbenchError as exc:
            problems.append((num, overrides, str(exc)))
        except Exception as exc:  # Hydra's own composition errors name the override
            from .hydra_choices import compose_error_line

            problems.append((num, overrides, compose_error_line(exc)))
    return problems


def finish(summaries: list[dict[str, Any]], expected: int | None = None) -> int:
    """Write the reports of the summaries' results folders; print totals; the exit status.

    Every error is printed once: a lone job's own error (it printed it as it stopped) is not
    repeated, and a report failing on the same store error says nothing new."""
    from .report import write_reports

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
    from .errors import os_error

    if isinstance(exc, BrdfbenchError):
        return str(exc)
    if isinstance(exc, OSError):
        return os_error(exc, f"writing the leaderboard of {folder}")
    first = (str(exc).splitlines() or [""])[0]
    return f"{folder}: the leaderboard could not be written: {type(exc).__name__}: {first}"


def writable(folder: Path) -> str | None:
    """Why `folder` (created if missing) cannot take a run's files, or None where it can.

    Hydra writes its sweep folder before any job starts, so a read-only or full results
    folder is found here, with one line, rather than in Hydra's traceback. Folders this
    made are removed again when it fails."""
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


class SweepCallback(Callback):
    def __init__(self) -> None:
        self.expected: int | None = None

    def on_multirun_start(self, config: DictConfig, config_name: str | None = None, **kwargs: Any) -> None:
        os.environ[SWEEP_ENV] = uuid.uuid4().hex
        try:  # the sweep's own keys: one line, not one per job
            parallelism.count("workers", config.get("workers", "auto"))
            parallelism.count("threads", config.get("threads", "auto"))
            parallelism.count("fit_workers", config.get("fit_workers", "auto"))
        except BrdfbenchError as exc:
            print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
            raise SystemExit(2) from None
        IN_PROCESS.clear()
        jobs = sweep_overrides(config)
        self.expected = None if jobs is None else len(jobs)
        problems = validate_jobs(config, config_name)
        if problems:
            if self.expected == 1 or (len(problems) == self.expected and len({p[2] for p in problems}) == 1):
                # a lone job, or every job for the same reason (a key on the command line): the error once
                print(f"brdfbench: error: {problems[0][2]}", file=sys.stderr, flush=True)
                raise SystemExit(2)
            for num, overrides, error in problems:
                print(f"brdfbench: error: job {num} ({' '.join(overrides)}): {error}", file=sys.stderr, flush=True)
            print(f"brdfbench: {len(problems)} of {self.expected} job(s) are invalid; nothing was run",
                  file=sys.stderr, flush=True)
            raise SystemExit(2)
        for key, folder in (("results_dir", config.get("results_dir", "results")), ("hydra.sweep.dir", config.hydra.sweep.dir)):
            why = writable(Path(str(folder)))
            if why:
                print(f"brdfbench: error: {key}={folder}: {why}", file=sys.stderr, flush=True)
                raise SystemExit(2)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        sweep = os.environ.get(SWEEP_ENV)
        found: dict[str, dict[str, Any]] = {}
        for path in sorted(sweep_dir.glob(f"*/{JOB_SUMMARY}")):
            try:
                summary = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            if summary.get("sweep") == sweep:
                found[str(summary.get("job"))] = summary
        for summary in IN_PROCESS:  # jobs run here whose summary file a full disk refused
            if summary.get("sweep") == sweep:
                found.setdefault(str(summary.get("job")), summary)
        summaries = [found[k] for k in sorted(found, key=lambda j: (len(j), j))]
        raise SystemExit(finish(summaries, self.expected))
