"""Hydra entry: compose the packaged configs into a RunConfig, run the job, write the report."""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from .errors import BrdfbenchError, ConfigError
from .runner import HarnessConfig, RunConfig, run


def _section(cfg: DictConfig, key: str) -> dict:
    node = OmegaConf.select(cfg, key, throw_on_missing=False)
    if node is None:
        return {}
    try:
        return OmegaConf.to_container(node, resolve=True, throw_on_missing=True)
    except Exception as exc:  # omegaconf's MissingMandatoryValue and interpolation errors name the key
        raise ConfigError(f"config key {key}: {exc}".splitlines()[0]) from None


def to_run_config(cfg: DictConfig) -> RunConfig:
    rep = _section(cfg, "representation")
    ds = _section(cfg, "dataset")
    harness = _section(cfg, "harness")
    scene = _section(cfg, "scene")
    for key, section in (("representation", rep), ("dataset", ds)):
        if "name" not in section:
            raise ConfigError(f"config key {key}.name is missing")
    known = set(HarnessConfig.__dataclass_fields__)
    for key in harness:
        if key not in known:
            raise ConfigError(f"unknown config key harness.{key}; known: {', '.join(sorted(known))}")
    harness["metrics"] = tuple(harness.get("metrics", HarnessConfig.metrics))
    if isinstance(harness.get("sampler_params"), dict):  # a harness yaml may declare sampler keys as null: unset
        harness["sampler_params"] = {k: v for k, v in harness["sampler_params"].items() if v is not None}
    materials = cfg.get("materials")
    return RunConfig(
        representation=rep["name"],
        representation_params=rep.get("params") or {},
        label=rep.get("label") or rep["name"],
        dataset=ds["name"],
        dataset_params=ds.get("params") or {},
        harness=HarnessConfig(**harness),
        scene=scene.get("name", "brdf_space"),
        scene_params=scene.get("params") or {},
        materials=tuple(materials) if materials else None,
        limit=cfg.get("limit"),
        seed=int(cfg.seed),
        results_dir=Path(cfg.results_dir),
        save_models=bool(cfg.save_models),
    )


@hydra.main(version_base="1.3", config_path="pkg://brdfbench_conf", config_name="config")
def _app(cfg: DictConfig) -> None:
    from .report import write_reports

    try:
        run_cfg = to_run_config(cfg)
        counts = run(run_cfg)
        paths = write_reports(run_cfg.results_dir)
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print(
        f"{run_cfg.label}: {counts['done']} done, {counts['skipped']} already in the store, "
        f"{counts['failed']} failed; leaderboard: {paths[0]}"
    )


def run_hydra(argv: list[str]) -> int:
    # Hydra's parser takes flags only before the overrides; accept `-m` anywhere, as in
    # `brdfbench harness=render scene=sphere_envmap -m representation=merl,nbrdf`.
    flags = [a for a in argv if a in ("-m", "--multirun")]
    sys.argv = ["brdfbench", *flags, *(a for a in argv if a not in flags)]
    _app()
    return 0
