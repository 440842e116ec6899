"""harness.memory_limit: a worker over it is stopped (SIGKILL) by the supervisor, its cells
become failure rows naming the limit and the peak, and the sweep goes on with a fresh
worker; the limit is run control (never in a configuration's hash)."""

from __future__ import annotations

import logging
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.pipeline.config import harness_config
from brdfbench.pipeline.memory import format_size, parse_size, process_rss
from brdfbench.pipeline.plan import hashed_config
from brdfbench.pipeline.worker import shared_worker
from brdfbench.provenance import config_hash
from brdfbench.pipeline.config import RunConfig
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.store.sqlite import ResultsStore
from brdfbench_representations.lambert import Lambert

MiB, GiB = 2**20, 2**30
QUICK = harness_config(n_random=1024, throughput_batch=256, timeout_s=60)
_HELD: list = []  # what Leaks keeps in the worker between tasks
#: the supervisor reads a worker's memory from /proc; elsewhere the limit is not enforced
needs_proc = pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="no /proc to read a worker's memory from")


class Allocates(Lambert):
    """Touches 3 GiB while fitting a metal."""

    def fit(self, target, *, seed=0):
        if target.category == "metal":
            block = np.ones(3 * GiB, dtype=np.uint8)  # every page written: resident
            assert block[-1] == 1
        return super().fit(target, seed=seed)


class Leaks(Lambert):
    """Keeps 1 GiB in the worker after its fit (a cache that outlives the task)."""

    def fit(self, target, *, seed=0):
        _HELD.append(np.ones(GiB, dtype=np.uint8))
        return super().fit(target, seed=seed)


def _cfg(tmp_path, synthetic_cache, name, harness=QUICK, limit=3, **kw):
    return RunConfig(representation=name, representation_params={}, label=name, dataset="synthetic",
                     dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, harness=harness,
                     results_dir=tmp_path, limit=limit, progress="none", **kw)


def _frame(tmp_path):
    return ResultsStore(tmp_path / "brdfbench.sqlite").frame()


# --------------------------------------------------------------------------- parse_size


@pytest.mark.parametrize("value, size", [
    ("1500MiB", 1500 * MiB), ("2GiB", 2 * GiB), ("1.5 GB", 1_500_000_000), ("1.5GiB", 1536 * MiB),
    ("800M", 800_000_000), ("64 kib", 64 * 1024), ("4096", 4096), ("4096B", 4096), (" 3 TiB ", 3 * 2**40),
    ("1e9", 1_000_000_000), (1_000_000, 1_000_000), (2.0e9, 2_000_000_000), (None, None),
])
def test_parse_size_reads_the_accepted_forms(value, size):
    assert parse_size(value) == size


@pytest.mark.parametrize("value", ["lots", "1500 MiBs", "-1GiB", "0", 0, -5, "1.5.0G", "GiB", "", True, 1.5, [1],
                                   "nan", "1e999GB", "1e-9"])
def test_a_bad_size_is_a_config_error_naming_the_key_value_and_forms(value):
    with pytest.raises(ConfigError) as err:
        harness_config(memory_limit=value)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"harness.memory_limit={value!r}")
    assert '"1500MiB"' in text and "null" in text


@given(st.integers(min_value=1, max_value=2**50), st.sampled_from(["", "B", "KiB", "MiB", "GiB", "kB", "MB", "GB"]),
       st.sampled_from(["", " "]))
def test_a_whole_count_of_any_unit_round_trips(n, unit, space):
    scale = {"": 1, "B": 1, "KiB": 2**10, "MiB": MiB, "GiB": GiB, "kB": 1000, "MB": 1000**2, "GB": 1000**3}[unit]
    assert parse_size(f"{n}{space}{unit}" if unit else str(n)) == n * scale
    assert parse_size(f"{n}{space}{unit.lower()}" if unit else n) == n * scale


@given(st.integers(min_value=1, max_value=10**6))
def test_format_size_reads_back_to_the_same_mib(mib):
    assert parse_size(format_size(mib * MiB).replace(" ", "")) == mib * MiB


@given(st.integers(min_value=1, max_value=10**4), st.integers(min_value=1, max_value=MiB - 1))
def test_a_whole_peak_just_over_a_limit_reads_over_it(mib, extra):
    assert format_size(mib * MiB, whole=True) == f"{mib} MiB"
    assert format_size(mib * MiB + extra, whole=True) == f"{mib + 1} MiB"


# --------------------------------------------------------------------------- config and hash


@pytest.mark.parametrize("kind", ["accuracy", "render", "convergence", "generation"])
def test_every_harness_kind_takes_the_key_and_leaves_it_out_of_its_hash(kind):
    limited = harness_config(kind, memory_limit="2GiB")
    assert limited.memory_limit == 2 * GiB and harness_config(kind).memory_limit is None
    assert "memory_limit" not in limited.hashed() and limited.hashed() == harness_config(kind).hashed()


def test_memory_limit_does_not_change_the_config_hash(tmp_path, synthetic_cache):
    checked_cls = registry.get("harnesses", "accuracy").load()
    hashes = {config_hash(hashed_config(_cfg(tmp_path, synthetic_cache, "lambert", harness=replace(QUICK, memory_limit=v)),
                                        checked_cls)) for v in (None, "1500MiB", 8 * GiB)}
    assert len(hashes) == 1


def test_the_cli_refuses_a_bad_limit_in_one_line(tmp_path, cli):
    result = cli("dataset=synthetic", "dataset.params.size=small", "harness=quick", "limit=1", "representation=lambert",
                 "harness.memory_limit=plenty", cwd=tmp_path)
    assert result.returncode == 2
    assert "harness.memory_limit='plenty'" in result.stderr and "1500MiB" in result.stderr
    assert not (tmp_path / "results" / "brdfbench.sqlite").exists()


# --------------------------------------------------------------------------- enforcement


@needs_proc
def test_a_worker_over_the_limit_is_stopped_and_the_sweep_goes_on(tmp_path, synthetic_cache, plugin):
    counts = run(_cfg(tmp_path, synthetic_cache, plugin(Allocates), harness=replace(QUICK, memory_limit="1500MiB")))
    assert counts == {"done": 2, "skipped": 0, "failed": 1}
    df = _frame(tmp_path)
    failed = df[df.status == "failed"]
    assert list(failed.material) == ["synth-metal-chrome-01"]
    message = failed.message.iloc[0]
    match = re.fullmatch(r"memory limit 1500 MiB exceeded \(peak (\d+) MiB\) while fitting allocates to "
                         r"synth-metal-chrome-01: worker stopped", message)
    assert match, message
    assert 1500 < int(match.group(1)) < 3 * 1024  # stopped on the way up, before the 3 GiB were all touched
    assert set(df[df.status == "ok"].material) == {"synth-plastic-green-00", "synth-metallic-paint-blue-02"}


@needs_proc
def test_the_cli_exits_1_with_a_failure_row_for_the_limit(tmp_path, cli, plugin):
    name = plugin(Allocates)
    result = cli("dataset=synthetic", "dataset.params.size=small", "harness=quick", "harness.n_random=1024",
                 "limit=2", "representation=lambert", f"representation.name={name}", "harness.memory_limit=1500MiB", cwd=tmp_path)
    assert result.returncode == 1, result.stderr[-2000:]
    df = ResultsStore(tmp_path / "results" / "brdfbench.sqlite").frame()
    assert set(df.status) == {"ok", "failed"}
    assert "memory limit 1500 MiB exceeded (peak" in df[df.status == "failed"].message.iloc[0]


def test_a_normal_plugin_under_a_generous_limit_runs_and_keeps_its_hash(tmp_path, synthetic_cache):
    limited = run(_cfg(tmp_path, synthetic_cache, "lambert", harness=replace(QUICK, memory_limit="8GiB"), limit=2))
    assert limited == {"done": 2, "skipped": 0, "failed": 0}
    df = _frame(tmp_path)
    assert (df.status == "ok").all()
    fit = df[df.metric == "peak_rss_fit"].value
    assert (fit < 8 * GiB).all()
    assert run(_cfg(tmp_path, synthetic_cache, "lambert", limit=2)) == {"done": 0, "skipped": 2, "failed": 0}


@needs_proc
def test_a_worker_left_over_the_limit_is_replaced_before_the_next_task(tmp_path, synthetic_cache, plugin):
    worker = shared_worker()
    worker.stop()
    fresh = process_rss(worker.ensure().process.pid)
    assert run(_cfg(tmp_path / "a", synthetic_cache, plugin(Leaks), limit=1))["done"] == 1  # no limit: it keeps 1 GiB
    held, pid = process_rss(worker.process.pid), worker.process.pid
    assert held > fresh + GiB
    limit = held - 512 * MiB  # below this worker, above a fresh one and a small lambert job (~700 MiB peak)
    counts = run(_cfg(tmp_path / "b", synthetic_cache, "lambert", harness=replace(QUICK, memory_limit=limit), limit=1))
    assert counts == {"done": 1, "skipped": 0, "failed": 0}
    assert worker.process.pid != pid


@needs_proc
def test_a_limit_below_a_fresh_worker_fails_its_cells_naming_it(tmp_path, synthetic_cache, caplog):
    with caplog.at_level(logging.WARNING):
        counts = run(_cfg(tmp_path, synthetic_cache, "lambert", harness=replace(QUICK, memory_limit="20MiB"), limit=1))
    assert counts == {"done": 0, "skipped": 0, "failed": 1}
    message = _frame(tmp_path).message.iloc[0]
    assert re.fullmatch(r"memory limit 20 MiB exceeded \(peak \d+ MiB\) while starting the worker process: "
                        r"worker stopped", message), message
    assert "below the resident memory of a fresh worker" in caplog.text


def test_in_process_runs_warn_that_the_limit_is_not_enforced(tmp_path, synthetic_cache, caplog):
    from brdfbench.pipeline import sweep

    sweep._INLINE_WARNED.discard("memory_limit")
    with caplog.at_level(logging.WARNING):
        counts = run(_cfg(tmp_path, synthetic_cache, "lambert", harness=replace(QUICK, memory_limit="20MiB"), limit=1,
                          isolate=False))
    assert counts["done"] == 1
    assert "harness.memory_limit is not enforced" in caplog.text


class Hangs(Lambert):
    def fit(self, target, *, seed=0):
        import time

        time.sleep(60)
        return self


def test_the_time_limit_still_holds_while_memory_is_watched(tmp_path, synthetic_cache, plugin):
    harness = replace(QUICK, timeout_s=2, memory_limit="8GiB")
    counts = run(_cfg(tmp_path, synthetic_cache, plugin(Hangs), harness=harness, limit=1))
    assert counts["failed"] == 1
    assert "exceeded the time limit of 2 s (worker process killed)" in _frame(tmp_path).message.iloc[0]
