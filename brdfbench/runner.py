"""One benchmark job: fit one representation to every material of a dataset, measure, store.

A plugin that raises or exceeds the time limit becomes a recorded failure row and the
sweep goes on; bad data (a malformed MERL file) stops the job with an error naming it.
Cells already in the store are skipped, so an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import inspect
import logging
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm.auto import tqdm

from . import __version__, modelio, registry
from .errors import BrdfbenchError, ConfigError, RenderError
from .harness import Measurement
from .harness.accuracy import evaluate_accuracy
from .harness.cost import evaluation_throughput, model_size
from .protocol import FIT_LOSS_KEY
from .provenance import config_hash, git_sha
from .store import ResultsStore, Row, now
from .timeouts import time_limit

log = logging.getLogger(__name__)

DTYPES = {"float32": torch.float32, "float64": torch.float64}


#: Metric domains each harness kind takes from `harness.metrics`. A convergence harness takes
#: none (the list must be empty): it always measures its own per-spp errors and timings.
HARNESS_KINDS = {"accuracy": ("merl_grid", "random_pairs"), "render": ("image",), "convergence": ()}
RENDERED_KINDS = ("render", "convergence")
#: Fields only rendered kinds read, and of those the ones only convergence reads. A kind's
#: config hash leaves out the fields it does not read, so that adding them did not
#: invalidate the cells already in a store.
RENDER_FIELDS = ("kind", "simulator", "backend", "sampler", "sampler_params", "spp", "exposure", "save_images")
CONVERGENCE_FIELDS = ("spp_ladder", "reference_spp")
UNHASHED_FIELDS = {"accuracy": RENDER_FIELDS + CONVERGENCE_FIELDS, "render": CONVERGENCE_FIELDS, "convergence": ()}


@dataclass(frozen=True)
class HarnessConfig:
    kind: str = "accuracy"  # accuracy: BRDF-space metrics; render: image metrics; convergence: error vs spp
    metrics: tuple[str, ...] = ("l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae")
    n_random: int = 2**20
    dtype: str = "float32"
    throughput_batch: int = 2**16
    timeout_s: float | None = 600.0
    folds: int = 4  # cross-validation folds for representations that train on a split
    # rendering (kind: render)
    simulator: str | None = None  # None: the cheapest exact one for the scene
    backend: str | None = None  # mitsuba (JIT) or torch; None: mitsuba where LLVM >= 19 loads
    sampler: str = "cosine"  # BRDF importance sampler of Monte Carlo simulators
    sampler_params: dict[str, Any] = field(default_factory=dict)
    spp: int | None = None  # samples per pixel; None: the scene's
    exposure: float = 0.0  # stops, for tone-mapped (LDR) metrics and PNGs
    save_images: bool = True
    # Monte Carlo convergence (kind: convergence; `metrics` must be empty, `spp` null)
    spp_ladder: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64)  # spp of the rungs, strictly increasing
    reference_spp: int = 1024  # spp of the model's own reference render; above the ladder


@dataclass(frozen=True)
class RunConfig:
    representation: str
    representation_params: dict[str, Any]
    label: str
    dataset: str
    dataset_params: dict[str, Any]
    harness: HarnessConfig = field(default_factory=HarnessConfig)
    scene: str = "brdf_space"
    scene_params: dict[str, Any] = field(default_factory=dict)
    materials: tuple[str, ...] | None = None
    limit: int | None = None
    seed: int = 0
    results_dir: Path = Path("results")
    save_models: bool = False

    @property
    def store_path(self) -> Path:
        return self.results_dir / "brdfbench.sqlite"


def _check_params(cls, params: dict[str, Any], where: str) -> None:
    """Reject parameters the plugin's constructor does not take, naming the key."""
    sig = inspect.signature(cls)
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return
    for key in params:
        if key not in sig.parameters:
            allowed = ", ".join(sig.parameters) or "none"
            raise ConfigError(f"unknown key {where}.{key}; {where} takes: {allowed}")


def run(cfg: RunConfig) -> dict[str, int]:
    """Run one job; returns counts of cells done, skipped and failed."""
    rep_spec = registry.get("representations", cfg.representation)
    rep_cls = rep_spec.load()
    _check_params(rep_cls, cfg.representation_params, "representation.params")
    scene_factory = registry.get("scenes", cfg.scene).load()
    _check_params(scene_factory, cfg.scene_params, "scene.params")
    scene = scene_factory(**cfg.scene_params)
    metric_specs = _metric_specs(cfg.harness, scene)
    if cfg.harness.dtype not in DTYPES:
        raise ConfigError(f"harness.dtype {cfg.harness.dtype!r} must be one of {', '.join(DTYPES)}")
    dtype = DTYPES[cfg.harness.dtype]

    ds_factory = registry.get("datasets", cfg.dataset).load()
    _check_params(ds_factory, cfg.dataset_params, "dataset.params")
    dataset = ds_factory(**cfg.dataset_params).subset(list(cfg.materials) if cfg.materials else None, cfg.limit)

    store = ResultsStore(cfg.store_path)
    chash = config_hash({
        "representation": cfg.representation, "params": cfg.representation_params,
        "harness": _hashed_harness(cfg.harness), "seed": cfg.seed,
        **({"scene": cfg.scene, "scene_params": cfg.scene_params} if scene.needs_rendering else {}),
    })
    measure = _measurer(cfg, scene, metric_specs, dtype, dataset.fingerprint)
    scene_label = _scene_label(cfg)
    run_id = uuid.uuid4().hex[:12]
    counts = {"done": 0, "skipped": 0, "failed": 0}

    def row(material: str, category: str, m: Measurement | None, status="ok", message="") -> Row:
        return Row(
            run_id=run_id, representation=cfg.label, dataset=cfg.dataset, dataset_fingerprint=dataset.fingerprint,
            material=material, category=category, metric=m.metric if m else "error",
            value=m.value if m else None, unit=m.unit if m else "", higher_is_better=m.higher_is_better if m else False,
            status=status, message=message, seed=cfg.seed, config_hash=chash, package_version=__version__,
            git_sha=git_sha(), timestamp=now(), scene=scene_label,
        )

    fitter = None
    bar = tqdm(total=len(dataset), desc=f"{cfg.label} on {cfg.dataset}", unit="material", dynamic_ncols=True)
    for train_names, fit_names in plan_folds(dataset.materials, rep_cls.needs_training, cfg.harness.folds, cfg.seed):
        pending = [n for n in fit_names if not store.has_cell(cfg.label, chash, dataset.fingerprint, n)]
        counts["skipped"] += len(fit_names) - len(pending)
        bar.update(len(fit_names) - len(pending))
        if not pending:
            continue
        trained, extra = None, []
        if train_names is not None:
            bar.set_postfix_str(f"training on {len(train_names)} materials")
            try:
                with time_limit(cfg.harness.timeout_s, f"training {cfg.label}"):
                    torch.manual_seed(cfg.seed)
                    trained = rep_spec.create(**cfg.representation_params)
                    t0 = time.perf_counter()
                    trained.train((dataset.load(n) for n in train_names), seed=cfg.seed)
                    extra = [Measurement("train_time", time.perf_counter() - t0, "s", False)]
            except BrdfbenchError:
                raise
            except Exception as exc:  # a failed training fails every cell of its fold, and the sweep goes on
                log.warning("training %s failed: %s", cfg.label, exc)
                message = "training failed: " + "".join(traceback.format_exception_only(type(exc), exc)).strip()
                for name in pending:
                    store.write_cell([row(name, dataset.category(name), None, "failed", message)])
                    counts["failed"] += 1
                    bar.update(1)
                continue
        if trained is None and fitter is None:
            fitter = rep_spec.create(**cfg.representation_params)  # one per job: it may carry a shared initialisation
        batch = 1 if trained is not None else max(1, int(fitter.fit_batch_size))
        for start in range(0, len(pending), batch):
            chunk = pending[start:start + batch]
            materials = [dataset.load(name) for name in chunk]  # bad data raises DataError: stop, naming the file
            try:
                with time_limit(None if cfg.harness.timeout_s is None else cfg.harness.timeout_s * len(chunk),
                                f"fitting {cfg.label} to {', '.join(chunk)}"):
                    torch.manual_seed(cfg.seed)
                    t0 = time.perf_counter()
                    if trained is not None:
                        models = [trained.fit(materials[0], seed=cfg.seed)]
                    else:  # one fitter per job: state such as a shared initialisation carries across batches
                        progress = f"fitting {len(chunk)} materials" if batch > 1 else False
                        models = fitter.fit_many(materials, seed=cfg.seed, progress=progress)
                    fit_s = (time.perf_counter() - t0) / len(chunk)  # amortised over the batch
                    if len(models) != len(chunk):
                        raise RuntimeError(f"fit_many returned {len(models)} models for {len(chunk)} materials")
            except BrdfbenchError:
                raise
            except Exception as exc:  # a failed fit fails every cell of its batch, and the sweep goes on
                log.warning("%s failed to fit %s: %s", cfg.label, ", ".join(chunk), exc)
                message = "".join(traceback.format_exception_only(type(exc), exc)).strip()
                for name, material in zip(chunk, materials):
                    store.write_cell([row(name, material.category, None, "failed", message)])
                    counts["failed"] += 1
                    bar.update(1)
                continue
            fit_extra = [Measurement("fit_batch", float(len(chunk)), "materials", False)] if batch > 1 else []
            for name, material, model in zip(chunk, materials, models):
                try:
                    with time_limit(cfg.harness.timeout_s, f"{cfg.label} on {name}"):
                        measurements = measure(model, material)
                        measurements.append(Measurement("fit_time", fit_s, "s", False))
                        measurements.extend(fit_extra)
                        fit_loss = model.metadata().get(FIT_LOSS_KEY)
                        if isinstance(fit_loss, (int, float)):
                            measurements.append(Measurement("fit_loss", float(fit_loss), "objective", False))
                        measurements.extend(extra)
                        measurements.extend(model_size(model))
                        if cfg.save_models:
                            modelio.save(model, cfg.representation, cfg.results_dir / "models" / dataset.fingerprint / cfg.label / f"{name}.safetensors")
                except RenderError as exc:  # the plugin's fault (non-finite values), named with its material
                    log.warning("%s", str(exc))
                    store.write_cell([row(name, material.category, None, "failed", str(exc))])
                    counts["failed"] += 1
                except BrdfbenchError:
                    raise
                except Exception as exc:  # any plugin fault is recorded, and the sweep goes on
                    log.warning("%s failed on %s: %s", cfg.label, name, exc)
                    message = "".join(traceback.format_exception_only(type(exc), exc)).strip()
                    store.write_cell([row(name, material.category, None, "failed", message)])
                    counts["failed"] += 1
                else:
                    store.write_cell([row(name, material.category, m) for m in measurements])
                    counts["done"] += 1
                    bar.set_postfix(fit_s=f"{fit_s:.2f}")
                bar.update(1)
    bar.close()
    return counts


def _metric_specs(harness: HarnessConfig, scene) -> list:
    """The harness's metric specs, checked against its kind and the scene before any work."""
    if harness.kind not in HARNESS_KINDS:
        raise ConfigError(f"harness.kind {harness.kind!r} must be one of {', '.join(HARNESS_KINDS)}")
    if scene.needs_rendering and harness.kind not in RENDERED_KINDS:
        raise ConfigError(f"scene {scene.name!r} is rendered: use harness=render (image metrics) or scene=brdf_space")
    if not scene.needs_rendering and harness.kind in RENDERED_KINDS:
        raise ConfigError(f"harness={harness.kind} needs a rendered scene (scene=sphere_directional, sphere_envmap, "
                          f"spheres_on_plane); scene {scene.name!r} is not rendered")
    if harness.kind == "convergence":
        from .harness.convergence import check_config

        check_config(harness, scene)
    specs = [registry.get("metrics", m) for m in harness.metrics]
    allowed = HARNESS_KINDS[harness.kind]
    for spec in specs:
        domain = getattr(spec.load(), "domain", None)
        if domain not in allowed:
            raise ConfigError(f"harness.metrics: {spec.name!r} is measured on {domain!r}, but a {harness.kind} "
                              f"harness measures on {', '.join(allowed)}")
    return specs


def _measurer(cfg: RunConfig, scene, metric_specs: list, dtype: torch.dtype, fingerprint: str):
    """The per-(model, material) measurement of this job's harness kind."""
    if cfg.harness.kind == "convergence":
        return _convergence_measurer(cfg, scene, dtype, fingerprint)
    if cfg.harness.kind == "render":
        from .harness.render import RenderHarness

        h = cfg.harness
        simulator = _simulator_factory(h, scene, dtype)(h.spp)
        harness = RenderHarness(
            simulator, metric_specs, out_dir=cfg.results_dir / "renders" / scene.name, dataset_fingerprint=fingerprint,
            seed=cfg.seed, exposure=h.exposure, save_images=h.save_images,
            key={"scene": cfg.scene, "scene_params": cfg.scene_params, "simulator": simulator.name, "backend": simulator.backend,
                 "sampler": h.sampler, "sampler_params": h.sampler_params, "spp": h.spp, "dtype": h.dtype},
        )
        return lambda model, material: harness.measure(model, material, cfg.label)

    def accuracy(model, material):
        out = evaluate_accuracy(model, material, metric_specs, n_random=cfg.harness.n_random, seed=cfg.seed, dtype=dtype)
        return out + [evaluation_throughput(model, batch=cfg.harness.throughput_batch, seed=cfg.seed, dtype=dtype)]

    return accuracy


def _convergence_measurer(cfg: RunConfig, scene, dtype: torch.dtype, fingerprint: str):
    """Error against the model's own high-spp render along the spp ladder (harness.convergence)."""
    from .harness.convergence import ConvergenceHarness

    h = cfg.harness
    harness = ConvergenceHarness(
        _simulator_factory(h, scene, dtype), h.spp_ladder, h.reference_spp, out_dir=cfg.results_dir / "renders" / scene.name / "convergence",
        dataset_fingerprint=fingerprint, seed=cfg.seed, exposure=h.exposure, save_images=h.save_images,
        key={"scene": cfg.scene, "scene_params": cfg.scene_params, "sampler": h.sampler,
             "sampler_params": h.sampler_params, "dtype": h.dtype,
             "representation": cfg.representation, "params": cfg.representation_params},
    )
    return lambda model, material: harness.measure(model, material, cfg.label)


def _simulator_factory(h: HarnessConfig, scene, dtype: torch.dtype):
    """spp -> the simulator the harness config asks for on this scene, at that spp."""
    from .render.simulate import build_simulator

    def build(spp: int | None):
        return build_simulator(scene, name=h.simulator, sampler=h.sampler, sampler_params=h.sampler_params,
                               spp=spp, dtype=dtype, backend=h.backend)

    return build


def _scene_label(cfg: RunConfig) -> str:
    """The store's scene column: the scene, or for convergence rows "<scene>/convergence/<sampler>"."""
    if cfg.harness.kind != "convergence":
        return cfg.scene
    from .harness.convergence import scene_label

    return scene_label(cfg.scene, cfg.harness.sampler, cfg.harness.sampler_params)


def _hashed_harness(harness: HarnessConfig) -> dict[str, Any]:
    """The harness fields in the config hash: those its kind reads."""
    skip = UNHASHED_FIELDS[harness.kind]
    return {k: v for k, v in harness.__dict__.items() if k not in skip}


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
