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


def test_calls_are_the_steps_between_files_cut_at_the_first_plugin():
    chains = [[CLI, APP, (SWEEP, "run_one"), (PLUGIN, "fit"), ("brdfbench/protocols/representation.py", "__init__")]]
    assert run_path.calls(chains, {PLUGIN}) == {
        (CLI[0], APP[0]): {"main -> run_hydra"}, (APP[0], SWEEP): {"run_hydra -> run_one"}, (SWEEP, PLUGIN): {"run_one -> fit"}}
    assert (PLUGIN, "brdfbench/protocols/representation.py") in run_path.calls(chains)  # uncut: the plugin's insides


def test_a_file_that_calls_back_into_its_caller_is_a_cycle_and_leaves_no_reading_order():
    sweeper, worker, record = "hydra_plugins/brdfbench_sweeper/__init__.py", "brdfbench/pipeline/worker.py", "brdfbench/pipeline/record.py"
    callback = [[CLI, APP, (sweeper, "sweep"), (APP[0], "_app"), (SWEEP, "run_one")]]  # Hydra's task function
    assert run_path.call_cycles(run_path.calls(callback)) == [[APP[0], sweeper]]
    files = [CLI[0], APP[0], sweeper, SWEEP]
    assert run_path.reading_order(files, run_path.calls(callback)) is None
    # the same run with the entry in the CLI: every call leads on, and the order says where to read each file
    forward = [[CLI, (sweeper, "sweep"), (APP[0], "_app"), (SWEEP, "run_one"), (worker, "run"), (record, "cell")],
               [CLI, (APP[0], "checked_argv")], [CLI, APP, (SWEEP, "run_one"), (record, "__init__")]]
    edges = run_path.calls(forward)
    assert run_path.call_cycles(edges) == []
    assert run_path.reading_order([CLI[0], APP[0], SWEEP, record, sweeper, worker], edges) == [
        CLI[0], sweeper, APP[0], SWEEP, worker, record]
    # a closure of the sweep handed to the worker calls back into the sweep
    back = forward + [[CLI, (sweeper, "sweep"), (APP[0], "_app"), (SWEEP, "run_one"), (worker, "run"), (SWEEP, "cell")]]
    assert run_path.call_cycles(run_path.calls(back)) == [[SWEEP, worker]]
