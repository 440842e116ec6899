"""Harnesses: plugins (group `brdfbench.harnesses`) that measure fitted representations or generators.

A harness owns a typed config (a `HarnessConfig` subclass: its keys, types and ranges are
checked before any work), its up-front validation against the scene and metrics, the
fields that enter the configuration hash (all but run control such as time limits), and
its measuring. It is built once per job inside the worker process that runs the job's
cells, so what it builds (simulators, reference renders, direction sets) is reused for
every material. `scope` says whether it scores one material at a time ("material") or a
whole sample set at once ("set"), and `plugin_group` whether it measures representations
or generators.

A set-scope harness plans its own cells (`plan_sets`: the training materials and the names
of the sets to score, e.g. independent sample draws), trains the job's plugin once per
task (`train`) and measures each set (`measure_set`); the pipeline times, isolates and
records them as it does per-material cells.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from abc import ABC
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from ..errors import ConfigError
from ..pipeline.memory import parse_size

DTYPES = ("float32", "float64")


@dataclass(frozen=True)
class Measurement:
    metric: str
    value: float
    unit: str
    higher_is_better: bool
    spp: int = 0  # samples per pixel of a per-rung figure (convergence); 0 otherwise
    distance: str = ""  # the distance a set-level figure is computed over (generation); "" otherwise
    category: str | None = None  # the category a set-level count is of; None: the cell's own category


@dataclass(frozen=True)
class HarnessConfig:
    """Keys every harness has; subclasses add theirs with a default and, where the type
    alone does not say it, a range in the field's metadata (`min`, `choices`)."""

    kind: str = "accuracy"
    metrics: tuple[str, ...] = ()
    dtype: str = field(default="float32", metadata={"choices": DTYPES})
    folds: int = field(default=4, metadata={"min": 2})  # cross-validation folds of representations that train on a split
    timeout_s: float | None = field(default=600.0, metadata={"min_exclusive": 0})  # per cell; run control, not hashed
    # resident memory a worker process may hold ("1500MiB", "2GiB", bytes; None: no limit),
    # enforced by the supervisor (SIGKILL, a failure row); stored as bytes; run control, not hashed
    memory_limit: int | str | None = None

    #: Keys that control how a run goes, not what it measures: left out of the config hash.
    RUN_CONTROL: ClassVar[tuple[str, ...]] = ("timeout_s", "memory_limit")

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            if f.name == "memory_limit":
                object.__setattr__(self, f.name, parse_size(self.memory_limit, "harness.memory_limit"))
                continue
            object.__setattr__(self, f.name, check_value(f"harness.{f.name}", getattr(self, f.name), hints[f.name],
                                                         f.metadata))

    def hashed(self) -> dict[str, Any]:
        """The fields that decide what is measured (the config hash's share of the harness)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in self.RUN_CONTROL}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "HarnessConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        for key in values:
            if key not in known:
                raise ConfigError(f"unknown config key harness.{key} for harness={values.get('kind', cls.kind)}; "
                                  f"known: {', '.join(sorted(known))}")
        return cls(**values)


@dataclass(frozen=True)
class HarnessContext:
    """What a harness is built from, in the worker: the job's scene, data and options."""

    scene: Any
    metric_specs: list
    seed: int
    results_dir: Path
    dataset_fingerprint: str
    representation: str  # the job's plugin (a representation, or a generator for generator harnesses)
    representation_params: dict[str, Any]
    scene_name: str
    scene_params: dict[str, Any]
    config_hash: str = ""  # the job's configuration: artifacts (`brdfbench.artifacts`) are indexed by it
    dataset: Any = None  # the job's dataset (`brdfbench.data.Dataset`), already subset
    label: str = ""  # the job's label
    device: Any = None  # the job's torch device for the harness's own work (None: the CPU)


class Harness(ABC):
    """A measurement of fitted models; see the module docstring."""

    name: ClassVar[str]
    Config: ClassVar[type[HarnessConfig]] = HarnessConfig
    scope: ClassVar[str] = "material"
    #: the registry group of what it measures: "representations" or "generators"
    plugin_group: ClassVar[str] = "representations"
    #: Metric domains the harness accepts in `harness.metrics`.
    domains: ClassVar[tuple[str, ...]] = ()
    #: True: needs a rendered scene; False: needs scene=brdf_space.
    rendered: ClassVar[bool] = False
    #: True: the harness computes its own figures (distances, features) on the job's device,
    #: so they count as measured there even where the plugin runs on the CPU.
    uses_device: ClassVar[bool] = False
    #: True: `measure` takes models where they were fitted (the job's device); False: the
    #: pipeline moves a model fitted on a GPU to the CPU before measuring it.
    measures_on_device: ClassVar[bool] = False

    @classmethod
    def validate(cls, config: HarnessConfig, scene, metric_specs: list) -> None:
        """Up-front checks of the config against the scene and metrics (no heavy work)."""
        if scene.needs_rendering and not cls.rendered:
            raise ConfigError(f"scene {scene.name!r} is rendered: use harness=render (image metrics) or scene=brdf_space")
        if not scene.needs_rendering and cls.rendered:
            raise ConfigError(f"harness={cls.name} needs a rendered scene (scene=sphere_directional, sphere_envmap, "
                              f"spheres_on_plane); scene {scene.name!r} is not rendered")
        for spec in metric_specs:
            domain = getattr(spec.load(), "domain", None)
            if domain not in cls.domains:
                raise ConfigError(f"harness.metrics: {spec.name!r} is measured on {domain!r}, but a {cls.name} "
                                  f"harness measures on {', '.join(cls.domains) or 'no metric domain'}")

    @classmethod
    def check_plugin(cls, config: HarnessConfig, spec, dataset) -> None:
        """Up-front checks of the job's plugin against the data (e.g. what a generator learns
        from); a ConfigError names what does not fit. The default accepts everything."""

    @classmethod
    def plan_sets(cls, config: HarnessConfig, dataset, seed: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """A set-scope harness's (training materials, names of the sets to score)."""
        raise NotImplementedError(f"harness {cls.name!r} scores materials, not sets")

    def prepare(self, model, materials: tuple[str, ...]) -> None:
        """A set-scope harness: make the training data ready (e.g. fit a dataset's cached NBRDF
        weights) before `train` is timed; its own step, under the same time limit."""

    def train(self, model, materials: tuple[str, ...], seed: int, progress: bool | str = False):
        """A set-scope harness: fit the job's plugin on `materials`; returns the fitted model."""
        raise NotImplementedError(f"harness {self.name!r} scores materials, not sets")

    def measure_set(self, model, set_name: str) -> list[Measurement]:
        """A set-scope harness: measurements of one set (e.g. one draw of samples)."""
        raise NotImplementedError(f"harness {self.name!r} scores materials, not sets")

    @classmethod
    def key(cls, config: HarnessConfig, scene_name: str, scene_params: dict[str, Any]) -> dict[str, Any]:
        """The harness's share of the configuration hash."""
        out: dict[str, Any] = {"harness": config.hashed()}
        if cls.rendered:
            out.update(scene=scene_name, scene_params=scene_params)
        return out

    @classmethod
    def columns(cls, config: HarnessConfig, scene) -> dict[str, Any]:
        """Typed store columns of this harness's rows (scene, sampler)."""
        return {"scene": scene.name, "sampler": ""}

    def __init__(self, config: HarnessConfig, context: HarnessContext):
        self.config = config
        self.context = context

    def measure(self, model, material, label: str) -> list[Measurement]:
        """Measurements of one fitted model on its material (every material-scope harness implements it)."""
        raise NotImplementedError(f"harness {self.name!r} scores sets, not materials")


# --------------------------------------------------------------------------- typed values


def check_value(key: str, value: Any, hint: Any, rule: typing.Mapping[str, Any] = {}) -> Any:
    """`value` converted to the type `hint` says, or a ConfigError naming the key and what it takes."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (hint,) = [a for a in args if a is not type(None)]
        origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}={value!r} must be true or false")
    elif hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}={value!r} must be an integer{_range(rule)}")
    elif hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}={value!r} must be a number{_range(rule)}")
        value = float(value)
        if value != value or value in (float("inf"), float("-inf")):
            raise ConfigError(f"{key}={value!r} must be a finite number{_range(rule)}")
    elif hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}={value!r} must be a string")
    elif origin is tuple:
        if isinstance(value, (str, bytes, dict)) or not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}={value!r} must be a list (e.g. {key}=[a,b])")
        value = tuple(check_value(f"{key}[{i}]", v, args[0]) for i, v in enumerate(value))
        return value
    elif origin is dict or hint is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{key}={value!r} must be a mapping")
        return dict(value)
    if "choices" in rule and value not in rule["choices"]:
        raise ConfigError(f"{key}={value!r} must be one of {', '.join(map(str, rule['choices']))}")
    if "min" in rule and value < rule["min"]:
        raise ConfigError(f"{key}={value!r} must be ≥ {rule['min']}")
    if "min_exclusive" in rule and value <= rule["min_exclusive"]:
        raise ConfigError(f"{key}={value!r} must be > {rule['min_exclusive']}")
    return value


def _range(rule: typing.Mapping[str, Any]) -> str:
    if "min" in rule:
        return f" ≥ {rule['min']}"
    if "min_exclusive" in rule:
        return f" > {rule['min_exclusive']}"
    return ""
