"""The notebook API (`import brdfbench as bb`): the README's example run verbatim, and each
call with its errors (bad names from the registry, bad parameters named by key)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import brdfbench as bb
from brdfbench.errors import ConfigError, DataError, PluginError

REPO = Path(__file__).resolve().parents[2]
FIRST = "synth-plastic-green-00"  # material 0 of the synthetic set, whatever its size
QUICK = {"n_random": 4096}


def readme_example() -> str:
    """The ```python block right after the README's "## Python API" heading."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    found = re.search(r"^## Python API\n(?:(?!^## ).)*?^```python\n(.*?)^```", text, re.S | re.M)
    assert found, "README.md has no ```python block under '## Python API'"
    return found.group(1)


@pytest.fixture(scope="module")
def material(synthetic_cache):
    return bb.datasets("synthetic", size="small", cache_dir=str(synthetic_cache)).load(FIRST)


@pytest.fixture(scope="module")
def model(material):
    return bb.representation("lambert").fit(material)


@pytest.fixture(scope="module")
def results_folder(tmp_path_factory, synthetic_cache):
    """A working folder whose `results/` holds a store, as `brdfbench` writes it (in-process)."""
    from brdfbench.pipeline.config import RunConfig, harness_config
    from brdfbench.pipeline.sweep import run_job as run

    cwd = tmp_path_factory.mktemp("notebook")
    run(RunConfig(representation="lambert", representation_params={}, label="lambert", dataset="synthetic",
                  dataset_params={"size": "small", "cache_dir": str(synthetic_cache)},
                  harness=harness_config(n_random=4096, throughput_batch=1024), limit=2,
                  results_dir=cwd / "results", isolate=False, progress="none"))
    return cwd


# --------------------------------------------------------------------------- the README


def test_the_readme_example_runs_verbatim(results_folder, monkeypatch, capsys):
    code = readme_example()
    assert len(code.strip().splitlines()) == 6
    monkeypatch.chdir(results_folder)
    scope: dict = {}
    exec(compile(code, "README.md (Python API)", "exec"), scope)
    out = capsys.readouterr().out
    assert "hdr_rmse" in out and "1/sr" in out and "evals/s" in out  # the scores, with units
    assert "lambert" in out and "l1_log_cos" in out  # the stored results' pivot
    image = scope["image"]
    assert isinstance(image, torch.Tensor) and image.dtype == torch.float32 and image.shape == (256, 256, 3)
    assert bool(torch.isfinite(image).all()) and float(image.max()) > 0


# --------------------------------------------------------------------------- the package


def test_import_brdfbench_stays_light_and_lists_the_api():
    code = ("import sys, brdfbench as bb\n"
            "light = not any(m in sys.modules for m in ('torch', 'brdfbench.api', 'pandas'))\n"
            "print(light, all(n in dir(bb) for n in bb.__all__))\n"
            "bb.evaluate\n"
            "print('brdfbench.api' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "True", "True"]


def test_render_is_the_subpackage_and_the_call():
    from brdfbench import api
    from brdfbench.render import build

    assert bb.render.build is build and callable(bb.render)
    assert bb.evaluate is api.evaluate and bb.Scores is api.Scores
    with pytest.raises(AttributeError, match="no attribute 'nonesuch'"):
        bb.nonesuch  # noqa: B018


# --------------------------------------------------------------------------- datasets and representations


def test_datasets_returns_the_plugins_dataset(synthetic_cache):
    ds = bb.datasets("synthetic", size="small", cache_dir=str(synthetic_cache))
    assert len(ds.materials) == 6 and ds.materials[0] == FIRST and ds.fingerprint.startswith("synthetic-")
    assert ds.load(FIRST).name == FIRST


def test_datasets_errors_name_what_exists_and_the_key():
    with pytest.raises(PluginError, match="Did you mean 'synthetic'"):
        bb.datasets("synthetc")
    with pytest.raises(ConfigError, match=r"dataset\.params\.sise.*takes: size, seed, cache_dir"):
        bb.datasets("synthetic", sise="small")
    with pytest.raises(ConfigError, match="size must be"):
        bb.datasets("synthetic", size="huge")


def test_representation_is_the_plugin_unfitted_with_its_params():
    from brdfbench.plugins import registry

    model = bb.representation("merl", mode="trilinear")
    assert isinstance(model, registry.get("representations", "merl").load())
    assert model.params["mode"] == "trilinear"
    with pytest.raises(PluginError, match="Did you mean 'lambert'"):
        bb.representation("lamber")
    with pytest.raises(ConfigError, match=r"unknown key representation\.params\.mood"):
        bb.representation("merl", mood="nearest")
    with pytest.raises(ConfigError, match="cubic"):
        bb.representation("merl", mode="cubic")


# --------------------------------------------------------------------------- evaluate


def test_evaluate_scores_as_the_accuracy_harness(model, material):
    from brdfbench.plugins import registry
    from brdfbench.harness.accuracy import evaluate_accuracy
    from brdfbench.pipeline.config import harness_config

    scores = bb.evaluate(model, material, **QUICK)
    defaults = harness_config("accuracy").metrics
    assert defaults, "the shipped harness=accuracy option names the default metrics"
    assert list(scores)[:len(defaults)] == list(defaults)
    assert {"evals_per_s", "model_bytes"} <= set(scores)
    direct = evaluate_accuracy(model, material, [registry.get("metrics", m) for m in defaults], n_random=4096)
    assert [scores[m.metric] for m in direct] == [m.value for m in direct]
    by_name = {m.metric: m for m in scores.measurements}
    assert by_name["l1"].unit == "1/sr" and not by_name["l1"].higher_is_better
    assert by_name["evals_per_s"].higher_is_better
    assert scores.as_dict() == dict(scores) and list(scores.frame().metric) == list(scores)
    assert "hdr_mae" in repr(scores)


def test_evaluate_without_cost_and_with_chosen_metrics(model, material):
    scores = bb.evaluate(model, material, metrics=["l1_log", "hdr_rmse"], dtype="float64", cost=False, **QUICK)
    assert list(scores) == ["l1_log", "hdr_rmse"]
    with pytest.raises(KeyError, match="'l1' was not measured"):
        scores["l1"]


def test_evaluate_errors_name_the_metric_or_key(model, material):
    with pytest.raises(PluginError, match="Did you mean 'hdr_rmse'"):
        bb.evaluate(model, material, metrics=["hdr_rmsee"])
    with pytest.raises(ConfigError, match="psnr_ldr.*image"):
        bb.evaluate(model, material, metrics=["psnr_ldr"])
    with pytest.raises(ConfigError, match=r"harness\.n_random=0"):
        bb.evaluate(model, material, n_random=0)
    with pytest.raises(ConfigError, match=r"harness\.dtype='float16'"):
        bb.evaluate(model, material, dtype="float16")
    with pytest.raises(ConfigError, match="seed=-1"):
        bb.evaluate(model, material, seed=-1)


# --------------------------------------------------------------------------- render


def test_render_goes_through_the_harness_simulator(model):
    from brdfbench.plugins import registry
    from brdfbench.render.build import build_simulator

    image = bb.render(model, "sphere_envmap", width=16, height=12, spp=4, backend="torch")
    assert image.dtype == torch.float32 and image.shape == (12, 16, 3)
    assert bool(torch.isfinite(image).all()) and float(image.min()) >= 0 and float(image.max()) > 0
    scene = registry.get("scenes", "sphere_envmap").load()(width=16, height=12)
    same = build_simulator(scene, spp=4, backend="torch").render(model, seed=0)
    assert torch.equal(image, same)
    lit = bb.render(model, "sphere_directional", width=8, height=8)  # closed form: spp does not apply
    assert lit.shape == (8, 8, 3) and float(lit.max()) > 0


def test_render_errors_name_the_scene_or_key(model):
    with pytest.raises(PluginError, match="Did you mean 'sphere_envmap'"):
        bb.render(model, "sphere_envmp")
    with pytest.raises(ConfigError, match="needs a rendered scene"):
        bb.render(model, "brdf_space")
    with pytest.raises(ConfigError, match=r"unknown key scene\.params\.widht"):
        bb.render(model, widht=16)
    with pytest.raises(ConfigError, match=r"scene\.params\.width=0"):
        bb.render(model, width=0)
    with pytest.raises(ConfigError, match=r"harness\.spp=0"):
        bb.render(model, spp=0)
    with pytest.raises(PluginError, match="Did you mean 'ggx'"):
        bb.render(model, sampler="ggxx")


# --------------------------------------------------------------------------- results


def test_results_opens_the_folders_store(results_folder):
    frame = bb.results(results_folder / "results").frame()
    assert set(frame.representation) == {"lambert"} and frame.material.nunique() == 2
    assert {"l1", "hdr_rmse", "fit_time"} <= set(frame.metric)


def test_results_never_creates_a_store(tmp_path, results_folder):
    missing = tmp_path / "nothing-here"
    with pytest.raises(DataError, match=re.escape(str(missing))):
        bb.results(missing)
    assert not missing.exists()
    with pytest.raises(PluginError, match="Did you mean 'sqlite'"):
        bb.results(results_folder / "results", store="sqlit")
    with pytest.raises(ConfigError, match=r"unknown key store_params\.flie"):
        bb.results(results_folder / "results", flie="x.sqlite")
    with pytest.raises(ConfigError, match=r"store_params\.create is set by brdfbench"):
        bb.results(missing, create=True)
    assert not missing.exists()
