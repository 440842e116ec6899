"""The runner in-process: failures and timeouts become rows, cells are skipped on re-run."""

import math
import time

import pytest

from brdfbench.errors import ConfigError
from brdfbench.report import write_reports
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.store.sqlite import ResultsStore
from brdfbench_representations.lambert import Lambert

QUICK = harness_config(n_random=4096, throughput_batch=1024)


class Explodes(Lambert):
    def fit(self, target, *, seed=0):
        if target.category == "metal":
            raise RuntimeError("cannot fit metals")
        return super().fit(target, seed=seed)


class Hangs(Lambert):
    def fit(self, target, *, seed=0):
        time.sleep(30)
        return self


def _cfg(tmp_path, synthetic_cache, name, **kw):
    return RunConfig(
        representation=name, representation_params={}, label=name, dataset="synthetic",
        dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, harness=kw.pop("harness", QUICK),
        results_dir=tmp_path, **kw,
    )


def test_a_raising_plugin_is_recorded_and_the_sweep_goes_on(tmp_path, synthetic_cache, plugin):
    name = plugin(Explodes, "explodes")
    counts = run(_cfg(tmp_path, synthetic_cache, name))
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    failed = df[df.status == "failed"]
    assert counts["failed"] == len(failed) >= 1 and counts["done"] >= 1
    assert failed.message.str.contains("cannot fit metals").all()
    board = write_reports(tmp_path)[0].read_text()
    assert "### Failures" in board and "cannot fit metals" in board


def test_a_hanging_plugin_times_out_as_a_failure(tmp_path, synthetic_cache, plugin):
    name = plugin(Hangs, "hangs")
    harness = harness_config(n_random=1024, throughput_batch=256, timeout_s=0.5)
    t0 = time.perf_counter()
    counts = run(_cfg(tmp_path, synthetic_cache, name, harness=harness, limit=2))
    assert counts == {"done": 0, "skipped": 0, "failed": 2}
    assert time.perf_counter() - t0 < 25  # both cells cut at 0.5 s, not 30 s each
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert df.message.str.contains("exceeded the time limit").all()


def test_rerun_skips_done_cells_and_config_change_does_not(tmp_path, synthetic_cache):
    cfg = _cfg(tmp_path, synthetic_cache, "lambert", limit=2)
    assert run(cfg)["done"] == 2
    assert run(cfg) == {"done": 0, "skipped": 2, "failed": 0}
    other = _cfg(tmp_path, synthetic_cache, "lambert", limit=2, seed=1)
    assert run(other)["done"] == 2


def test_results_carry_units_direction_and_provenance(tmp_path, synthetic_cache):
    run(_cfg(tmp_path, synthetic_cache, "lambert", limit=1))
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    by_metric = df.set_index("metric")
    assert set(by_metric.index) >= {"l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae", "fit_time", "evals_per_s", "model_bytes"}
    assert by_metric.loc["evals_per_s", "unit"] == "evals/s" and by_metric.loc["evals_per_s", "higher_is_better"]
    assert by_metric.loc["fit_time", "unit"] == "s" and not by_metric.loc["fit_time", "higher_is_better"]
    assert by_metric.loc["target_lobe_half_width", "unit"] == "rad"  # the target's, for the sharpest-tenth split
    assert 0 < by_metric.loc["target_lobe_half_width", "value"] <= math.pi / 2
    assert (df.config_hash.str.len() == 16).all() and (df.package_version != "").all()
    assert (df.value > 0).all()


def test_unknown_representation_param_names_the_key(tmp_path, synthetic_cache):
    cfg = RunConfig(
        representation="merl", representation_params={"mdoe": "nearest"}, label="merl", dataset="synthetic",
        dataset_params={}, results_dir=tmp_path,
    )
    with pytest.raises(ConfigError, match=r"representation\.params\.mdoe"):
        run(cfg)


def test_bad_param_value_names_the_value(tmp_path, synthetic_cache):
    cfg = _cfg(tmp_path, synthetic_cache, "merl")
    cfg = RunConfig(**{**cfg.__dict__, "representation_params": {"mode": "cubic"}})
    with pytest.raises(ConfigError, match="'cubic'"):
        run(cfg)


def test_accuracy_is_deterministic_given_a_seed(tmp_path, synthetic_cache):
    frames = []
    for sub in ("a", "b"):
        run(_cfg(tmp_path / sub, synthetic_cache, "lambert", limit=2))
        df = ResultsStore(tmp_path / sub / "brdfbench.sqlite").frame()
        frames.append(df[df.metric.isin(["l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae"])].sort_values(["material", "metric"]))
    assert frames[0].value.tolist() == frames[1].value.tolist()


def test_trained_representation_is_cross_validated_over_every_material(tmp_path, synthetic_cache):
    harness = harness_config(n_random=2048, throughput_batch=512, folds=3)
    counts = run(_cfg(tmp_path, synthetic_cache, "pca", harness=harness))
    assert counts == {"done": 6, "skipped": 0, "failed": 0}
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert df.material.nunique() == 6
    per_metric = df.groupby("metric").size()
    assert per_metric["train_time"] == 6 and per_metric["shared_bytes"] == 6
    assert run(_cfg(tmp_path, synthetic_cache, "pca", harness=harness))["skipped"] == 6
    board = write_reports(tmp_path)[0].read_text()
    assert "train time ↓" in board and "shared bytes" in board and "bytes/material" in board


def test_k_too_large_fails_every_cell_naming_it(tmp_path, synthetic_cache):
    """A plugin that cannot run so (more components than the training split gives) fails its
    cells with its own words; the run goes on to the end, so a sweep's other jobs still run."""
    cfg = _cfg(tmp_path, synthetic_cache, "pca", harness=harness_config(n_random=1024, throughput_batch=256, folds=2))
    cfg = RunConfig(**{**cfg.__dict__, "representation_params": {"k": 300}})
    counts = run(cfg)
    assert counts["done"] == 0 and counts["failed"] == 6  # the small set
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert (df.status == "failed").all() and df.message.str.contains("k=300 is larger than").all()


def test_a_models_own_fit_loss_is_recorded(tmp_path, synthetic_cache):
    run(_cfg(tmp_path, synthetic_cache, "ggx", limit=1))
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    loss = df[df.metric == "fit_loss"]
    assert len(loss) == 1 and loss.unit.iloc[0] == "objective" and 0 < loss.value.iloc[0] < 1


def test_run_control_stays_out_of_the_hash_and_measured_fields_do_not(tmp_path, synthetic_cache):
    """A time limit changes how a run goes, not what it measures: finished cells stay valid."""
    from dataclasses import replace

    first = run(_cfg(tmp_path, synthetic_cache, "lambert", limit=2))
    again = run(_cfg(tmp_path, synthetic_cache, "lambert", limit=2, harness=replace(QUICK, timeout_s=30.0)))
    assert first["done"] == 2 and again == {"done": 0, "skipped": 2, "failed": 0}
    assert run(_cfg(tmp_path, synthetic_cache, "lambert", limit=2, harness=replace(QUICK, n_random=2048)))["done"] == 2
