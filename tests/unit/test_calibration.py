"""The machine-speed figure stored with every cell, and the report's table of it."""

from __future__ import annotations

import math

import pandas as pd

from brdfbench.pipeline import calibration
from leaderboard import machines, markdown


def test_the_product_is_timed_as_a_positive_speed():
    m = calibration.measure()
    assert m.metric == calibration.METRIC and m.unit == "GFLOP/s" and m.higher_is_better
    assert math.isfinite(m.value) and m.value > 0


def _rows(values, host="a", threads=2):
    return [{"metric": calibration.METRIC, "status": "ok", "value": v, "host": host, "cpu_model": "cpu",
             "threads": threads, "device": "cpu", "run_id": run} for run, v in values]


def test_speeds_are_summarised_per_host_and_thread_count_over_runs():
    df = pd.DataFrame(_rows([("r1", 100.0), ("r1", 110.0), ("r2", 50.0), ("r3", 80.0)])
                      + _rows([("r4", 30.0)], threads=1) + _rows([("r5", 7.0)], host="b"))
    speeds = {(m.host, m.threads): m for m in machines.machine_speeds(df)}
    a2 = speeds[("a", 2)]
    assert (a2.runs, a2.median, a2.low, a2.high) == (3, 80.0, 50.0, 105.0)  # run r1: the median of its cells
    assert speeds[("a", 1)].runs == 1 and speeds[("b", 2)].median == 7.0


def test_the_report_shows_the_table_and_never_ranks_it():
    base = {"config_hash": "h", "representation": "lambert", "dataset": "synthetic", "dataset_fingerprint": "f",
            "material": "m", "category": "plastic", "unit": "log", "higher_is_better": False, "status": "ok",
            "message": "", "seed": 0, "package_version": "0", "git_sha": "g", "timestamp": 0.0, "run_id": "r1",
            "host": "a", "cpu_model": "cpu", "threads": 2, "device": "cpu", "params": "{}", "harness": "accuracy"}
    df = pd.DataFrame([{**base, "metric": "l1_log_cos", "value": 0.1},
                       {**base, "metric": calibration.METRIC, "value": 120.0, "unit": "GFLOP/s", "higher_is_better": True}])
    text = markdown.render(df, "store")
    assert "## Machine speed" in text and "| a | cpu | cpu | 2 | 1 | 120 |" in text
    assert calibration.METRIC not in text
