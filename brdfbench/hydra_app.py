"""Hydra entry: compose the packaged configs into a RunConfig and run the job.

Every invocation is a Hydra multirun (one job or a sweep): `brdfbench.hydra_callbacks`
validates every job before the first starts and writes the report once at the end. A
job records its counts (or its error) in `brdfbench_job.json` in its Hydra output folder,
so the end of the sweep knows how it went whichever launcher ran the jobs.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import hydra
from omegaconf import DictConfig

from .errors import BrdfbenchError, os_error
from .hydra_callbacks import finish
from .hydra_choices import check_group_choices, check_words
from .hydra_config import JOB_SUMMARY, to_run_config, write_summary

__all__ = ["JOB_SUMMARY", "run_hydra", "to_run_config"]


@hydra.main(version_base="1.3", config_path="pkg://brdfbench_conf", config_name="config")
def _app(cfg: DictConfig) -> None:
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from .runner import run

    hc = HydraConfig.get()
    multirun = hc.mode == RunMode.MULTIRUN
    job = str(hc.job.num) if multirun else ""
    summary: dict[str, Any] = {"job": job, "overrides": list(hc.overrides.task),
                               "sweep": os.environ.get("BRDFBENCH_SWEEP_ID")}
    try:
        run_cfg = to_run_config(cfg, job=job)
        summary.update(results_dir=str(run_cfg.results_dir), store=run_cfg.store, store_params=run_cfg.store_params)
        counts = run(run_cfg)
        summary.update(counts, label=run_cfg.label)
        print(f"{run_cfg.label}: {counts['done']} done, {counts['skipped']} already in the store, "
              f"{counts['failed']} failed", flush=True)
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
        summary.update(error=str(exc), printed=True)
        if not multirun:
            raise SystemExit(2) from None
    except OSError as exc:  # the results folder could not be written (read-only, a full disk)
        message = os_error(exc, "writing the results")
        print(f"brdfbench: error: {message}", file=sys.stderr, flush=True)
        summary.update(error=message, printed=True)
        if not multirun:
            raise SystemExit(2) from None
    finally:
        write_summary(Path(hc.runtime.output_dir), summary)
    if not multirun:
        raise SystemExit(finish([summary]))


def run_hydra(argv: list[str]) -> int:
    # Hydra's parser takes flags only before the overrides; accept `-m` anywhere, as in
    # `brdfbench harness=render scene=sphere_envmap -m representation=merl,nbrdf`.
    flags = [a for a in argv if a in ("-m", "--multirun")]
    try:
        from .cli_help import SUBCOMMANDS
        from .hydra_config import TOP_LEVEL

        check_words(argv, SUBCOMMANDS, tuple(sorted(TOP_LEVEL)))
        check_group_choices([a for a in argv if not a.startswith("-")])
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
        return 2
    sys.argv = ["brdfbench", *flags, *(a for a in argv if a not in flags)]
    _app()
    return 0
