"""The Hydra adapter: the command line checked, Hydra's configs composed, the jobs handed to
the pipeline (`brdfbench.pipeline.sweep`) at the three points of a Hydra multirun.

Every invocation is a multirun (one job or a sweep), and Hydra calls this module three times:

- before the first job, `SweepCallback.on_multirun_start` (configured in config.yaml)
  composes every job as its launcher will (`compose_jobs`) and hands them all to
  `sweep.check_jobs`, so a bad override in any job fails before any work, naming the job;
- for each job, the launcher calls the task function `_app`, which runs the job with
  `sweep.run_one` (on the config and check made at the start where the job runs in this
  process: `prepared`) and records its counts (or its error) in `brdfbench_job.json` in
  its Hydra output folder, so the end of the sweep knows how it went whichever launcher
  ran it;
- after the last job, `SweepCallback.on_multirun_end` hands the jobs' summaries to
  `sweep.finish`, which writes the reports; its status is the exit status.

Validation covers Hydra's basic sweeper and brdfbench's; other sweepers choose their jobs
as they go, and each of those jobs is checked when it starts.
"""

from __future__ import annotations

import json
import os
import sys
import uuid
from pathlib import Path
from typing import Any

import hydra
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from .. import parallelism
from ..cli_help import SUBCOMMANDS
from ..errors import BrdfbenchError
from ..pipeline import sweep
from ..pipeline.config import RunConfig
from ..pipeline.plan import Checked
from .choices import check_group_choices, check_words, compose_error_line
from .jobs import IN_PROCESS, JOB_SUMMARY, TOP_LEVEL, job_overrides, parallel_workers, to_run_config, write_summary

__all__ = ["SweepCallback", "checked_argv", "main", "to_run_config"]

BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"
#: brdfbench's own: the basic sweeper plus a profile's sections (hydra_plugins/brdfbench_sweeper)
SECTION_SWEEPER = "hydra_plugins.brdfbench_sweeper.SectionSweeper"
#: Set for the jobs of a sweep (they inherit it, whichever launcher starts them), so the
#: end of the sweep reads its own jobs' summaries only.
SWEEP_ENV = "BRDFBENCH_SWEEP_ID"
#: Jobs checked at the sweep's start that run in this process: job number → (its task
#: overrides, its config, what its check loaded), each taken once by its job.
PREPARED: dict[int, tuple[list[str], RunConfig, Checked]] = {}
#: Sweeps (by SWEEP_ENV) whose every job was composed and checked at the start: the
#: sweeper need not compose them again to validate its batches (`composed_up_front`).
COMPOSED: set[str] = set()


def sweep_overrides(config: DictConfig) -> list[list[str]] | None:
    """Each job's overrides, as the sweeper will expand them: Hydra's basic sweeper, or
    brdfbench's, which adds a profile's sections (None for other sweepers)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    target = config.hydra.sweeper.get("_target_")
    task = list(config.hydra.overrides.task)
    def plain(node) -> dict:  # a DictConfig, or None / {} where the sweeper has no such key
        return OmegaConf.to_container(node, resolve=False) if OmegaConf.is_config(node) else dict(node or {})

    params = plain(config.hydra.sweeper.get("params"))
    if target == SECTION_SWEEPER:
        sections = plain(config.hydra.sweeper.get("sections"))
        return job_overrides(params, sections, task)
    if target != BASIC_SWEEPER:
        return None
    parsed = OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()] + task)
    return [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]


def runs_here(config: DictConfig, n_jobs: int) -> bool:
    """Whether the sweep's jobs run in this process: Hydra's basic launcher, one job at a
    time (brdfbench's sweeper hands several at once to joblib's processes)."""
    if not str(config.hydra.launcher.get("_target_", "")).endswith("BasicLauncher"):
        return False
    if config.hydra.sweeper.get("_target_") == SECTION_SWEEPER:
        return parallel_workers(config, n_jobs) < 2
    return True


def compose_jobs(config: DictConfig, config_name: str | None,
                 jobs: list[list[str]]) -> list[tuple[str, RunConfig | str, list[str]]]:
    """(its overrides in one line, its config or why it has none, its task overrides) of
    every job, composed as its launcher will compose it: the command line's hydra overrides
    first, the sweep's resolved values (`${now:...}`) kept."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode

    loader = GlobalHydra.instance().config_loader()
    hydra_overrides = list(OmegaConf.to_container(config.hydra.overrides.hydra))
    composed: list[tuple[str, RunConfig | str, list[str]]] = []
    for num, overrides in enumerate(jobs):
        task: list[str] = []
        try:
            job_cfg = loader.load_configuration(config_name=config_name, overrides=hydra_overrides + list(overrides),
                                                run_mode=RunMode.MULTIRUN)
            OmegaConf.copy_cache(from_config=config, to_config=job_cfg)
            task = list(job_cfg.hydra.overrides.task)
            job: RunConfig | str = to_run_config(job_cfg, job=str(num))
        except BrdfbenchError as exc:
            job = str(exc)
        except Exception as exc:  # Hydra's own composition errors name the override
            job = compose_error_line(exc)
        composed.append((" ".join(overrides), job, task))
    return composed


def composed_up_front() -> bool:
    """Whether the running sweep's jobs were all composed (and checked) at its start."""
    return os.environ.get(SWEEP_ENV) in COMPOSED


def prepared(num: int, overrides: list[str]) -> tuple[RunConfig, Checked] | None:
    """Job `num`'s config and check, made at the sweep's start, where they are this job's
    (the same overrides); taken once."""
    entry = PREPARED.pop(num, None)
    if entry is None or entry[0] != list(overrides):
        return None
    return entry[1], entry[2]


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
        PREPARED.clear()
        try:  # resolved now (`${now:...}`), so the jobs composed below share the values their launcher sees
            str(config.hydra.sweep.dir)
        except Exception:
            pass  # the jobs' check names the key
        jobs = sweep_overrides(config)
        self.expected = None if jobs is None else len(jobs)
        if jobs is not None:
            # jobs run in other processes (joblib, submitit, Ray) are checked here and again
            # there, once in each process: what a check loads does not cross the boundary
            here = runs_here(config, len(jobs))
            composed = compose_jobs(config, config_name, jobs)
            try:
                ready = sweep.check_jobs([(name, job) for name, job, _ in composed], keep=here)
            except sweep.InvalidSweep as exc:
                for line in exc.lines:
                    print(line, file=sys.stderr, flush=True)
                raise SystemExit(2) from None
            COMPOSED.add(os.environ[SWEEP_ENV])
            if here:
                PREPARED.update({num: (composed[num][2], job, checked) for num, (job, checked) in enumerate(ready)})
        for key, folder in (("results_dir", config.get("results_dir", "results")), ("hydra.sweep.dir", config.hydra.sweep.dir)):
            why = sweep.writable(Path(str(folder)))
            if why:
                PREPARED.clear()
                print(f"brdfbench: error: {key}={folder}: {why}", file=sys.stderr, flush=True)
                raise SystemExit(2)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        PREPARED.clear()  # jobs that never ran (a sweeper that stopped early)
        sweep_dir = Path(config.hydra.sweep.dir)
        sweep_id = os.environ.get(SWEEP_ENV)
        found: dict[str, dict[str, Any]] = {}
        for path in sorted(sweep_dir.glob(f"*/{JOB_SUMMARY}")):
            try:
                summary = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            if summary.get("sweep") == sweep_id:
                found[str(summary.get("job"))] = summary
        for summary in IN_PROCESS:  # jobs run here whose summary file a full disk refused
            if summary.get("sweep") == sweep_id:
                found.setdefault(str(summary.get("job")), summary)
        summaries = [found[k] for k in sorted(found, key=lambda j: (len(j), j))]
        raise SystemExit(sweep.finish(summaries, self.expected))


# --------------------------------------------------------------------------- the task function and the entry


@hydra.main(version_base="1.3", config_path="pkg://brdfbench_conf", config_name="config")
def _app(cfg: DictConfig) -> None:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    job = str(hc.job.num) if multirun else ""
    summary: dict[str, Any] = {"job": job, "overrides": list(hc.overrides.task), "sweep": os.environ.get(SWEEP_ENV)}
    # a job the sweep's start built and checked in this process runs on that; any other (a
    # launcher's own process, another sweeper's job, hydra.mode=RUN) is built and checked here
    ready = prepared(hc.job.num, summary["overrides"]) if multirun else None
    run_cfg, checked = ready or ((lambda: to_run_config(cfg, job=job)), None)
    try:
        sweep.run_one(run_cfg, checked, summary)
    finally:
        write_summary(Path(hc.runtime.output_dir), summary)
    if not multirun:
        raise SystemExit(2 if summary.get("printed") else sweep.finish([summary]))


def checked_argv(argv: list[str]) -> list[str]:
    """The command line as Hydra's parser takes it (`sys.argv`), after the checks Hydra does
    not make: a misspelt word or group choice is a ConfigError naming it."""
    # Hydra's parser takes flags only before the overrides; accept `-m` anywhere, as in
    # `brdfbench harness=render scene=sphere_envmap -m representation=merl,nbrdf`.
    flags = [a for a in argv if a in ("-m", "--multirun")]
    check_words(argv, SUBCOMMANDS, tuple(sorted(TOP_LEVEL)))
    check_group_choices([a for a in argv if not a.startswith("-")])
    return ["brdfbench", *flags, *(a for a in argv if a not in flags)]


#: The entry Hydra wraps: reads `sys.argv` (set it with `checked_argv`), composes, sweeps,
#: and calls back `SweepCallback` and the task function. `brdfbench.cli` calls it, so that
#: Hydra's calls into the sweeper and back into this module all start from the command line.
main = _app
