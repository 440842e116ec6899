"""Materials fitted side by side in single-threaded helper processes (`fit_workers`,
`Representation.fits_in_parallel`): the same figures as one after another, the count on
every row, failures that stay with their material, and a worker that still exits cleanly."""

from __future__ import annotations

import pytest

from brdfbench.store.sqlite import ResultsStore

MATERIALS = "materials=[synth-plastic-green-00,synth-metal-chrome-01,synth-fabric-cotton-green-03]"
ARGS = ["dataset.params.size=small", "harness=quick", "progress=lines", MATERIALS]
#: figures of the machine, not of the model
MACHINE = {"fit_time", "evals_per_s", "peak_rss_fit", "peak_rss_eval", "calibration_gflops", "fit_batch", "fit_workers"}


def _frame(folder):
    return ResultsStore(folder / "brdfbench.sqlite").frame()


def test_side_by_side_fits_give_the_figures_of_one_after_another(tmp_path, cli):
    par, seq = tmp_path / "par", tmp_path / "seq"
    assert cli("representation=blinn_phong", *ARGS, "fit_workers=2", f"results_dir={par}", cwd=tmp_path).returncode == 0
    assert cli("representation=blinn_phong", *ARGS, "fit_workers=1", f"results_dir={seq}", cwd=tmp_path).returncode == 0
    a, b = _frame(par), _frame(seq)
    assert (a.status == "ok").all() and len(a) == len(b) + 6  # fit_batch and fit_workers of three materials
    assert set(a[a.metric == "fit_workers"].value) == {2.0} and set(a[a.metric == "fit_batch"].value) == {3.0}
    assert not b.metric.isin(["fit_workers", "fit_batch"]).any()  # one at a time: as before
    key = ["material", "metric"]
    fa = a[~a.metric.isin(MACHINE)].set_index(key).value.sort_index()
    fb = b[~b.metric.isin(MACHINE)].set_index(key).value.sort_index()
    assert fa.index.equals(fb.index)
    assert (fa == fb).all(), (fa - fb)[fa != fb]  # bit for bit: each fit from the same seed on one thread


def test_workers_1_fits_one_after_another_unless_fit_workers_is_given(tmp_path, cli):
    one = tmp_path / "one"
    assert cli("representation=blinn_phong", *ARGS, "workers=1", f"results_dir={one}", cwd=tmp_path).returncode == 0
    assert not _frame(one).metric.isin(["fit_workers"]).any()


def test_the_fits_run_in_helper_processes(tmp_path, cli, plugin):
    """Each fit's process id as its fit loss: one after another, the worker's; side by side,
    helpers', never the worker's."""
    from fit_plugins import WhereFitted

    name = plugin(WhereFitted)
    assert cli("representation=lambert", f"representation.name={name}", *ARGS, "fit_workers=1", f"results_dir={tmp_path / 's'}", cwd=tmp_path).returncode == 0
    worker = set(_frame(tmp_path / "s").query("metric == 'fit_loss'").value)
    assert len(worker) == 1
    assert cli("representation=lambert", f"representation.name={name}", *ARGS, "fit_workers=2", f"results_dir={tmp_path / 'p'}", cwd=tmp_path).returncode == 0
    helpers = set(_frame(tmp_path / "p").query("metric == 'fit_loss'").value)
    assert helpers and not helpers & worker


def test_a_fit_that_raises_fails_its_material_only(tmp_path, cli, plugin):
    from fit_plugins import VICTIM, RaisesOnOne

    name = plugin(RaisesOnOne)
    assert cli("representation=lambert", f"representation.name={name}", *ARGS, "fit_workers=2", f"results_dir={tmp_path}", cwd=tmp_path).returncode == 1
    df = _frame(tmp_path)
    failed = df[df.status == "failed"]
    assert set(failed.material) == {VICTIM}
    assert failed.message.iloc[0] == f"ValueError: cannot fit {VICTIM}"
    assert df[df.status == "ok"].material.nunique() == 2


def test_a_helper_that_dies_fails_its_own_fit_only_and_the_next_job_gets_fresh_helpers(tmp_path, cli, plugin):
    from fit_plugins import VICTIM, KillsItsHelper

    name = plugin(KillsItsHelper)
    out = cli("representation=lambert", f"representation.name={name}", *ARGS, "fit_workers=2",
              f"results_dir={tmp_path}", cwd=tmp_path)
    assert out.returncode == 1
    # the same worker, fresh helpers
    assert cli("representation=blinn_phong", *ARGS, "fit_workers=2", f"results_dir={tmp_path}",
               cwd=tmp_path).returncode == 0
    df = _frame(tmp_path)
    mine = df[df.plugin == name]
    failed = mine[mine.status == "failed"]
    assert set(failed.material) == {VICTIM}  # the others ran again, alone, in fresh helpers
    assert failed.message.iloc[0] == "a fit helper process died (segmentation fault (SIGSEGV)) while fitting this material"
    assert mine[mine.status == "ok"].material.nunique() == 2
    after = df[df.plugin == "blinn_phong"]
    assert (after.status == "ok").all() and after.material.nunique() == 3


def test_the_worker_exits_cleanly_after_side_by_side_fits(tmp_path):
    """The helpers stop with the worker: it returns when asked (exit status 0), rather than
    waiting on them until it is killed."""
    from omegaconf import OmegaConf

    from brdfbench.hydra.jobs import to_run_config
    from brdfbench.pipeline.plan import Task
    from brdfbench.pipeline.worker import Worker

    cfg = OmegaConf.create({"representation": {"name": "blinn_phong"}, "dataset": {"name": "synthetic",
                            "params": {"size": "small"}}, "harness": {"kind": "accuracy", "metrics": ["l1"], "n_random": 4096},
                            "results_dir": str(tmp_path), "fit_workers": 2, "progress": "none"})
    job = to_run_config(cfg)
    worker = Worker()
    cells = []
    outcome = worker.run(job, Task(("synth-plastic-green-00", "synth-metal-chrome-01")), cells.append)
    assert outcome.status == "done" and [c[3] for c in cells] == ["ok", "ok"]
    process = worker.process
    worker.stop()
    assert process.exitcode == 0


@pytest.mark.parametrize("value, fresh", [("0", False), ("-1", False), ("999", False), ("abc", True)])
def test_a_bad_fit_workers_is_one_line_naming_the_key_and_range(tmp_path, cli, cli_process, value, fresh):
    """In this process, and once as a user starts it (a fresh interpreter)."""
    run = cli_process if fresh else cli
    out = run("representation=blinn_phong", *ARGS, f"fit_workers={value}", f"results_dir={tmp_path}", cwd=tmp_path)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("brdfbench: error: fit_workers=")
    assert value in lines[0] and ": expected auto or a whole number from 1 to " in lines[0]
    assert not (tmp_path / "brdfbench.sqlite").exists()


def test_a_hanging_fit_is_cut_at_the_limit_and_its_helper_dies_with_the_worker(tmp_path, cli, plugin, monkeypatch):
    import os
    import time

    from fit_plugins import VICTIM, HangsOnOne

    name = plugin(HangsOnOne)
    pid_file = tmp_path / "helper.pid"
    monkeypatch.setenv("BRDFBENCH_TEST_PID_FILE", str(pid_file))
    out = cli("representation=lambert", f"representation.name={name}", *ARGS, "fit_workers=2", "harness.timeout_s=3",
              f"results_dir={tmp_path}", cwd=tmp_path)
    assert out.returncode == 1
    df = _frame(tmp_path)
    assert (df.status == "failed").all() and df.material.nunique() == 3  # the task's fits went with the worker
    assert "exceeded the time limit" in df.message.iloc[0]
    assert VICTIM in set(df.material)
    pid = int(pid_file.read_text())
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and os.path.exists(f"/proc/{pid}") and "Z" not in _state(pid):
        time.sleep(0.1)
    assert not os.path.exists(f"/proc/{pid}") or "Z" in _state(pid), "the hung helper outlived its worker"


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "Z"
