"""One benchmark job: plan → execute → record (see `brdfbench.pipeline`).

The whole job is validated before any work; cells already in the store are skipped, so an
interrupted run resumes where it stopped. Cells run in a worker process with a hard time
limit: a plugin that raises, hangs, crashes or is killed becomes a recorded failure row
and the sweep goes on; bad data (a malformed MERL file) stops the job with an error
naming it.
"""

from __future__ import annotations

import logging
import uuid

from . import artifacts

from .pipeline.config import RunConfig, harness_config
from .pipeline.environment import ActiveMarker, environment
from .pipeline.execute import execute, job_state
from .pipeline.plan import check, make_plan, plan_folds
from .pipeline.progress import Progress
from .pipeline.record import Recorder
from .pipeline.worker import apply_threads, shared_worker

__all__ = ["RunConfig", "harness_config", "plan_folds", "run"]

log = logging.getLogger(__name__)


def run(cfg: RunConfig) -> dict[str, int]:
    """Run one job; returns counts of cells done, skipped and failed."""
    checked = check(cfg)
    store = cfg.open_store()
    plan = make_plan(cfg, checked, store.done_cells)
    recorder = Recorder(store, plan, uuid.uuid4().hex[:12])
    counts = {"done": 0, "skipped": plan.skipped, "failed": 0}
    progress = Progress(cfg, plan.total, plan.skipped, unit="set" if checked.harness_cls.scope == "set" else "material")

    def on_cell(message: tuple) -> None:
        material, category, measurements, status, text, concurrent = message
        try:
            recorder.cell(material, category, measurements, status, text, concurrent)
        except Exception:  # not stored (a full disk): leave no file of a cell the store does not hold
            artifacts.discard(cfg.results_dir, plan.config_hash, material)
            if cfg.save_models and not cfg.generator:
                artifacts.saved_model_path(cfg.results_dir, plan.dataset.fingerprint, cfg.label, material).unlink(missing_ok=True)
            raise
        counts["done" if status == "ok" else "failed"] += 1
        if status != "ok":
            log.warning("%s on %s failed: %s", cfg.label, material, text)
        progress.cell(material, status, measurements)

    try:
        if cfg.isolate:
            _run_isolated(cfg, plan, recorder, on_cell, progress.note)
        elif plan.tasks:
            _run_inline(cfg, plan, recorder, on_cell, progress.note)
    finally:
        progress.close()
    return counts


def _run_isolated(cfg: RunConfig, plan, recorder: Recorder, on_cell, on_note) -> None:
    worker = shared_worker()
    for task in plan.tasks:
        finished: set[str] = set()

        def cell(message: tuple) -> None:
            finished.add(message[0])
            on_cell(message)

        recorder.environment(environment(worker.ensure().threads, cfg.launcher, worker.device))
        outcome = worker.run(cfg, task, cell, on_note,
                             on_device=lambda device: recorder.environment(environment(worker.threads, cfg.launcher, device)))
        # a hang or a crash: the task's unfinished cells fail with its cause (and none is ever lost)
        message = outcome.message or "the worker finished its task without a result for this material"
        for name in task.materials:
            if name not in finished:
                on_cell((name, plan.category(name), [], "failed", message, 1))


_INLINE_WARNED: set[str] = set()  # warnings of in-process runs given once per process


def _run_inline(cfg: RunConfig, plan, recorder: Recorder, on_cell, on_note) -> None:
    import torch

    log.warning("isolate=false: cells run in this process with no time limit")
    if cfg.harness.memory_limit is not None and "memory_limit" not in _INLINE_WARNED:
        _INLINE_WARNED.add("memory_limit")
        log.warning("isolate=false: harness.memory_limit is not enforced (only a worker process can be stopped)")
    state = job_state(cfg)
    if cfg.threads:
        apply_threads(cfg.threads)
    recorder.environment(environment(torch.get_num_threads(), cfg.launcher, state.recorded_device))
    marker = ActiveMarker()

    def emit(message: tuple) -> None:
        if message[0] == "cell":
            on_cell(message[1:])
        elif message[0] == "phase" and message[3] is not None:
            on_note(message[3])

    with marker:
        for task in plan.tasks:
            execute(cfg, task, state, emit, marker.count)
