"""Hydra entry: the command line checked, Hydra's configs composed, each job handed to the
pipeline (`brdfbench.pipeline.sweep`).

Every invocation is a Hydra multirun (one job or a sweep): `brdfbench.hydra.callbacks`
checks every job before the first starts and hands the jobs' summaries to the pipeline's
`finish` at the end. A job records its counts (or its error) in `brdfbench_job.json` in its
Hydra output folder, so the end of the sweep knows how it went whichever launcher ran it.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import hydra
from omegaconf import DictConfig

from ..errors import BrdfbenchError
from .callbacks import SWEEP_ENV, prepared
from .choices import check_group_choices, check_words
from .jobs import to_run_config, TOP_LEVEL, write_summary
from ..pipeline import sweep
from ..cli_help import SUBCOMMANDS

__all__ = ["run_hydra", "to_run_config"]


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


def run_hydra(argv: list[str]) -> int:
    # Hydra's parser takes flags only before the overrides; accept `-m` anywhere, as in
    # `brdfbench harness=render scene=sphere_envmap -m representation=merl,nbrdf`.
    flags = [a for a in argv if a in ("-m", "--multirun")]
    try:
        check_words(argv, SUBCOMMANDS, tuple(sorted(TOP_LEVEL)))
        check_group_choices([a for a in argv if not a.startswith("-")])
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
        return 2
    sys.argv = ["brdfbench", *flags, *(a for a in argv if a not in flags)]
    _app()
    return 0
