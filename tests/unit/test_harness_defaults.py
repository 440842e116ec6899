"""A harness kind's defaults come from its shipped option: `harness_config(kind)` (the Python
API) and `brdfbench harness=<kind>` (Hydra) agree, and the core's Config classes name no metric."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_module

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.harness import HarnessConfig
from brdfbench.pipeline import harness_defaults
from brdfbench.pipeline.config import harness_class, harness_config
from brdfbench.pipeline.harness_defaults import shipped_defaults

REPO = Path(__file__).resolve().parents[2]
CORE_KINDS = [n for n in registry.names("harnesses")
              if registry.get("harnesses", n).target.startswith("brdfbench.")]


def _composed(option: str, *overrides: str):
    from brdfbench.hydra.jobs import to_run_config

    with initialize_config_module(config_module="brdfbench_conf", version_base="1.3"):
        return to_run_config(compose("config", overrides=[f"harness={option}", *overrides])).harness


@pytest.mark.parametrize("kind", CORE_KINDS)
def test_a_core_harness_config_names_no_metric_and_its_option_does(kind):
    assert harness_class(kind).Config().metrics == (), f"{kind}: the Config class names its metrics"
    shipped = yaml.safe_load((REPO / "conf" / "harness" / f"{kind}.yaml").read_text())
    assert shipped["kind"] == kind and shipped["metrics"], f"conf/harness/{kind}.yaml lists no metrics"
    assert list(harness_config(kind).metrics) == shipped["metrics"]


@pytest.mark.parametrize("kind", ["accuracy", "render"])
def test_python_defaults_equal_the_cli_s(kind):
    scene = ["scene=sphere_directional"] if kind == "render" else []
    assert _composed(kind, *scene) == harness_config(kind)


def test_harness_default_is_the_accuracy_option():
    assert _composed("default") == _composed("accuracy") == harness_config("accuracy")
    assert _composed("default").hashed() == harness_config("accuracy").hashed()


def test_given_keys_win_and_a_kind_without_an_option_takes_its_dataclass_defaults(monkeypatch):
    assert harness_config("accuracy", metrics=["l1"], n_random=8).metrics == ("l1",)
    monkeypatch.setattr(harness_defaults, "_find", lambda option: None)
    harness_defaults._shipped.cache_clear()
    try:
        assert shipped_defaults("accuracy") == {}
        assert harness_config("accuracy").metrics == ()
    finally:
        harness_defaults._shipped.cache_clear()


def test_a_global_package_option_gives_its_harness_mapping():
    generation = shipped_defaults("generation")
    assert generation["draws"] == 3 and "dataset" not in generation and "hydra" not in generation


def test_a_defaults_list_that_includes_itself_is_refused_naming_the_file(tmp_path, monkeypatch):
    (tmp_path / "harness").mkdir()
    (tmp_path / "harness" / "loop.yaml").write_text("defaults:\n  - loop\nkind: accuracy\n")
    monkeypatch.setattr(harness_defaults, "_config_dirs", lambda: [tmp_path / "harness"])
    harness_defaults._shipped.cache_clear()
    try:
        with pytest.raises(ConfigError, match=r"loop\.yaml: harness option 'loop' includes itself"):
            shipped_defaults("loop")
    finally:
        harness_defaults._shipped.cache_clear()


def test_null_entries_of_a_mapping_are_left_out_as_the_cli_leaves_them():
    assert shipped_defaults("convergence")["sampler_params"] == {}
    assert isinstance(harness_config("convergence"), HarnessConfig)
