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
from .hydra_config import JOB_SUMMARY, to_run_config

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
    params = OmegaConf.to_container(config.hydra.sweeper.get("params") or {}, resolve=False)
    if target == SECTION_SWEEPER:
        from hydra_plugins.brdfbench_sweeper import job_overrides

        sections = OmegaConf.to_container(config.hydra.sweeper.get("sections") or {}, resolve=False)
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
            problems.append((num, overrides, str(exc).splitlines()[0]))
    return problems


def finish(summaries: list[dict[str, Any]], expected: int | None = None) -> int:
    """Write the reports of the summaries' results folders; print totals; the exit status."""
    from .report import write_reports

    code = 0
    stores = {(s["results_dir"], s.get("store", "sqlite"), json.dumps(s.get("store_params") or {}, sort_keys=True))
              for s in summaries if s.get("results_dir")}
    for folder, store, params in sorted(stores):
        try:
            paths = write_reports(Path(folder), store, json.loads(params))
            print(f"leaderboard: {paths[0]}", flush=True)
        except BrdfbenchError as exc:
            print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
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
        print(f"brdfbench: error: job {s.get('job', '?')} ({' '.join(s.get('overrides', []))}): {s['error']}",
              file=sys.stderr, flush=True)
    if errors or missing or code:
        return 2
    return 1 if failed else 0


class SweepCallback(Callback):
    def __init__(self) -> None:
        self.expected: int | None = None

    def on_multirun_start(self, config: DictConfig, config_name: str | None = None, **kwargs: Any) -> None:
        os.environ[SWEEP_ENV] = uuid.uuid4().hex
        try:  # the sweep's own keys: one line, not one per job
            parallelism.count("workers", config.get("workers", "auto"))
            parallelism.count("threads", config.get("threads", "auto"))
        except BrdfbenchError as exc:
            print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
            raise SystemExit(2) from None
        jobs = sweep_overrides(config)
        self.expected = None if jobs is None else len(jobs)
        problems = validate_jobs(config, config_name)
        if problems:
            for num, overrides, error in problems:
                print(f"brdfbench: error: job {num} ({' '.join(overrides)}): {error}", file=sys.stderr, flush=True)
            print(f"brdfbench: {len(problems)} of {self.expected} job(s) are invalid; nothing was run",
                  file=sys.stderr, flush=True)
            raise SystemExit(2)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        summaries = []
        for path in sorted(sweep_dir.glob(f"*/{JOB_SUMMARY}")):
            try:
                summary = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            if summary.get("sweep") == os.environ.get(SWEEP_ENV):
                summaries.append(summary)
        raise SystemExit(finish(summaries, self.expected))
