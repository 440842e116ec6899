"""tests/tools/run_path.py's reading of traced call chains: the spine is the chains cut at the
first plugin file, read as a tree of files; a file at two places is a return visit, and one
from which the control goes on into other files is counted apart."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

import run_path  # noqa: E402

CLI, APP, SWEEP, PLAN = ("brdfbench/cli.py", "main"), ("brdfbench/hydra/app.py", "run_hydra"), "brdfbench/pipeline/sweep.py", "brdfbench/pipeline/plan.py"
PLUGIN, STORE = "representations/lambert.py", "brdfbench/store/sqlite.py"


def test_chains_are_cut_at_the_first_plugin_and_prefixes_dropped():
    chains = [
        [CLI, APP, (SWEEP, "check_jobs"), (PLAN, "check"), (PLUGIN, "__init__"), ("brdfbench/coords.py", "f")],
        [CLI, APP, (SWEEP, "check_jobs")],  # reaches no plugin: not on the spine
        [CLI, APP, (SWEEP, "run_one"), (PLAN, "make_plan"), (STORE, "done_cells")],
        [CLI, APP, (SWEEP, "run_one"), (PLAN, "make_plan"), (STORE, "done_cells")],  # the same way in, once
    ]
    ways = run_path.spine(chains, {PLUGIN, STORE})
    assert [[f for f, _ in w] for w in ways] == [
        [CLI[0], APP[0], SWEEP, PLAN, PLUGIN], [CLI[0], APP[0], SWEEP, PLAN, STORE]]


def test_a_file_read_at_two_places_is_a_return_and_onward_when_it_calls_on():
    ways = [
        [CLI, APP, (SWEEP, "check_jobs"), (PLAN, "check"), (PLUGIN, "__init__")],
        [CLI, APP, (SWEEP, "run_one"), (PLAN, "make_plan"), (STORE, "done_cells")],  # one place: sweep -> plan
        [CLI, APP, ("hydra_plugins/brdfbench_sweeper/__init__.py", "sweep"), (SWEEP, "run_one"), (STORE, "write")],
        [CLI, APP, ("brdfbench/report.py", "write_reports"), (PLUGIN, "eval")],
    ]
    order, lines, onward = run_path.read(run_path.tree(ways))
    assert order == [CLI[0], APP[0], SWEEP, PLAN, PLUGIN, STORE, "hydra_plugins/brdfbench_sweeper/__init__.py",
                     SWEEP, STORE, "brdfbench/report.py", PLUGIN]
    assert onward == [SWEEP]  # entered again under the sweeper, and calling on into the store
    assert lines[2].strip() == f"{SWEEP} (check_jobs, run_one)" and lines[7].endswith("<- again")
