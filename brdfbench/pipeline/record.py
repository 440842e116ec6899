"""Record: the only writer of a job's results, one transaction per cell.

It stores the configuration behind the job's hash and the environment once, then turns
each cell message from the executor into typed rows (a failed cell is one `error` row
naming the cause).
"""

from __future__ import annotations

from .. import __version__
from ..harness import Measurement
from ..provenance import git_sha
from ..store.sqlite import now
from ..store.protocol import ConfigRecord, Environment, Row, Store
from .plan import Plan


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
