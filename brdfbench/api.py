"""The notebook API (`import brdfbench as bb`): datasets, representations, scores, renders
and stored results in a few calls.

Each call is a thin layer over what a benchmark job runs: plugins are found through the
registry (an unknown name gets its "did you mean"), parameters are checked as a job's are
(a ConfigError naming the key), scores come from the accuracy harness's config and
functions, renders from the simulator the render harness builds. Calls run in this
process, with no time limit, and write to no store.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from .plugins import registry
from .errors import ConfigError
from .harness import HarnessConfig, Measurement
from .store.protocol import open_store

if TYPE_CHECKING:
    import pandas as pd
    import torch

    from .data import Dataset
    from .protocols.generator import Generator, TrainingData
    from .protocols.representation import Material, Representation
    from .store.protocol import Store

__all__ = ["Scores", "datasets", "evaluate", "generator", "render", "representation", "results", "training_data"]


def _harness_config(kind: str, **keys: Any) -> HarnessConfig:
    """Harness `kind`'s typed config: the keys given (not None) over its own defaults."""
    from .pipeline.config import harness_config  # lazy: torch

    return harness_config(kind, **{k: v for k, v in keys.items() if v is not None})


def _check_seed(seed: Any) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed={seed!r} must be a non-negative integer")


def _checked(factory, params: dict[str, Any], where: str, internal: tuple[str, ...] = ()) -> None:
    from .pipeline.plan import check_params  # lazy: torch

    check_params(factory, params, where, internal)


# --------------------------------------------------------------------------- data and models


def datasets(name: str, **params: Any) -> Dataset:
    """The dataset plugin `name` with its `dataset.params` (e.g. `size="small"`): a
    `brdfbench.data.Dataset`, whose `.materials` are names and `.load(name)` a Material."""
    factory = registry.get("datasets", name).load()
    _checked(factory, params, "dataset.params")
    return factory(**params)


def representation(name: str, **params: Any) -> Representation:
    """A new, unfitted instance of the representation plugin `name`; `.fit(material)` fits it."""
    spec = registry.get("representations", name)
    _checked(spec.load(), params, "representation.params")
    return spec.create(**params)


def generator(name: str, **params: Any) -> Generator:
    """A new, unfitted instance of the generator plugin `name`; `.fit(bb.training_data(ds))`
    fits it and `.sample(n, seed=...)` draws materials (fitted representations)."""
    spec = registry.get("generators", name)
    _checked(spec.load(), params, "generator.params")
    return spec.create(**params)


def training_data(dataset: Dataset, names: list[str] | None = None) -> TrainingData:
    """What a generator's `fit` reads: the dataset's training split (its own, where it
    declares one; else every material), or the materials `names`."""
    from .protocols.generator import TrainingData  # lazy: torch

    if names is None:
        names = list((dataset.splits or {}).get("train", dataset.materials))
    unknown = [n for n in names if n not in dataset.materials]
    if unknown:
        raise ConfigError(f"dataset {dataset.name!r} has no material(s) {', '.join(map(repr, unknown))}")
    return TrainingData(names=tuple(names), load=dataset.load, categories=dict(dataset.categories or {}),
                        weight_source=dataset.weights, dataset=dataset.name)


# --------------------------------------------------------------------------- scores


@dataclass(frozen=True)
class Scores(Mapping):
    """What `evaluate` measured: a read-only mapping metric -> value, with each figure's
    unit and direction kept in `measurements`."""

    measurements: tuple[Measurement, ...]

    def __getitem__(self, metric: str) -> float:
        for m in self.measurements:
            if m.metric == metric:
                return m.value
        raise KeyError(f"{metric!r} was not measured; measured: {', '.join(self)}")

    def __iter__(self) -> Iterator[str]:
        return (m.metric for m in self.measurements)

    def __len__(self) -> int:
        return len(self.measurements)

    def as_dict(self) -> dict[str, float]:
        return {m.metric: m.value for m in self.measurements}

    def frame(self) -> pd.DataFrame:
        """One row per metric: metric, value, unit, higher_is_better."""
        import pandas as pd

        return pd.DataFrame([(m.metric, m.value, m.unit, m.higher_is_better) for m in self.measurements],
                            columns=["metric", "value", "unit", "higher_is_better"])

    def __repr__(self) -> str:
        width = max((len(m.metric) for m in self.measurements), default=0)
        lines = [f"  {m.metric:<{width}}  {m.value:.6g} {m.unit}{'  (higher is better)' if m.higher_is_better else ''}"
                 for m in self.measurements]
        return "\n".join(["Scores(", *lines, ")"]) if lines else "Scores()"


def evaluate(model: Representation, material: Material, *, metrics: list[str] | None = None,
             n_random: int | None = None, dtype: str | None = None, seed: int = 0, cost: bool = True) -> Scores:
    """Score a fitted `model` against `material`'s table as the accuracy harness does
    (`harness=default`); None takes that harness's default (metrics l1, l1_log, l1_log_cos,
    hdr_rmse, hdr_mae; 2^20 random pairs; float32). `cost` adds evaluation throughput,
    model size and the model's own fit loss, as a benchmark cell records them (not the fit
    time or memory: the fit ran outside)."""
    import torch

    from .harness.accuracy import evaluate_accuracy  # lazy: torch
    from .harness.cost import evaluation_throughput, fit_loss, model_size  # lazy: torch
    from .pipeline.config import harness_class  # lazy: torch

    config = _harness_config("accuracy", metrics=metrics, n_random=n_random, dtype=dtype)
    _check_seed(seed)
    metric_specs = [registry.get("metrics", m) for m in config.metrics]
    harness_class("accuracy").validate(config, registry.get("scenes", "brdf_space").load()(), metric_specs)
    torch_dtype = getattr(torch, config.dtype)
    out = evaluate_accuracy(model, material, metric_specs, n_random=config.n_random, seed=seed, dtype=torch_dtype)
    if cost:
        out.append(evaluation_throughput(model, batch=config.throughput_batch, seed=seed, dtype=torch_dtype))
        out += model_size(model)
        out += fit_loss(model)
    return Scores(tuple(out))


# --------------------------------------------------------------------------- images


def render(model: Representation, scene: str = "sphere_envmap", *, spp: int | None = 16, seed: int = 0,
           simulator: str | None = None, sampler: str | None = None, sampler_params: dict[str, Any] | None = None,
           backend: str | None = None, dtype: str | None = None, **scene_params: Any) -> torch.Tensor:
    """Linear radiance (H, W, 3), a float32 torch tensor, of `model` in the scene plugin
    `scene` with its `scene.params` (width, height, envmap, ...), through the simulator the
    render harness builds (`harness=render`: the cheapest exact one, or `simulator`).
    `spp` defaults to a quick 16 samples per pixel for Monte Carlo scenes (None: the
    scene's own, as `harness=render` renders); the other keys are the render harness's,
    None taking its default. `brdfbench.images.tonemap` makes it displayable."""
    import torch

    from .pipeline.config import harness_class  # lazy: torch
    from .render.build import build_simulator  # lazy: torch

    factory = registry.get("scenes", scene).load()
    _checked(factory, scene_params, "scene.params")
    built = factory(**scene_params)
    config = _harness_config("render", metrics=(), spp=spp, simulator=simulator, sampler=sampler,
                             sampler_params=sampler_params, backend=backend, dtype=dtype)
    _check_seed(seed)
    harness_class("render").validate(config, built, [])
    c = config
    sim = build_simulator(built, name=c.simulator, sampler=c.sampler, sampler_params=c.sampler_params, spp=c.spp,
                          dtype=getattr(torch, c.dtype), backend=c.backend)
    return sim.render(model, seed=seed, label=type(model).__name__)


# --------------------------------------------------------------------------- stored results


def results(folder: str | Path = "results", *, store: str = "sqlite", **store_params: Any) -> Store:
    """The results store of a benchmark's results folder (`results_dir`, what `brdfbench`
    writes), never created here: a folder without one is a DataError naming it. `.frame()`
    is the pandas DataFrame of its rows (one per material and metric)."""
    _checked(registry.get("stores", store).load(), store_params, "store_params", internal=("results_dir", "create"))
    return open_store(store, Path(folder), {**store_params, "create": False})
