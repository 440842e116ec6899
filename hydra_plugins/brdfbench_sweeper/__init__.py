"""Hydra sweeper plugin: Hydra's basic sweeper plus a profile's extra sections.

A profile (`conf/profile/*.yaml`) names the jobs of a plain `brdfbench`: the main sweep
(`hydra.sweeper.params`, expanded exactly as Hydra's basic sweeper does) and, in
`hydra.sweeper.sections`, further sweeps of their own (e.g. a few representations rendered
under an environment map), each a mapping of override keys to values (sweep syntax
allowed). A section's jobs run after the main sweep's, with the command line's overrides
applied on top. Where the command line chooses what to measure itself (it sets
`representation`, `generator`, `harness` or `scene`), the sections are left out: `brdfbench
representation=lambert` is that one job.

With Hydra's basic launcher (the default) and more than one job, `workers` jobs run at once
(brdfbench.parallelism: auto is one at a time below four cores) in joblib's process pool,
each on `threads` torch threads; every cell records its threads and how many brdfbench
workers ran beside it, and `workers=1` runs the jobs one after another on every core.
"""

from __future__ import annotations

from typing import Any, Mapping

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.override_parser.overrides_parser import OverridesParser

from brdfbench.hydra.jobs import basic_launcher, job_overrides, override_key, parallel_workers

__all__ = ["SectionSweeper", "job_overrides", "parallel_workers"]

class SectionSweeper(BasicSweeper):
    """Hydra's basic sweeper over the main sweep and a profile's sections, in one batch;
    parallel jobs where the machine has the cores (see the module docstring)."""

    def __init__(self, max_batch_size: int | None = None, params: Mapping[str, str] | None = None,
                 sections: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        super().__init__(max_batch_size=max_batch_size, params=dict(params or {}))
        self.sections = {k: dict(v or {}) for k, v in (sections or {}).items()}
        self.task_function = None

    def setup(self, *, hydra_context, task_function, config) -> None:
        super().setup(hydra_context=hydra_context, task_function=task_function, config=config)
        self.task_function = task_function

    def _parallel(self, jobs: list[list[str]]) -> tuple[Any, list[list[str]]]:
        """The launcher for `jobs` and their overrides: joblib's pool with each job's thread
        count where several jobs run at once, else the configured launcher unchanged."""
        import os

        from brdfbench import parallelism

        workers = parallel_workers(self.config, len(jobs)) if basic_launcher(self.launcher) else 1
        if workers < 2:
            return self.launcher, jobs
        from hydra_plugins.hydra_joblib_launcher.joblib_launcher import JoblibLauncher

        _, threads = parallelism.resolve(self.config.get("workers", "auto"), self.config.get("threads", "auto"), len(jobs))
        launcher = JoblibLauncher(n_jobs=workers, backend="loky", prefer="processes", batch_size=1,
                                  pre_dispatch="n_jobs")
        launcher.setup(hydra_context=self.hydra_context, task_function=self.task_function, config=self.config)
        os.environ[parallelism.LAUNCHER_ENV] = f"parallel:{workers}"
        print(f"brdfbench: {len(jobs)} jobs, {workers} at a time on {threads} threads each "
              "(workers=1: one at a time, exclusive timings)", flush=True)
        given = any(override_key(a) == "threads" for a in jobs[0]) if jobs else True
        return launcher, jobs if given else [job + [f"threads={threads}"] for job in jobs]

    def sweep(self, arguments: list[str]) -> Any:
        import os
        from pathlib import Path

        from omegaconf import OmegaConf

        from brdfbench import parallelism
        from brdfbench.hydra.app import composed_up_front

        assert self.config is not None and self.launcher is not None and self.hydra_context is not None
        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        jobs = job_overrides(self.params, self.sections, arguments, parser)
        before = os.environ.get(parallelism.LAUNCHER_ENV)  # _parallel names the pool for the jobs only
        try:
            launcher, jobs = self._parallel(jobs)
            self.overrides = list(BasicSweeper.split_overrides_to_chunks(jobs, self.max_batch_size))
            sweep_dir = Path(self.config.hydra.sweep.dir)
            sweep_dir.mkdir(parents=True, exist_ok=True)
            OmegaConf.save(self.config, sweep_dir / "multirun.yaml")
            returns, index = [], 0
            while not self.is_done():
                batch = self.get_job_batch()
                if not composed_up_front():  # else the sweep's start composed every job already
                    self.validate_batch_is_legal(batch)
                results = launcher.launch(batch, initial_job_idx=index)
                for r in results:
                    _ = r.return_value  # raise a job's exception here, as the basic sweeper does
                index += len(batch)
                returns.append(results)
            return returns
        finally:
            if before is None:
                os.environ.pop(parallelism.LAUNCHER_ENV, None)
            else:
                os.environ[parallelism.LAUNCHER_ENV] = before
