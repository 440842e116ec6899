"""Generation jobs through the pipeline: set-scope cells planned, isolated, recorded and
reported; bad samples excluded and counted; bad configurations refused before any work."""

from __future__ import annotations

import os

import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.protocols.generator import TrainingData
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.plugins.specs import GeneratorSpec
from brdfbench.store.sqlite import ResultsStore
from brdfbench_generators.samples import TableSamples
from brdfbench_generators.training_set import TrainingSet

QUICK = dict(distances=("l1", "l1_log"), metrics=("mmd", "cov", "one_nna"), draws=2, test_fraction=0.34,
             categories=False)


class NaNSamples(TrainingSet):
    """The training set, with its second sample's parameters made NaN."""

    def _sample(self, n, condition, seed):
        s = super()._sample(n, condition, seed)
        array = s.array.clone()
        array[1] = float("nan")
        return TableSamples(array, s.to_table, name="nan")


class AllNaN(TrainingSet):
    def _sample(self, n, condition, seed):
        s = super()._sample(n, condition, seed)
        return TableSamples(torch.full_like(s.array, float("nan")), s.to_table, name="nan")


class DiesInFit(TrainingSet):
    def fit(self, data, *, seed=0, progress=False):
        os._exit(3)


@pytest.fixture
def generator():
    added = []

    def add(cls, learns_from="tables"):
        name = cls.__name__.lower()
        registry.register("generators", GeneratorSpec(name=name, description="test", target=f"{__name__}:{cls.__name__}",
                                                      learns_from=learns_from))
        added.append(name)
        return name

    yield add
    for name in added:
        registry.unregister("generators", name)


def _job(tmp_path, synthetic_cache, name, **harness):
    return RunConfig(representation="", representation_params={}, label=name, dataset="synthetic",
                     dataset_params={"size": "small", "cache_dir": str(synthetic_cache)},
                     harness=harness_config("generation", **{**QUICK, **harness}), results_dir=tmp_path,
                     progress="none", generator=name)


def _frame(tmp_path):
    return ResultsStore(tmp_path / "brdfbench.sqlite").frame()


def test_a_generation_job_stores_set_rows_per_draw_and_distance(tmp_path, synthetic_cache):
    counts = run(_job(tmp_path, synthetic_cache, "training_set"))
    assert counts == {"done": 2, "skipped": 0, "failed": 0}
    df = _frame(tmp_path)
    assert set(df.scope) == {"set"} and set(df.material) == {"draw-0", "draw-1"}
    assert set(df.category) == {"set"}
    sets = df[df.metric.isin(["mmd", "cov", "one_nna"])]
    assert set(zip(sets.metric, sets.distance)) == {(m, d) for m in ("mmd", "cov", "one_nna") for d in ("l1", "l1_log")}
    assert len(sets) == 2 * 3 * 2  # draws × metrics × distances
    assert (df[df.metric == "reference_materials"].value == 2).all()  # 6 small materials, a third held out
    assert (df[df.metric == "non_finite_samples"].value == 0).all()
    assert ((sets[sets.metric == "cov"].value >= 0) & (sets[sets.metric == "cov"].value <= 100)).all()
    # the configuration records the generator, not a representation
    (config,) = ResultsStore(tmp_path / "brdfbench.sqlite").configs()
    assert config.plugin == "training_set" and config.harness == "generation" and "generator" in config.params
    # a re-run finds every draw in the store
    assert run(_job(tmp_path, synthetic_cache, "training_set")) == {"done": 0, "skipped": 2, "failed": 0}


def test_a_non_finite_sample_is_excluded_and_counted(tmp_path, synthetic_cache, generator):
    counts = run(_job(tmp_path, synthetic_cache, generator(NaNSamples), draws=1))
    assert counts == {"done": 1, "skipped": 0, "failed": 0}
    df = _frame(tmp_path)
    assert float(df[df.metric == "non_finite_samples"].value.iloc[0]) == 1.0
    assert float(df[df.metric == "samples_scored"].value.iloc[0]) == 1.0


def test_a_draw_without_a_usable_sample_fails_naming_the_count(tmp_path, synthetic_cache, generator):
    counts = run(_job(tmp_path, synthetic_cache, generator(AllNaN), draws=1))
    assert counts == {"done": 0, "skipped": 0, "failed": 1}
    message = _frame(tmp_path).message.iloc[0]
    assert "all 2 samples are non-finite" in message


def test_a_generator_that_kills_its_worker_fails_every_draw_naming_the_cause(tmp_path, synthetic_cache, generator):
    counts = run(_job(tmp_path, synthetic_cache, generator(DiesInFit)))
    assert counts == {"done": 0, "skipped": 0, "failed": 2}
    df = _frame(tmp_path)
    assert set(df.material) == {"draw-0", "draw-1"}
    assert all("exited with status 3" in m and "training" in m for m in df.message)


def test_a_generator_over_weights_on_a_dataset_without_them_is_refused_up_front(tmp_path, synthetic_cache, generator):
    name = generator(TrainingSet, learns_from="nbrdf")
    with pytest.raises(ConfigError, match="dataset=neumerl"):
        run(_job(tmp_path, synthetic_cache, name))
    assert not (tmp_path / "brdfbench.sqlite").exists() or _frame(tmp_path).empty


def test_a_reference_split_of_one_material_is_refused(tmp_path, synthetic_cache):
    with pytest.raises(ConfigError, match="at least 2"):
        run(_job(tmp_path, synthetic_cache, "training_set", test_fraction=0.1))


def test_generator_and_harness_must_agree(tmp_path, synthetic_cache):
    job = _job(tmp_path, synthetic_cache, "training_set")
    with pytest.raises(ConfigError, match="harness=generation"):
        run(RunConfig(**{**job.__dict__, "harness": harness_config("accuracy")}))
    with pytest.raises(ConfigError, match="measures generators"):
        run(RunConfig(**{**job.__dict__, "generator": "", "generator_params": {}, "representation": "lambert"}))


def test_the_cli_runs_a_generation_sweep_and_reports_it(tmp_path, cli):
    result = cli("harness=generation", "dataset=synthetic", "dataset.params.size=small", "-m",
                 "generator=training_set", "harness.test_fraction=0.34", "harness.draws=2",
                 "harness.distances=[l1]", "harness.metrics=[mmd,cov,one_nna]", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    text = (tmp_path / "results" / "leaderboard.md").read_text()
    assert "generators" in text and "Unconditional synthesis (Zhou et al., Table 1)" in text
    assert "MMD BRDF-L1 (×0.001)" in text and "(2.51)" in text  # the published training-set figure beside ours
    page = (tmp_path / "results" / "leaderboard.html").read_text()
    assert "Zhou et al., Table 1" in page
    bad = cli("harness=generation", "dataset=synthetic", "dataset.params.size=small", "generator=nosuch", cwd=tmp_path)
    assert bad.returncode == 2 and "generator='nosuch': no such generator config" in bad.stderr
    assert "training_set" in bad.stderr


def test_check_and_inspect_know_generators(tmp_path, cli):
    from brdfbench import modelio

    checked = cli("check", "training_set", cwd=tmp_path)
    assert checked.returncode == 0 and "conformance of 'training_set'" in checked.stdout
    assert "xfailed  save_load_roundtrip" in checked.stdout
    gen = TrainingSet().fit(TrainingData(("a", "b"), load=lambda n: None))
    path = modelio.save_generator(gen, "training_set", tmp_path / "g.safetensors")
    shown = cli("inspect", str(path), cwd=tmp_path)
    assert shown.returncode == 0 and "generator 'training_set'" in shown.stdout and "names: ['a', 'b']" in shown.stdout
