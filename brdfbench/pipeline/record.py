"""Record: the only writer of a job's results, one transaction per cell.

`Recorder` stores the configuration behind the job's hash and the environment once, then
turns each cell message from the executor into typed rows (a failed cell is one `error` row
naming the cause). `JobRecord` is what the executor talks to, in a worker or in this
process: each cell written, counted and shown, and the environment it was measured in, so
that control passes from the sweep to the executor to here and never back.
"""

from __future__ import annotations

import logging
from typing import Any

from .. import __version__, artifacts
from ..harness import Measurement
from ..provenance import git_sha
from ..store.sqlite import now
from ..store.protocol import ConfigRecord, Environment, Row, Store
from .environment import environment
from .plan import Plan, Task

log = logging.getLogger(__name__)


class Recorder:
    def __init__(self, store: Store, plan: Plan, run_id: str):
        self.store = store
        self.plan = plan
        self.run_id = run_id
        self.env_id = ""
        job = plan.job
        store.write_config(ConfigRecord(plan.config_hash, job.label, job.plugin, plan.plugin_version,
                                        job.harness.kind, plan.params))

    def environment(self, env: Environment) -> None:
        if env.env_id != self.env_id:
            self.store.write_environment(env)
            self.env_id = env.env_id

    def cell(self, material: str, category: str, measurements: list[Measurement], status: str, message: str,
             concurrent: int) -> bool:
        """Write one cell; False when another writer had finished it first."""
        plan, job = self.plan, self.plan.job
        common = dict(
            run_id=self.run_id, config_hash=plan.config_hash, dataset=job.dataset,
            dataset_fingerprint=plan.dataset.fingerprint, material=material, category=category, seed=job.seed,
            package_version=__version__, git_sha=git_sha(), timestamp=now(), scope=plan.checked.harness_cls.scope,
            env_id=self.env_id or "unknown", concurrent_jobs=int(concurrent), **plan.columns,
        )
        if status == "ok":
            rows = [Row(metric=m.metric, value=m.value, unit=m.unit, higher_is_better=m.higher_is_better, spp=m.spp,
                        distance=m.distance, status="ok", message="",
                        **{**common, "category": common["category"] if m.category is None else m.category})
                    for m in measurements]
        else:
            rows = [Row(metric="error", value=None, unit="", higher_is_better=False, status="failed", message=message,
                        **common)]
        return self.store.write_cell(rows)


class JobRecord:
    """One job's cells as they arrive: written by `recorder` (for its plan's job), counted
    (`counts`), shown by `progress` (`brdfbench.pipeline.progress.Progress`)."""

    def __init__(self, recorder: Recorder, progress: Any):
        self.recorder, self.progress = recorder, progress
        self.plan = plan = recorder.plan
        self.cfg = plan.job
        self.counts = {"done": 0, "skipped": plan.skipped, "failed": 0}
        self.finished: set[str] = set()

    def cell(self, message: tuple) -> None:
        """A cell message from the executor: (material, category, measurements, status, text,
        concurrent jobs)."""
        material, category, measurements, status, text, concurrent = message
        cfg, plan = self.cfg, self.plan
        self.finished.add(material)
        try:
            self.recorder.cell(material, category, measurements, status, text, concurrent)
        except Exception:  # not stored (a full disk): leave no file of a cell the store does not hold
            artifacts.discard(cfg.results_dir, plan.config_hash, material)
            if cfg.save_models and not cfg.generator:
                artifacts.saved_model_path(cfg.results_dir, plan.dataset.fingerprint, cfg.label, material).unlink(missing_ok=True)
            raise
        self.counts["done" if status == "ok" else "failed"] += 1
        if status != "ok":
            log.warning("%s on %s failed: %s", cfg.label, material, text)
        self.progress.cell(material, status, measurements)

    def note(self, text: str) -> None:
        """A phase's note (a fit's progress, the set being rendered)."""
        self.progress.note(text)

    def environment(self, threads: int, device: tuple[str, str] = ("cpu", "cpu")) -> None:
        """Where the next cells are measured: `threads` torch threads, on `device`."""
        self.recorder.environment(environment(threads, self.cfg.launcher, device))

    def unfinished(self, task: Task, message: str) -> None:
        """The cells of `task` that sent no result (a hang, a crash), each failed with `message`."""
        for name in task.materials:
            if name not in self.finished:
                self.cell((name, self.plan.category(name), [], "failed", message, 1))
