"""One run followed from the command line to its plugins (tests/tools/run_path.py): no file on
the way in calls back into a file that called it, so the files read once each, in order; and
the framework's files on the way number at most 15."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

import run_path  # noqa: E402


def test_one_run_reads_forward_through_at_most_15_framework_files():
    m = run_path.measure(run_path.DEFAULT)
    assert m["cycles"] == [], "\n".join(" <-> ".join(g) for g in m["cycles"])
    assert run_path.reading_order(m["files"], m["edges"]) is not None
    core = [f for f in m["files"] if f not in m["plugins"]]
    assert len(core) <= 15, core
    # the spine does reach the run's plugins: the representation, the store and both reports
    for plugin in ("representations/lambert.py", "brdfbench/store/sqlite.py", "leaderboard/report.py", "leaderboard/html.py"):
        assert plugin in m["files"]
