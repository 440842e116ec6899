"""Cells in a worker process: a crash, an exit, a kill or a hang is a failure row naming its
cause, and the job goes on with the next cell; non-finite figures are failures too."""

from __future__ import annotations

import ctypes
import math
import os
import signal
import time

import pytest
import torch

from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.store.sqlite import ResultsStore
from brdfbench_representations.lambert import Lambert

QUICK = harness_config(n_random=1024, throughput_batch=256, timeout_s=60)


def _victim(target) -> bool:
    return target.category == "metal"


class Segfaults(Lambert):
    def fit(self, target, *, seed=0):
        if _victim(target):
            ctypes.string_at(0)  # a real SIGSEGV
        return super().fit(target, seed=seed)


class Exits(Lambert):
    def fit(self, target, *, seed=0):
        if _victim(target):
            os._exit(3)
        return super().fit(target, seed=seed)


class KilledForMemory(Lambert):
    def fit(self, target, *, seed=0):
        if _victim(target):
            os.kill(os.getpid(), signal.SIGKILL)  # what the out-of-memory killer sends
        return super().fit(target, seed=seed)


class HangsInEval(Lambert):
    def _eval(self, wi, wo):
        if getattr(self, "hang", False):
            time.sleep(120)
        return super()._eval(wi, wo)

    def fit(self, target, *, seed=0):
        super().fit(target, seed=seed)
        self.hang = _victim(target)
        return self


class ReturnsNaN(Lambert):
    def _eval(self, wi, wo):
        out = super()._eval(wi, wo)
        return torch.full_like(out, math.nan) if getattr(self, "nan", False) else out

    def fit(self, target, *, seed=0):
        super().fit(target, seed=seed)
        self.nan = _victim(target)
        return self


def _run(tmp_path, synthetic_cache, name, harness=QUICK, limit=3):
    cfg = RunConfig(representation=name, representation_params={}, label=name, dataset="synthetic",
                    dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, harness=harness,
                    results_dir=tmp_path, limit=limit, progress="none")
    return run(cfg), ResultsStore(tmp_path / "brdfbench.sqlite").frame()


@pytest.mark.parametrize("cls, cause", [
    (Segfaults, "segmentation fault"),
    (Exits, "exited with status 3"),
    (KilledForMemory, "killed by SIGKILL"),
])
def test_a_dying_plugin_is_a_failure_naming_the_cause_and_the_job_goes_on(tmp_path, synthetic_cache, plugin, cls, cause):
    counts, df = _run(tmp_path, synthetic_cache, plugin(cls))
    assert counts == {"done": 2, "skipped": 0, "failed": 1}
    failed = df[df.status == "failed"]
    assert list(failed.material) == ["synth-metal-chrome-01"]
    assert cause in failed.message.iloc[0] and "fitting" in failed.message.iloc[0]
    assert set(df[df.status == "ok"].material) == {"synth-plastic-green-00", "synth-metallic-paint-blue-02"}


def test_a_hang_while_measuring_is_cut_at_the_limit(tmp_path, synthetic_cache, plugin):
    harness = harness_config(n_random=1024, throughput_batch=256, timeout_s=5)  # a healthy lambert step: ~0.1 s
    t0 = time.monotonic()
    counts, df = _run(tmp_path, synthetic_cache, plugin(HangsInEval), harness=harness)
    assert time.monotonic() - t0 < 110  # the 120 s sleep was cut
    assert counts == {"done": 2, "skipped": 0, "failed": 1}
    message = df[df.status == "failed"].message.iloc[0]
    assert "hangsineval on synth-metal-chrome-01 exceeded the time limit of 5 s (worker process killed)" in message


def test_a_non_finite_figure_is_a_failure_naming_material_and_metric(tmp_path, synthetic_cache, plugin):
    counts, df = _run(tmp_path, synthetic_cache, plugin(ReturnsNaN))
    assert counts["failed"] == 1 and counts["done"] == 2
    message = df[df.status == "failed"].message.iloc[0]
    assert "non-finite" in message and "synth-metal-chrome-01" in message
    assert df[df.status == "ok"].value.map(math.isfinite).all()


def test_every_cell_records_peak_memory_and_its_environment(tmp_path, synthetic_cache):
    counts, df = _run(tmp_path, synthetic_cache, "lambert", limit=1)
    rows = df.set_index("metric")
    for metric in ("peak_rss_fit", "peak_rss_eval"):
        assert rows.loc[metric, "unit"] == "B" and 50e6 < rows.loc[metric, "value"] < 20e9
    assert (df.host != "").all() and (df.threads >= 1).all() and (df.cpu_count >= 1).all()
    assert (df.launcher == "basic").all() and (df.concurrent_jobs >= 1).all()


def test_in_process_cells_give_the_same_figures(tmp_path, synthetic_cache):
    from dataclasses import replace

    cfg = RunConfig(representation="lambert", representation_params={}, label="lambert", dataset="synthetic",
                    dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, harness=QUICK,
                    results_dir=tmp_path / "a", limit=1, progress="none")
    run(cfg)
    run(replace(cfg, results_dir=tmp_path / "b", isolate=False))
    a, b = (ResultsStore(tmp_path / d / "brdfbench.sqlite").frame() for d in "ab")
    accuracy = ["l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae"]
    values = [f[f.metric.isin(accuracy)].sort_values("metric").value.tolist() for f in (a, b)]
    assert values[0] == values[1] and a.config_hash.iloc[0] == b.config_hash.iloc[0]


def test_a_script_without_a_main_guard_runs_once(tmp_path, synthetic_cache):
    """`spawn` would re-run an unguarded script in the worker; the worker starts without it."""
    import subprocess
    import sys

    script = tmp_path / "bench.py"
    script.write_text(
        "from brdfbench.pipeline.config import RunConfig, harness_config\n"
        "from brdfbench.pipeline.sweep import run_job as run\n"
        "print('script body ran')\n"
        f"print(run(RunConfig(representation='merl', representation_params={{}}, label='merl', dataset='synthetic',"
        f" dataset_params={{'size': 'small', 'cache_dir': {str(synthetic_cache)!r}}},"
        f" harness=harness_config(n_random=1024, throughput_batch=256), results_dir={str(tmp_path / 'res')!r},"
        " limit=1, progress='none')))\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("script body ran") == 1 and "'done': 1" in out.stdout
