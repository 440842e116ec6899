"""A job's typed configuration: what to measure (hashed) and how to run it (not hashed).

Every key is checked on construction, so a bad value fails before any work, naming the
key and what it takes. The harness config is the harness plugin's own typed config,
built from its `kind` through the registry (`harness_config`).
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..plugins import registry
from ..device import check_spec
from ..errors import ConfigError
from ..harness import HarnessConfig, check_value
from .harness_defaults import shipped_defaults

PROGRESS = ("auto", "bar", "lines", "none")


def harness_class(kind: str):
    """The harness plugin class registered as `kind` (harness.kind)."""
    if not isinstance(kind, str):
        raise ConfigError(f"harness.kind={kind!r} must be a harness name: {', '.join(registry.names('harnesses'))}")
    try:
        return registry.get("harnesses", kind).load()
    except Exception as exc:  # an unknown kind: the registry's message lists the harnesses
        raise ConfigError(f"harness.kind {kind!r}: {exc}") from None


def harness_config(kind: str = "accuracy", **values: Any) -> HarnessConfig:
    """The typed config of harness `kind` from its keys (unknown keys and bad values named);
    keys not given take the shipped option's values (`harness_defaults`), then the Config's."""
    cls = harness_class(kind)
    return cls.Config.from_dict({**shipped_defaults(kind), **values, "kind": kind})


def _default_harness() -> HarnessConfig:
    return harness_config("accuracy")


@dataclass(frozen=True)
class RunConfig:
    """One job: a representation (or, for a harness that measures generators, a generator)
    configuration on a dataset through one harness."""

    representation: str
    representation_params: dict[str, Any]
    label: str
    dataset: str
    dataset_params: dict[str, Any]
    harness: HarnessConfig = field(default_factory=_default_harness)
    scene: str = "brdf_space"
    scene_params: dict[str, Any] = field(default_factory=dict)
    materials: tuple[str, ...] | None = None
    limit: int | None = field(default=None, metadata={"min": 1})
    seed: int = field(default=0, metadata={"min": 0})
    results_dir: Path = Path("results")
    save_models: bool = False
    # run control: how the job runs, never part of a configuration's hash
    store: str = "sqlite"  # the results store plugin (group `stores`), opened for results_dir
    store_params: dict[str, Any] = field(default_factory=dict)
    isolate: bool = True  # cells in a worker process with a hard time limit (False: in-process, for debugging)
    progress: str = field(default="auto", metadata={"choices": PROGRESS})
    launcher: str = "basic"  # the Hydra launcher that started the job (recorded with every figure)
    device: str = "auto"  # where torch work runs: auto | cpu | cuda | cuda:N (see brdfbench.device)
    threads: int | None = field(default=None, metadata={"min": 1})  # torch threads of the job (None: torch's default)
    # single-threaded fits the job runs at once (None: its threads), see brdfbench.parallelism
    fit_workers: int | None = field(default=None, metadata={"min": 1})
    job: str = ""  # the job's number in a sweep, for progress lines
    # a generation job's generator (harness=generation); "" for jobs that measure representations
    generator: str = ""
    generator_params: dict[str, Any] = field(default_factory=dict)

    @property
    def plugin_group(self) -> str:
        """The registry group of the job's model plugin: "generators" or "representations"."""
        return "generators" if self.generator else "representations"

    @property
    def plugin(self) -> str:
        """The name of the plugin the job measures (its generator, else its representation)."""
        return self.generator or self.representation

    @property
    def plugin_params(self) -> dict[str, Any]:
        return self.generator_params if self.generator else self.representation_params

    @property
    def params_key(self) -> str:
        """The config key of the plugin's parameters, for messages."""
        return "generator.params" if self.generator else "representation.params"

    def __post_init__(self):
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "results_dir":
                if not isinstance(value, (str, Path)) or not str(value):
                    raise ConfigError(f"results_dir={value!r} must be a folder path")
                value = Path(value)
                if value.exists() and not value.is_dir():
                    raise ConfigError(f"results_dir={str(value)!r} exists and is not a folder")
            elif f.name == "device":
                value = check_spec(value)
            elif f.name == "harness":
                if not isinstance(value, HarnessConfig):
                    raise ConfigError(f"harness must be a harness config, got {type(value).__name__}")
            else:
                value = check_value(f.name, value, hints[f.name], f.metadata)
            object.__setattr__(self, f.name, value)
