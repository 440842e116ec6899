"""Plan: a job's cells (configuration × material), validated whole before any work starts.

Validation loads the plugins (never fits or renders): an unknown plugin, key or value
anywhere in the job fails here, naming it. The plan then groups the cells not yet in the
store into tasks, the units a worker executes: a batch of materials fitted together, or
one cross-validation fold (train once, then fit and measure each of its materials).
"""

from __future__ import annotations

import inspect
import logging
from dataclasses import dataclass
from typing import Any, Callable

import torch

from .. import device as devices
from .. import parallelism
from ..plugins import registry
from ..errors import ConfigError
from ..provenance import config_hash
from .config import RunConfig, harness_class

log = logging.getLogger(__name__)


#: Tasks of a representation fitted side by side hold this many materials per helper process.
PARALLEL_ROUNDS = 4


def parallel_fits(job: RunConfig, cls: type, device: torch.device) -> int:
    """How many materials of `job` are fitted side by side (1: one after another in the
    worker): its `fit_workers` (auto: its threads) where `cls.fits_in_parallel` and it fits
    on the CPU."""
    if not getattr(cls, "fits_in_parallel", False) or device.type != "cpu" or cls.needs_training:
        return 1
    return parallelism.fit_processes(job.fit_workers, job.threads or torch.get_num_threads())


@dataclass(frozen=True)
class Task:
    """Materials a worker handles in one go; `train` is the fold's training split, if any."""

    materials: tuple[str, ...]
    train: tuple[str, ...] | None = None


@dataclass
class Checked:
    """A job's plugins, loaded and checked."""

    spec: Any  # the job's model plugin: a representation's or a generator's spec
    cls: type
    probe: Any  # an unfitted instance: proves the parameter values, tells the fit batch size
    harness_cls: type
    scene: Any
    metric_specs: list
    dataset: Any


@dataclass
class Plan:
    job: RunConfig
    checked: Checked
    config_hash: str
    params: dict[str, Any]  # everything behind the hash, resolved
    plugin_version: str
    columns: dict[str, Any]  # typed store columns of every row (scene, sampler)
    tasks: list[Task]
    skipped: int

    @property
    def dataset(self):
        return self.checked.dataset

    @property
    def pending(self) -> int:
        return sum(len(t.materials) for t in self.tasks)

    @property
    def total(self) -> int:
        """Cells of the job: its materials, or its sets for a set-scope harness."""
        return self.pending + self.skipped

    def category(self, cell: str) -> str:
        """The category recorded with a cell: its material's, or "set"."""
        return "set" if self.checked.harness_cls.scope == "set" else self.dataset.category(cell)


def check_params(cls, params: dict[str, Any], where: str, internal: tuple[str, ...] = ()) -> None:
    """Reject parameters the plugin's constructor does not take, naming the key; `internal`
    ones are passed by brdfbench itself, never by a config."""
    if not isinstance(params, dict):
        raise ConfigError(f"{where}={params!r} must be a mapping of parameters")
    for key in params:
        if key in internal:
            hint = " (the top-level key device=... sets it for the whole job)" if key == "device" else ""
            raise ConfigError(f"{where}.{key} is set by brdfbench, not by a config{hint}")
    sig = inspect.signature(cls)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return
    for key in params:
        if key not in sig.parameters:
            allowed = ", ".join(k for k in sig.parameters if k not in internal) or "none"
            raise ConfigError(f"unknown key {where}.{key}; {where} takes: {allowed}")


def check(job: RunConfig) -> Checked:
    """Load and check every plugin the job names, and its data, before any work (once per
    job and process: the caller keeps the result for the job's run)."""
    check_params(registry.get("stores", job.store).load(), job.store_params, "store_params",
                 internal=("results_dir", "create"))
    harness_cls = harness_class(job.harness.kind)
    if harness_cls.plugin_group != job.plugin_group:
        raise ConfigError(_mismatch(harness_cls, job))
    spec = registry.get(job.plugin_group, job.plugin)
    cls = spec.load()
    check_params(cls, job.plugin_params, job.params_key)
    probe = spec.create(**job.plugin_params)  # a bad parameter value fails now, naming it
    probe.preflight()  # and a file it names (init=…) that is missing or unreadable
    scene_factory = registry.get("scenes", job.scene).load()
    check_params(scene_factory, job.scene_params, "scene.params")
    scene = scene_factory(**job.scene_params)
    metric_specs = [registry.get("metrics", m) for m in job.harness.metrics]
    harness_cls.validate(job.harness, scene, metric_specs)
    ds_factory = registry.get("datasets", job.dataset).load()
    check_params(ds_factory, job.dataset_params, "dataset.params", internal=("device",))
    # a dataset that computes (NeuMERL's fits, AugMERL's PCA) takes the job's device: run
    # control, never part of its fingerprint
    placed = {"device": job.device} if "device" in inspect.signature(ds_factory).parameters else {}
    dataset = ds_factory(**job.dataset_params, **placed).subset(None if job.materials is None else list(job.materials), job.limit)
    harness_cls.check_plugin(job.harness, spec, dataset)
    return Checked(spec, cls, probe, harness_cls, scene, metric_specs, dataset)


def _mismatch(harness_cls, job: RunConfig) -> str:
    if harness_cls.plugin_group == "generators":
        return (f"harness={harness_cls.name} measures generators: choose one with generator=NAME "
                f"({', '.join(registry.names('generators')) or 'none registered'})")
    return (f"generator={job.generator} needs a harness that measures generators (harness=generation); "
            f"harness={harness_cls.name} measures representations")


def hashed_config(job: RunConfig, harness_cls) -> dict[str, Any]:
    """What a configuration's hash covers: plugin, parameters, harness and seed (no run control)."""
    head = ({"generator": job.generator} if job.generator else {"representation": job.representation})
    return {**head, "params": job.plugin_params, "seed": job.seed,
            **harness_cls.key(job.harness, job.scene, job.scene_params)}


def make_plan(job: RunConfig, checked: Checked, done_cells: Callable[[str, str, str], set[str]]) -> Plan:
    """The job's tasks over the cells not done yet: `done_cells(config hash, dataset
    fingerprint, scope)` names the materials (or sets) already in the store."""
    params = hashed_config(job, checked.harness_cls)
    chash = config_hash(params)
    dataset = checked.dataset
    done = done_cells(chash, dataset.fingerprint, checked.harness_cls.scope)
    tasks: list[Task] = []
    skipped = 0
    if checked.harness_cls.scope == "set":
        train, sets = checked.harness_cls.plan_sets(job.harness, dataset, job.seed)
        pending = tuple(s for s in sets if s not in done)
        skipped = len(sets) - len(pending)
        tasks = [Task(pending, tuple(train))] if pending else []
    elif checked.cls.needs_training:
        for train, fold in plan_folds(dataset.materials, True, job.harness.folds, job.seed):
            pending = tuple(m for m in fold if m not in done)
            skipped += len(fold) - len(pending)
            if pending:
                tasks.append(Task(pending, tuple(train)))
    else:
        pending = tuple(m for m in dataset.materials if m not in done)
        skipped = len(dataset.materials) - len(pending)
        probe = checked.probe
        placed = devices.for_plugin(devices.resolve(job.device), checked.cls)
        if placed.type != "cpu":  # a plugin may fit more materials at once on a GPU
            probe.to(placed)
        batch = max(1, int(probe.fit_batch_size))
        processes = parallel_fits(job, checked.cls, placed)
        if processes > 1:  # a round of side-by-side fits per helper and task
            batch = max(batch, processes * PARALLEL_ROUNDS)
        tasks = [Task(pending[i:i + batch]) for i in range(0, len(pending), batch)]
    return Plan(job, checked, chash, params, registry.version(job.plugin_group, job.plugin),
                checked.harness_cls.columns(job.harness, checked.scene), tasks, skipped)


def plan_folds(materials: tuple[str, ...], needs_training: bool, folds: int, seed: int) -> list[tuple[list[str] | None, list[str]]]:
    """(training materials, materials to fit) pairs.

    A representation without training fits every material in one pass. One that trains
    is cross-validated over `folds` folds: each material is fitted exactly once, by a
    model trained on the other folds, so it is never scored on data it learnt from.
    """
    if not needs_training:
        return [(None, list(materials))]
    if folds < 2 or len(materials) < 2:
        raise ConfigError(
            f"harness.folds={folds} over {len(materials)} materials: cross-validation needs at least 2 folds and 2 materials"
        )
    if folds > len(materials):
        log.warning("harness.folds=%d exceeds the %d materials: using %d folds (leave-one-out)", folds, len(materials), len(materials))
        folds = len(materials)
    order = torch.randperm(len(materials), generator=torch.Generator().manual_seed(seed)).tolist()
    groups = [sorted(materials[i] for i in order[f::folds]) for f in range(folds)]
    return [([m for g in groups if g is not group for m in g], group) for group in groups]
