"""Execute: one task of a job, a function of the job and the task alone (run in a worker).

It loads the plugins and the data, fits (timed, peak memory), lets the harness measure
(peak memory) — or, for a set-scope harness, trains the job's plugin once and lets the
harness measure each set — and emits messages for the supervisor: `("phase", budget_s, what, note)`
before each step with a time limit (`note`: a line for the progress log where the step is
long work, training or a batch fit; else None), `("cell", material, category,
measurements, status, message)` for each finished material. A plugin fault becomes a
failed cell; bad data (a BrdfbenchError other than a plugin's RenderError) propagates and
stops the job.
Nothing here writes to the store.
"""

from __future__ import annotations

import errno
import logging
import math
import time
import traceback
from dataclasses import dataclass
from typing import Any, Callable

import torch

from .. import device as devices
from .. import artifacts, modelio
from ..errors import BrdfbenchError, ConfigError, DataError, RenderError, os_error
from ..harness import HarnessContext, Measurement
from ..harness.cost import fit_loss, model_size
from . import calibration, fit_pool, plan
from .config import RunConfig
from .memory import peak_rss, reset_peak
from .plan import Checked, Task, config_hash, hashed_config, parallel_fits
from .progress import mode as progress_mode

log = logging.getLogger(__name__)

Emit = Callable[[tuple], None]


@dataclass
class JobState:
    """What a worker builds once per job and reuses for each of its tasks."""

    checked: Checked
    harness: Any
    fitter: Any = None  # one per job: it may carry a shared initialisation across batches
    device: torch.device = devices.CPU  # where the job's plugin computes

    @property
    def recorded_device(self) -> tuple[str, str]:
        """(name, description) of the device the job's figures are computed on, for its rows."""
        used = self.device
        if used.type == "cpu" and self.checked.harness_cls.uses_device and self.harness.context.device is not None:
            used = self.harness.context.device
        return devices.name(used), devices.describe(used)

    def place(self, model):
        """`model` moved to the job's device (where its class declares it)."""
        return model if self.device.type == "cpu" else model.to(self.device)


def job_state(job: RunConfig, checked: Checked | None = None) -> JobState:
    """The job's state, on `checked` where the caller has it (an in-process run). A worker
    process checks the job itself, once per job: what the supervisor loaded (plugins, data)
    does not cross the process boundary."""
    checked = plan.check(job) if checked is None else checked
    asked = devices.resolve(job.device)
    context = HarnessContext(
        scene=checked.scene, metric_specs=checked.metric_specs, seed=job.seed, results_dir=job.results_dir,
        dataset_fingerprint=checked.dataset.fingerprint, representation=job.plugin,
        representation_params=job.plugin_params, scene_name=job.scene, scene_params=job.scene_params,
        config_hash=config_hash(hashed_config(job, checked.harness_cls)), dataset=checked.dataset, label=job.label,
        device=asked,
    )
    return JobState(checked, checked.harness_cls(job.harness, context), device=devices.for_plugin(asked, checked.cls))


#: errno values of a results folder that cannot be written: the job stops, naming the file
_DISK_ERRORS = {errno.ENOSPC, errno.EROFS, errno.EDQUOT}


def _fault(exc: Exception, device: torch.device = devices.CPU) -> str:
    """The failure message of a plugin's exception; bad data (any other BrdfbenchError) is
    re-raised, so that it stops the job naming the file. A device out of memory names the
    device and what was asked for, and frees the cached blocks for the next cell."""
    if devices.out_of_memory(exc):
        message = devices.memory_message(exc, device)
        if device.type == "cuda":
            torch.cuda.empty_cache()
        return message
    if isinstance(exc, (RenderError, NonFinite, fit_pool.HelperDied)):
        return str(exc)
    if isinstance(exc, ConfigError):  # the plugin cannot run so (e.g. too few materials): its cells fail, the sweep goes on
        return str(exc)
    if isinstance(exc, BrdfbenchError):
        raise exc
    if isinstance(exc, OSError) and exc.errno in _DISK_ERRORS:  # the results folder, not the plugin, failed
        raise DataError(os_error(exc, "writing the results")) from None
    return "".join(traceback.format_exception_only(type(exc), exc)).strip()


def _limit(job: RunConfig, n: int = 1) -> float | None:
    return None if job.harness.timeout_s is None else job.harness.timeout_s * n


def execute(job: RunConfig, task: Task, state: JobState, emit: Emit, concurrency: Callable[[], int] = lambda: 1) -> None:
    """Run `task`, emitting one cell message per material or set (see the module docstring)."""
    speed = calibration.measure()  # the machine's speed on this task's threads, stored with each cell
    if state.checked.harness_cls.scope == "set":
        return _execute_sets(job, task, state, emit, concurrency, speed)
    dataset, spec = state.checked.dataset, state.checked.spec
    trained, extra = None, [speed]
    if task.train is not None:
        what = f"training {job.label} on {len(task.train)} materials"
        emit(("phase", _limit(job), what, what))
        try:
            torch.manual_seed(job.seed)
            trained = state.place(spec.create(**job.representation_params))
            reset_peak()
            t0 = time.perf_counter()
            trained.train((dataset.load(n) for n in task.train), seed=job.seed)
            extra = [Measurement("train_time", time.perf_counter() - t0, "s", False),
                     *_memory("peak_rss_train"), speed]
        except Exception as exc:  # a failed training fails every cell of its fold, and the sweep goes on
            message = "training failed: " + _fault(exc, state.device)
            log.warning("%s: %s", job.label, message)
            return _fail_all(emit, dataset, task.materials, message)
        groups = [(name,) for name in task.materials]
    else:
        if state.fitter is None:
            state.fitter = state.place(spec.create(**job.representation_params))
        groups = [task.materials]
    for chunk in groups:
        _fit_and_measure(job, chunk, state, trained, extra, emit, concurrency)


def _fit_and_measure(job: RunConfig, chunk: tuple[str, ...], state: JobState, trained, extra: list, emit: Emit,
                     concurrency: Callable[[], int]) -> None:
    dataset = state.checked.dataset
    materials = [dataset.load(name) for name in chunk]  # bad data raises DataError: stop, naming the file
    note = f"fitting {job.label} to {len(chunk)} materials at once" if len(chunk) > 1 else None
    emit(("phase", _limit(job, len(chunk)), f"fitting {job.label} to {', '.join(chunk)}", note))
    busy = concurrency()
    processes = min(len(chunk), parallel_fits(job, state.checked.cls, state.device))  # 1 for a trained fold
    fit_extra = [Measurement("fit_batch", float(len(chunk)), "materials", False)] if len(chunk) > 1 else []
    if processes > 1:
        fitted, fit_s, fit_memory = _fit_side_by_side(job, materials, state, processes)
        fit_extra.append(Measurement("fit_workers", float(processes), "processes", False))
        for material, (ok, model) in zip(materials, fitted):
            if ok:
                _measure(job, material, model, state, fit_s, fit_extra + fit_memory, extra, emit, busy, concurrency)
            else:
                message = _fault(model, state.device)
                log.warning("%s failed to fit %s: %s", job.label, material.name, message)
                emit(("cell", material.name, material.category, [], "failed", message, busy))
        return
    try:
        torch.manual_seed(job.seed)
        reset_peak()
        t0 = time.perf_counter()
        if trained is not None:
            models = [trained.fit(materials[0], seed=job.seed)]
        else:
            # the fit's own bar only where the job shows a bar: in `lines` mode bars would garble the log
            progress = f"fitting {len(chunk)} materials" if len(chunk) > 1 and progress_mode(job) == "bar" else False
            models = state.fitter.fit_many(materials, seed=job.seed, progress=progress)
        devices.synchronize(state.device)  # queued device work belongs to the fit's time
        fit_s = (time.perf_counter() - t0) / len(chunk)  # amortised over the batch
        fit_memory = _memory("peak_rss_fit")
        if len(models) != len(chunk):
            raise RuntimeError(f"fit_many returned {len(models)} models for {len(chunk)} materials")
    except Exception as exc:  # a failed fit fails every cell of its batch, and the sweep goes on
        message = _fault(exc, state.device)
        log.warning("%s failed to fit %s: %s", job.label, ", ".join(chunk), message)
        return _fail_all(emit, dataset, chunk, message)
    for material, model in zip(materials, models):
        _measure(job, material, model, state, fit_s, fit_extra + fit_memory, extra, emit, busy, concurrency)


def _fit_side_by_side(job: RunConfig, materials: list, state: JobState, processes: int):
    """(per material (ok, model or exception), fit seconds amortised over them, the fit's
    peak memory: the worker's and its helpers' together), fitting `processes` at a time."""
    fit_pool.ready(type(state.fitter), processes)  # helpers' start-up is not the fit's time
    reset_peak()
    t0 = time.perf_counter()
    fitted, helpers_peak = fit_pool.fit_parallel(state.fitter, materials, job.seed, processes)
    fit_s = (time.perf_counter() - t0) / len(materials)
    own = peak_rss()
    memory = [] if own is None else [Measurement("peak_rss_fit", float(own + helpers_peak), "B", False)]
    return fitted, fit_s, memory


def _measure(job: RunConfig, material, model, state: JobState, fit_s: float, fit_extra: list, extra: list, emit: Emit,
             busy: int, concurrency: Callable[[], int]) -> None:
    """Let the harness measure one fitted material and emit its cell (a failed cell where
    the plugin faults)."""
    dataset = state.checked.dataset
    emit(("phase", _limit(job), f"{job.label} on {material.name}", None))
    try:
        if model.device.type != "cpu" and not state.checked.harness_cls.measures_on_device:
            model = model.to(devices.CPU)
        reset_peak()
        measurements = state.harness.measure(model, material, job.label)
        measurements += _memory("peak_rss_eval")
        measurements.append(Measurement("fit_time", fit_s, "s", False))
        measurements += fit_extra
        measurements += fit_loss(model)
        measurements += extra
        measurements += model_size(model)
        _check_finite(measurements, material.name)
        if job.save_models:
            modelio.save(model, job.representation,
                         artifacts.saved_model_path(job.results_dir, dataset.fingerprint, job.label, material.name))
    except Exception as exc:  # any plugin fault is recorded, and the sweep goes on
        message = _fault(exc, state.device)
        log.warning("%s failed on %s: %s", job.label, material.name, message)
        emit(("cell", material.name, material.category, [], "failed", message, busy))
    else:
        emit(("cell", material.name, material.category, measurements, "ok", "", max(busy, concurrency())))


def _execute_sets(job: RunConfig, task: Task, state: JobState, emit: Emit, concurrency: Callable[[], int],
                  speed: Measurement) -> None:
    """A set-scope task: train the job's plugin once on `task.train`, then measure each set."""
    harness = state.harness
    try:
        model = state.place(state.checked.spec.create(**job.plugin_params))
        what = f"preparing the training data of {job.label} ({len(task.train)} materials)"
        emit(("phase", _limit(job), what, what))
        harness.prepare(model, task.train)
        what = f"training {job.label} on {len(task.train)} materials"
        emit(("phase", _limit(job), what, what))
        torch.manual_seed(job.seed)
        reset_peak()
        t0 = time.perf_counter()
        model = harness.train(model, task.train, job.seed,
                              progress=f"training {job.label}" if progress_mode(job) == "bar" else False)
        devices.synchronize(state.device)
        extra = [Measurement("train_time", time.perf_counter() - t0, "s", False), *_memory("peak_rss_train"), speed]
        if job.save_models:
            modelio.save_generator(model, job.plugin, job.results_dir / "models" / state.checked.dataset.fingerprint
                                   / job.label / "generator.safetensors")
    except Exception as exc:  # a failed training fails every set of the task, and the sweep goes on
        message = "training failed: " + _fault(exc, state.device)
        log.warning("%s: %s", job.label, message)
        for name in task.materials:
            emit(("cell", name, "set", [], "failed", message, 1))
        return
    for name in task.materials:
        emit(("phase", _limit(job), f"{job.label}: {name}", None))
        busy = concurrency()
        try:
            reset_peak()
            measurements = harness.measure_set(model, name) + _memory("peak_rss_eval") + extra
            _check_finite(measurements, name)
        except Exception as exc:  # any plugin fault is recorded, and the sweep goes on
            message = _fault(exc, state.device)
            log.warning("%s failed on %s: %s", job.label, name, message)
            emit(("cell", name, "set", [], "failed", message, busy))
        else:
            emit(("cell", name, "set", measurements, "ok", "", max(busy, concurrency())))


def _fail_all(emit: Emit, dataset, names, message: str) -> None:
    for name in names:
        emit(("cell", name, dataset.category(name), [], "failed", message, 1))


def _memory(metric: str) -> list[Measurement]:
    peak = peak_rss()
    return [] if peak is None else [Measurement(metric, float(peak), "B", False)]


class NonFinite(Exception):
    pass


def _check_finite(measurements: list[Measurement], material: str) -> None:
    """A NaN or infinite figure is the plugin's failure, named by material and metric."""
    for m in measurements:
        if not isinstance(m.value, (int, float)) or not math.isfinite(m.value):
            at = f" at {m.spp} spp" if m.spp else ""
            raise NonFinite(f"non-finite {m.metric}{at} ({m.value!r}) on material {material!r}")
