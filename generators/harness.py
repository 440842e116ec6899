"""The generation harness (`harness=generation`): a generator's samples scored as a set.

A generation job trains one generator on a dataset's training split and scores `draws`
independent sample draws against the held-out test split (the reference set R), Zhou et al.'s
protocol (Table 1): per draw, MMD, COV and 1-NNA over each distance (BRDF-space L1,
L1-log and L1-log-cos over the full MERL grid; image-space RMSE, −PSNR and −SSIM on
rendered spheres), FID on those renders, and the counts of Zhou et al.'s seven categories
among the samples (constrained synthesis). Each draw is a set-scope cell, so the report's
interval over draws is the variability of the sample draw itself.

Samples with a non-finite parameter, or whose values or render are not finite, are
excluded from the scores and counted (`non_finite_samples`), never silently dropped; a
draw with no usable sample fails, naming the count.

It lives beside the generators (a harness plugin, as a third party would write one): the
core pipeline only knows that it scores sets.

Devices: the harness computes its own figures on the job's device (`uses_device`; the
context's device, None meaning the CPU): the BRDF distance matrices (torch on a GPU, numba
on the CPU), the image distance matrices and FID's feature extraction. Samples may live on
the generator's device: they are evaluated on the grid where they live, and moved to the
CPU to be rendered (Mitsuba renders on the CPU). On the CPU every figure is as before.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
import torch

from brdfbench import artifacts, merl
from brdfbench.atomic import replacing
from brdfbench.data import categories
from brdfbench.data.augmerl import unaugmented
from brdfbench.device import CPU, synchronize
from brdfbench.distances.brdf import distance_matrix
from brdfbench.distances.image import build_set_simulator, image_distance_matrix, render_with
from brdfbench.errors import ConfigError, RenderError
from brdfbench.harness import Harness, HarnessConfig, Measurement
from brdfbench.plugins import registry
from brdfbench.protocols.generator import TRAINING_CURVE_KEY, SampleSet, TrainingData, seeded_split

from .samples import TableSamples

log = logging.getLogger(__name__)

BRDF_DISTANCES = ("l1", "l1_log", "l1_log_cos")
IMAGE_DISTANCES = ("rmse", "neg_psnr", "neg_ssim")
DISTANCE_UNITS = {"l1": "1/sr", "l1_log": "log(1+1/sr)", "l1_log_cos": "log(1+1/sr)", "rmse": "1 (LDR)",
                  "neg_psnr": "-dB", "neg_ssim": "-SSIM"}
#: A draw's seed: apart from every other draw's and from the generator's training seed.
DRAW_SEED_STRIDE = 1_000_003


@dataclass(frozen=True)
class GenerationConfig(HarnessConfig):
    kind: str = "generation"
    metrics: tuple[str, ...] = ("mmd", "cov", "one_nna", "fid")
    distances: tuple[str, ...] = BRDF_DISTANCES + IMAGE_DISTANCES
    draws: int = field(default=3, metadata={"min": 1})  # independent sample draws, each scored against R
    n_samples: int | None = field(default=None, metadata={"min": 1})  # per draw; None: as many as R has
    test_fraction: float = field(default=0.1, metadata={"min_exclusive": 0})  # held out where the dataset has no split
    categories: bool = True  # count Zhou et al.'s seven categories among the samples
    image_scene: str = "sphere_envmap"  # the scene spheres are rendered in for image distances and FID
    image_size: int = field(default=64, metadata={"min": 8})  # rendered width = height (pixels)
    image_spp: int = field(default=64, metadata={"min": 1})  # samples per pixel of Monte Carlo scenes
    timeout_s: float | None = field(default=7200.0, metadata={"min_exclusive": 0})
    #: False: train on the training split's base materials alone, unpermuted and unmixed (Hu 2026,
    #: Table 4.5's "without augmentation"; AugMERL and NeuMERL); scored on the same test split
    augmented: bool = True

    def hashed(self) -> dict:
        """As every harness's, without `augmented` at its default (configurations stored before
        the key existed keep their hash)."""
        out = super().hashed()
        if out.get("augmented") is True:
            del out["augmented"]
        return out

    def __post_init__(self):
        super().__post_init__()
        unknown = [d for d in self.distances if d not in DISTANCE_UNITS]
        if unknown:
            raise ConfigError(f"harness.distances: unknown distance(s) {', '.join(map(repr, unknown))}; "
                              f"known: {', '.join(DISTANCE_UNITS)}")
        if not self.test_fraction < 1:
            raise ConfigError(f"harness.test_fraction={self.test_fraction!r} must be < 1")


class GenerationHarness(Harness):
    name = "generation"
    Config = GenerationConfig
    scope = "set"
    plugin_group = "generators"
    domains = ("set", "image_set")
    uses_device = True

    @classmethod
    def validate(cls, config: GenerationConfig, scene, metric_specs: list) -> None:
        if scene.needs_rendering:
            raise ConfigError(f"harness=generation renders its own spheres (harness.image_scene); "
                              f"leave scene=brdf_space, not {scene.name!r}")
        super().validate(config, scene, metric_specs)
        image_scene = registry.get("scenes", config.image_scene).load()()
        if not image_scene.needs_rendering:
            raise ConfigError(f"harness.image_scene={config.image_scene!r} is not a rendered scene "
                              "(e.g. sphere_envmap, sphere_directional)")

    @classmethod
    def check_plugin(cls, config: GenerationConfig, spec, dataset) -> None:
        if spec.learns_from == "nbrdf" and dataset.weights is None:
            raise ConfigError(f"generator {spec.name!r} learns from NBRDF weight vectors; dataset {dataset.name!r} "
                              "provides none: use dataset=neumerl (NeuMERL: AugMERL with aligned NBRDF fits)")
        train, test = cls.split(config, dataset, 0)
        if len(test) < 2:
            raise ConfigError(f"dataset {dataset.name!r}: the reference (test) split has {len(test)} material(s); "
                              "MMD / COV / 1-NNA need at least 2 (raise the dataset's size or test_fraction)")
        if len(train) < 2:
            raise ConfigError(f"dataset {dataset.name!r}: the training split has {len(train)} material(s); "
                              "a generator needs at least 2")

    @staticmethod
    def split(config: GenerationConfig, dataset, seed: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """(train, test): the dataset's own split where it declares one, else a seeded one;
        with `augmented=False`, the training split's unaugmented base materials only."""
        if dataset.splits is not None and "train" in dataset.splits and "test" in dataset.splits:
            train, test = tuple(dataset.splits["train"]), tuple(dataset.splits["test"])
        else:
            train, test = seeded_split(dataset.materials, config.test_fraction, seed)
        if not config.augmented:
            try:
                train = unaugmented(dataset, train)
            except ConfigError:
                raise ConfigError(f"harness.augmented=false trains on AugMERL's unaugmented base materials; dataset "
                                  f"{dataset.name!r} is not AugMERL or NeuMERL") from None
        return train, test

    @classmethod
    def plan_sets(cls, config: GenerationConfig, dataset, seed: int):
        train, _ = cls.split(config, dataset, seed)
        return train, tuple(f"draw-{i}" for i in range(config.draws))

    # -- training ------------------------------------------------------------------
    def prepare(self, model, materials: tuple[str, ...]) -> None:
        """Fit (or read from the cache) the split's NBRDF weights before training is timed: a
        dataset's one-off cost, not the generator's."""
        if model.learns_from == "nbrdf":
            self._weights = self.context.dataset.weights(tuple(materials))

    def train(self, model, materials: tuple[str, ...], seed: int, progress: bool | str = False):
        ds = self.context.dataset
        ready = getattr(self, "_weights", None)
        source = ds.weights if ready is None or ready.names != tuple(materials) else (lambda names: ready)
        data = TrainingData(names=tuple(materials), load=ds.load, categories=dict(ds.categories or {}),
                            weight_source=source, dataset=ds.name)
        fitted = model.fit(data, seed=seed, progress=progress)
        self._save_curve(fitted)
        return fitted

    def _save_curve(self, model) -> None:
        """The fit's training curves as an artifact of the configuration, for the report's plot."""

        ctx = self.context
        curves = model.metadata().get(TRAINING_CURVE_KEY)
        if not ctx.config_hash or not isinstance(curves, dict) or not curves:
            return
        path = artifacts.index_path(ctx.results_dir, ctx.config_hash, "training").with_suffix(".curve.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        with replacing(path) as tmp:
            tmp.write_text(json.dumps({"label": ctx.label, "curves": curves}), encoding="utf-8")
        artifacts.record(ctx.results_dir, ctx.config_hash, "training", "curve", path)

    @property
    def device(self) -> torch.device:
        """Where the harness computes its distances and features: the job's device (the CPU
        where the context names none)."""
        return CPU if self.context.device is None else torch.device(self.context.device)

    # -- the reference set, built once per job ------------------------------------------
    @cached_property
    def test_names(self) -> tuple[str, ...]:
        return self.split(self.config, self.context.dataset, self.context.seed)[1]

    @cached_property
    def reference_values(self) -> list[np.ndarray]:
        """R's tables as float32 value arrays (3, 90, 90, 180), 1/sr, negative = invalid."""
        return [self.context.dataset.load(n).table.values.astype(np.float32) for n in self.test_names]

    @property
    def renders(self) -> bool:
        """Whether a draw needs its samples rendered (image distances or FID)."""
        c = self.config
        return any(d in IMAGE_DISTANCES for d in c.distances) or any(
            s.load().domain == "image_set" for s in self.context.metric_specs)

    @cached_property
    def simulator(self):
        """One simulator for R and every draw: the same scene, environment and random numbers."""

        c = self.config
        return build_set_simulator(c.image_scene, spp=c.image_spp, width=c.image_size, height=c.image_size)

    @cached_property
    def reference_images(self):
        """R's tables rendered on spheres (N, H, W, 3), with the seed every draw's samples share."""

        merl_rep = registry.get("representations", "merl")
        models = [merl_rep.create().fit(self.context.dataset.load(n)) for n in self.test_names]
        return render_with(self.simulator, models, seed=self.context.seed, labels=list(self.test_names))

    # -- one draw ------------------------------------------------------------------------
    def measure_set(self, model, set_name: str) -> list[Measurement]:
        c = self.config
        draw = int(set_name.rpartition("-")[2])
        n = c.n_samples or len(self.test_names)
        t0 = time.perf_counter()
        samples = model.sample(n, seed=(self.context.seed * DRAW_SEED_STRIDE + draw) % 2**31)
        synchronize(getattr(model, "device", CPU))  # a generator on a GPU: its queued sampling is timed too
        sample_s = time.perf_counter() - t0
        values, images, excluded = self._sample_values(samples)
        if not values:
            raise ValueError(f"{set_name}: all {n} samples are non-finite; nothing to score")
        out = [Measurement("sample_time", sample_s, "s", False),
               Measurement("non_finite_samples", float(excluded), "samples", False),
               Measurement("samples_scored", float(len(values)), "samples", True),
               Measurement("reference_materials", float(len(self.test_names)), "materials", True),
               Measurement("model_bytes", float(model.nbytes), "B", False)]
        for kind in (d for d in c.distances if d in BRDF_DISTANCES):
            out += self._set_metrics(kind, self._brdf_matrix(values, kind))
        if images is not None:
            out += self._image_metrics(images)
        if c.categories:
            out += self._category_counts(values)
        return out

    @cached_property
    def thresholds(self):
        """Zhou et al.'s category thresholds, the specular ones from K-means on R's maximum reflectance."""

        return categories.thresholds([merl.MerlTable.from_values(v) for v in self.reference_values])

    def _category_counts(self, values: list[np.ndarray]) -> list[Measurement]:
        """How many of the draw's samples fall in each of Zhou et al.'s seven categories (they overlap)."""

        counts = categories.count_categories((merl.MerlTable.from_values(v) for v in values), self.thresholds)
        return [Measurement("category_count", float(k), "samples", False, category=name) for name, k in counts.items()]

    def _sample_values(self, samples: SampleSet):
        """Every usable sample's values on the grid (float32), their renders (N, H, W, 3) where
        a draw needs them (else None), and how many samples were excluded: a non-finite
        parameter, value or render."""

        keep, images, excluded = [], [], 0
        finite = samples.finite.cpu()
        for i in range(len(samples)):
            if not bool(finite[i]):
                log.warning("sample %d has non-finite parameters: excluded", i)
                excluded += 1
                continue
            built = None
            if isinstance(samples, TableSamples):
                v = samples.table(i).values.astype(np.float32)
            else:
                built = placed(samples[i], samples.array.device)
                v = grid_values(built)
            if not np.isfinite(v).all():
                log.warning("sample %d evaluates to non-finite values: excluded", i)
                excluded += 1
                continue
            if self.renders:
                try:
                    member = on_cpu(samples[i] if built is None else built)
                    images.append(render_with(self.simulator, [member], seed=self.context.seed,
                                              labels=[f"sample {i}"])[0])
                except RenderError as exc:
                    log.warning("%s: excluded", exc)
                    excluded += 1
                    continue
            keep.append(v)
        return keep, (torch.stack(images) if self.renders and images else None), excluded

    def _brdf_matrix(self, values: list[np.ndarray], kind: str) -> np.ndarray:

        return distance_matrix(self.reference_values + values, None, kind, device=self.device)

    def _image_metrics(self, images: torch.Tensor) -> list[Measurement]:
        """Set metrics over the image distances, and the image-set metrics (FID), of a draw's renders."""

        ref = self.reference_images
        out = []
        for kind in (d for d in self.config.distances if d in IMAGE_DISTANCES):
            out += self._set_metrics(kind, image_distance_matrix(torch.cat([ref, images]), None, kind,
                                                                 device=self.device))
        for spec in self.context.metric_specs:
            metric = spec.load()()
            if metric.domain == "image_set":
                where = {"device": self.device} if getattr(metric, "uses_device", False) else {}
                out.append(Measurement(spec.name, float(metric.compute(ref, images, **where)), metric.unit,
                                       spec.higher_is_better))
        return out

    def _set_metrics(self, distance: str, full: np.ndarray) -> list[Measurement]:
        """Every set metric of `harness.metrics` (MMD, COV, 1-NNA, …) over one distance, from
        the (R ∪ S)² matrix, through the metric plugins."""
        nr = len(self.test_names)
        d_rr, d_rs, d_ss = full[:nr, :nr], full[:nr, nr:], full[nr:, nr:]
        out = []
        for spec in self.context.metric_specs:
            metric = spec.load()()
            if metric.domain == "set":
                out.append(Measurement(spec.name, float(metric.compute(d_rr, d_ss, d_rs)),
                                       metric.unit_for(DISTANCE_UNITS[distance]), spec.higher_is_better,
                                       distance=distance))
        return out


def placed(model, where: torch.device):
    """A sample built from parameters on `where` (a sample set's array), consistent about its
    device: one whose `device` reads the CPU although its parameters lie on a GPU (a plugin
    that builds from device tensors without `to`) is moved where its class runs, that GPU if
    it declares it, else the CPU. Anything else is returned as it is."""
    if where.type == "cpu" or getattr(model, "device", CPU).type != "cpu" or not hasattr(model, "to"):
        return model
    return model.to(where if where.type in getattr(model, "devices", ()) else CPU)


def on_cpu(model):
    """`model` on the CPU, where renders are made (Mitsuba): moved there if it lives on a GPU."""
    return model if getattr(model, "device", CPU).type == "cpu" else model.to(CPU)


@lru_cache(maxsize=2)
def _grid_directions_on(device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """The fp64 grid directions on `device` (moved once per device; never modify in place)."""
    wi, wo = merl.grid_directions(torch.float64)
    return (wi, wo) if device.type == "cpu" else (wi.to(device), wo.to(device))


def grid_values(model, chunk: int = 1 << 18) -> np.ndarray:
    """A representation evaluated (fp64) at every MERL cell centre, on its own device:
    float32 (3, 90, 90, 180) on the host."""
    wi, wo = _grid_directions_on(getattr(model, "device", CPU))
    out = np.empty((3, merl.N_CELLS), dtype=np.float32)
    with torch.no_grad():
        for start in range(0, merl.N_CELLS, chunk):
            s = slice(start, start + chunk)
            out[:, s] = model.eval(wi[s], wo[s]).T.cpu().numpy()
    return out.reshape(3, *merl.SHAPE)
