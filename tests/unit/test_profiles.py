"""Profiles (conf/profile/): the jobs a plain `brdfbench` runs, and the section sweeper
(hydra_plugins/brdfbench_sweeper) that expands them."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf

from brdfbench.plugins import registry
from brdfbench.data.synthetic import CATEGORIES, synthetic_dataset
from hydra_plugins.brdfbench_sweeper import job_overrides


def _jobs(*overrides: str) -> tuple[list[dict[str, str]], object]:
    """Each job's overrides as a mapping, and the composed config of the first."""
    with initialize_config_module(config_module="brdfbench_conf", version_base="1.3"):
        cfg = compose("config", overrides=list(overrides), return_hydra_config=True)
    sweeper = OmegaConf.to_container(cfg.hydra.sweeper, resolve=False)
    jobs = job_overrides(sweeper["params"], sweeper["sections"], list(overrides))
    return [dict(o.split("=", 1) for o in job) for job in jobs], cfg


def _base(name: str) -> str:
    return name.removesuffix("_brief")


def test_first_look_runs_every_built_in_representation_and_a_render_section():
    jobs, cfg = _jobs()
    main = [j for j in jobs if "harness" not in j]
    renders = [j for j in jobs if j.get("harness") == "render"]
    assert len(main) + len(renders) == len(jobs)
    built_in = {n for n in registry.names("representations")
                if registry.get("representations", n).target.startswith("brdfbench_representations")}
    # the literature's analytic baselines and published fits have a profile of their own
    literature, _ = _jobs("profile=literature")
    baselines = {j["representation"] for j in literature} - {"ggx", "nbrdf"}
    assert {_base(j["representation"]) for j in main} == built_in - baselines
    assert not baselines & {_base(j["representation"]) for j in main}
    assert 2 <= len(renders) <= 4 and all(j["scene"] == "sphere_envmap" for j in renders)
    assert all(int(j["scene.params.width"]) <= 128 for j in renders)
    assert cfg.dataset.params.size >= 12 and cfg.harness.n_random < 2**20


def test_first_look_materials_cover_every_family(tmp_path):
    _, cfg = _jobs()
    ds = synthetic_dataset(cfg.dataset.params.size, seed=0, cache_dir=str(tmp_path))
    families = {next(c for c in CATEGORIES if name.startswith(f"synth-{c}-")) for name in ds.materials}
    assert families == set(CATEGORIES)


def test_literature_profile_runs_every_published_source_and_its_models():
    from brdfbench_representations.published import shipped_sources, source_model

    jobs, cfg = _jobs("profile=literature")
    assert cfg.dataset.name == "nbrdf_release"
    published = {j["representation.params.source"] for j in jobs if j["representation"] == "published_fit"}
    assert published == set(shipped_sources())
    refitted = {j["representation"] for j in jobs if j["representation"] != "published_fit"}
    assert {source_model(s) for s in published} | {"ggx", "nbrdf", "lafortune2", "lafortune3", "blinn_phong_ngan"} == refitted
    readings = {j.get("+representation.params.model") for j in jobs if j["representation"] == "published_fit"}
    assert readings == {None, "blinn_phong_ngan"}


def test_full_profile_is_the_previous_default():
    """profile=full: the eight representations of the earlier default on the 24-material set,
    default harness, full recipes, no sections."""
    jobs, cfg = _jobs("profile=full")
    assert [j["representation"] for j in jobs] == ["merl", "lambert", "blinn_phong", "cook_torrance", "ggx", "pca",
                                                   "nbrdf", "naive_mlp"]
    assert cfg.dataset.name == "synthetic" and cfg.dataset.params.size == "default"
    assert cfg.harness.n_random == 2**20 and cfg.harness.throughput_batch == 65536


@pytest.mark.parametrize("arguments", [["representation=lambert"], ["harness=render"], ["scene=sphere_envmap"],
                                       ["generator=pca_brdf"]])
def test_a_command_line_that_chooses_what_to_measure_drops_the_sections(arguments):
    params = {"representation": "merl,lambert"}
    sections = {"render": {"harness": "render", "representation": "merl"}}
    jobs = job_overrides(params, sections, arguments)
    assert all("harness=render" not in job or "harness=render" in arguments for job in jobs)
    # a generator measures itself: the representation sweep would repeat its one job
    assert len(jobs) == (1 if arguments[0].startswith(("representation", "generator")) else 2)


def test_sections_follow_the_main_sweep_with_the_command_line_on_top():
    params = {"representation": "merl,lambert"}
    sections = {"render": {"harness": "render", "representation": "merl,ggx", "limit": 3, "harness.display_spp": None}}
    jobs = job_overrides(params, sections, ["seed=1"])
    assert jobs == [["representation=merl", "seed=1"], ["representation=lambert", "seed=1"],
                    ["harness=render", "representation=merl", "limit=3", "harness.display_spp=null", "seed=1"],
                    ["harness=render", "representation=ggx", "limit=3", "harness.display_spp=null", "seed=1"]]
