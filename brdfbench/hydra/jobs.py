"""A sweep's jobs: each job's overrides (`job_overrides`: the basic sweeper's expansion plus a
profile's sections), how many run at once (`parallel_workers`), composed Hydra configs →
typed jobs (`to_run_config`), and the per-job summary file a sweep's end reads
(`brdfbench_job.json` in the job's Hydra output folder)."""

from __future__ import annotations

import importlib
import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig, OmegaConf

from .. import parallelism
from ..errors import ConfigError, os_error
from ..pipeline.config import RunConfig, harness_config
from ..pipeline.harness_defaults import unset_nulls
from ..atomic import replacing

JOB_SUMMARY = "brdfbench_job.json"
#: Summaries of the jobs run in this process, so the end of the sweep has them even where a
#: full disk kept their files from being written.
IN_PROCESS: list[dict[str, Any]] = []
#: Top-level keys of config.yaml besides the groups; anything else is a typo.
TOP_LEVEL = {"representation", "generator", "dataset", "harness", "scene", "seed", "materials", "limit", "results_dir",
             "save_models",
             "isolate", "progress", "store", "store_params", "device", "workers", "threads",
             "fit_workers"}


#: Command-line keys that choose what a run measures: with any of them, sections are left out.
SELECTORS = frozenset({"representation", "generator", "harness", "scene"})


def override_key(override: str) -> str:
    key = override.split("=", 1)[0].lstrip("+~")
    return key.split("@", 1)[0]


def _text(value: Any) -> str:
    """A config value as override syntax (null, true/false; strings and sweeps as written)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def job_overrides(params: Mapping[str, Any] | None, sections: Mapping[str, Mapping[str, Any]] | None,
                  arguments: Sequence[str], parser: OverridesParser | None = None) -> list[list[str]]:
    """Every job's overrides: the main sweep (`params`), then each of a profile's `sections`,
    which are left out where the command line's `arguments` choose what to measure
    (`SELECTORS`); see hydra_plugins.brdfbench_sweeper."""
    parser = parser or OverridesParser.create()
    keys = {override_key(a) for a in arguments}
    # a generator job measures the generator: the profile's sweep over representations would
    # only repeat it once per representation
    main = [f"{k}={_text(v)}" for k, v in (params or {}).items() if not ("generator" in keys and k == "representation")]
    groups = [main]
    if not any(override_key(a) in SELECTORS for a in arguments):
        for section in (sections or {}).values():
            groups.append([f"{k}={_text(v)}" for k, v in (section or {}).items()])
    jobs: list[list[str]] = []
    for group in groups:
        parsed = parser.parse_overrides(group + list(arguments))
        jobs += [job for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]
    return jobs


def basic_launcher(launcher: Any) -> bool:
    """Whether `launcher` is Hydra's basic launcher (jobs in this process, one at a time)."""
    return type(launcher).__name__ == "BasicLauncher"


def parallel_workers(config: Any, n_jobs: int) -> int:
    """How many of a sweep's `n_jobs` jobs run at once in joblib's process pool under the
    basic launcher (1: one after another, in this process): `workers` where the machine has
    the cores and joblib's plugin is installed."""
    try:
        workers, _ = parallelism.resolve(config.get("workers", "auto"), config.get("threads", "auto"), n_jobs)
    except ConfigError:
        return 1  # the jobs' validation reports it
    if workers < 2:
        return 1
    try:
        importlib.import_module("hydra_plugins.hydra_joblib_launcher.joblib_launcher")
    except ImportError:
        return 1  # without joblib's plugin the jobs run one at a time
    return workers


def _section(cfg: DictConfig, key: str) -> dict:
    node = OmegaConf.select(cfg, key, throw_on_missing=False)
    if node is None:
        return {}
    if not OmegaConf.is_config(node):  # a scalar where a mapping belongs (`store_params=5`)
        raise ConfigError(f"config key {key}={node!r} must be a mapping (e.g. +{key}.name=value)")
    try:
        value = OmegaConf.to_container(node, resolve=True, throw_on_missing=True)
    except Exception as exc:  # omegaconf's MissingMandatoryValue and interpolation errors name the key
        raise ConfigError(f"config key {key}: {exc}".splitlines()[0]) from None
    if not isinstance(value, dict):
        raise ConfigError(f"config key {key}={value!r} must be a config group (a mapping)")
    return value


def _value(cfg: DictConfig, key: str, default: Any = None) -> Any:
    try:
        node = OmegaConf.select(cfg, key, throw_on_missing=True, default=default)
        return OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else node
    except Exception as exc:
        raise ConfigError(f"config key {key}: {exc}".splitlines()[0]) from None


def _choices(cfg: DictConfig) -> dict[str, str]:
    """The config group choices (`representation: merl_trilinear`, `hydra/launcher: joblib`)."""
    node = OmegaConf.select(cfg, "hydra.runtime.choices", throw_on_missing=False)
    if node is not None:
        return dict(OmegaConf.to_container(node))
    from hydra.core.hydra_config import HydraConfig

    if HydraConfig.initialized():
        return dict(HydraConfig.get().runtime.choices)
    return {}


def to_run_config(cfg: DictConfig, job: str = "") -> RunConfig:
    """The typed job of a composed config; every key and value is checked, naming it."""
    unknown = sorted(k for k in cfg.keys() if k not in TOP_LEVEL and k != "hydra")
    if unknown:
        raise ConfigError(f"unknown config key(s) {', '.join(unknown)}; known: {', '.join(sorted(TOP_LEVEL))}")
    rep = _section(cfg, "representation")
    gen = _section(cfg, "generator")
    ds = _section(cfg, "dataset")
    harness = _section(cfg, "harness")
    scene = _section(cfg, "scene")
    for key, section in (("representation", rep), ("dataset", ds)) + ((("generator", gen),) if gen else ()):
        if "name" not in section:
            raise ConfigError(f"config key {key}.name is missing")
    for key, section, allowed in (("representation", rep, {"name", "label", "params"}),
                                  ("generator", gen, {"name", "label", "params"}),
                                  ("dataset", ds, {"name", "params"}), ("scene", scene, {"name", "params"})):
        extra = sorted(set(section) - allowed)
        if extra:
            raise ConfigError(f"unknown config key(s) {', '.join(f'{key}.{k}' for k in extra)}; "
                              f"{key} takes {', '.join(sorted(allowed))}")
    unset_nulls(harness)
    choices = _choices(cfg)
    materials = _value(cfg, "materials")
    if materials is not None and not isinstance(materials, (list, tuple)):
        raise ConfigError(f"materials={materials!r} must be a list of material names (e.g. materials=[a,b])")
    if materials is not None and len(materials) == 0:
        raise ConfigError("materials=[]: an empty selection; name at least one material, or leave materials out to take them all")
    if gen:  # a generator job: it measures the generator, the representation group is not read
        model = dict(representation="", representation_params={}, generator=gen["name"],
                     generator_params=gen.get("params") or {},
                     label=gen.get("label") or choices.get("generator") or gen["name"])
    else:
        model = dict(representation=rep["name"], representation_params=rep.get("params") or {},
                     label=rep.get("label") or choices.get("representation") or rep["name"])
    return RunConfig(
        **model,
        dataset=ds["name"],
        dataset_params=ds.get("params") or {},
        harness=harness_config(**harness),
        scene=scene.get("name", "brdf_space"),
        scene_params=scene.get("params") or {},
        materials=tuple(materials) if materials else None,
        limit=_value(cfg, "limit"),
        seed=_value(cfg, "seed", 0),
        results_dir=Path(str(_value(cfg, "results_dir", "results"))),
        save_models=_value(cfg, "save_models", False),
        store=_value(cfg, "store", "sqlite"),
        store_params=_section(cfg, "store_params"),
        isolate=_value(cfg, "isolate", True),
        progress=_value(cfg, "progress", "auto"),
        device=_value(cfg, "device", "auto"),
        threads=_threads(cfg),
        fit_workers=parallelism.fit_workers(_value(cfg, "workers", "auto"), _value(cfg, "fit_workers", "auto")),
        launcher=_launcher(choices),
        job=job,
    )


def _threads(cfg: DictConfig) -> int | None:
    """The job's thread count (None: torch's default); `workers` is checked here too."""
    parallelism.count("workers", _value(cfg, "workers", "auto"))
    return parallelism.count("threads", _value(cfg, "threads", "auto"))


def _launcher(choices: dict) -> str:
    """The launcher recorded with the job's figures: the sweeper's own parallel launch, else the choice."""
    launcher = choices.get("hydra/launcher", "basic")
    return os.environ.get(parallelism.LAUNCHER_ENV, launcher) if launcher == "basic" else launcher


def write_summary(folder: Path, summary: dict[str, Any]) -> None:
    """Keep the job's summary (in memory, and in its Hydra folder for other launchers); a
    folder that cannot be written (a full disk) becomes the job's error, not a traceback."""
    IN_PROCESS.append(summary)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with replacing(folder / JOB_SUMMARY) as tmp:
            tmp.write_text(json.dumps(summary), encoding="utf-8")
    except OSError as exc:
        summary.setdefault("error", f"the job's summary could not be written: {os_error(exc)}")
