"""One way into a run (issue 31): through the CLI, in this process, each job is built once
and checked once in each process it runs in; the report is written by the pipeline
(`brdfbench.pipeline.sweep`), not by the Hydra adapter; bad input still fails before any
work, in one line, with exit 2 and nothing written."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import pytest

from brdfbench.hydra import app as hydra_app
from brdfbench.plugins import registry
from brdfbench.data.synthetic import synthetic_dataset
from brdfbench.pipeline import plan, sweep
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.plugins.specs import DatasetSpec

from test_bad_input import one_error_line  # tests/e2e is on sys.path (pytest prepend import mode)

SMALL = ["dataset.name=counted", "dataset.params.size=small", "harness=quick", "progress=none", "workers=1"]
CHECKS = "BRDFBENCH_TEST_CHECKS"


def counted_synthetic(tag: int = 0, **params):
    """The synthetic set; each call (one per check of a job: `plan.check` is its only caller)
    adds "PID TAG" to the file $BRDFBENCH_TEST_CHECKS, whichever process makes it."""
    with open(os.environ[CHECKS], "a", encoding="utf-8") as fh:
        fh.write(f"{os.getpid()} {tag}\n")
    return synthetic_dataset(**params)


@pytest.fixture
def checks(tmp_path, monkeypatch):
    """`checks()`: the (process id, job tag) of every check made so far, in this process or any
    other (the cell worker gets the registration and the environment with each task)."""
    log = tmp_path / "checks.log"
    monkeypatch.setenv(CHECKS, str(log))
    registry.register("datasets", DatasetSpec(name="counted", description="test", target=f"{__name__}:counted_synthetic"))
    yield lambda: [tuple(line.split()) for line in log.read_text().splitlines()] if log.exists() else []
    registry.unregister("datasets", "counted")


@pytest.fixture
def built(monkeypatch):
    """`built()`: how many times a job's config has been built from Hydra's config (in this process)."""
    calls = []
    real = hydra_app.to_run_config

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(hydra_app, "to_run_config", counting)
    return lambda: len(calls)


@pytest.fixture
def checked(monkeypatch):
    """`checked()`: how many times `plan.check` has run in this process."""
    calls = []
    real = plan.check
    monkeypatch.setattr(plan, "check", lambda job: calls.append(1) or real(job))
    return lambda: len(calls)


HERE = str(os.getpid())


def test_a_lone_job_is_built_once_and_checked_once_in_each_process(tmp_path, cli, checks, built, checked):
    res = tmp_path / "res"
    out = cli("representation=lambert", *SMALL, "limit=2", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    made = checks()
    assert [pid for pid, _ in made].count(HERE) == 1  # the sweep's start; the job ran on that check
    assert len(made) == 2 and len({pid for pid, _ in made}) == 2  # and once in its cell worker
    assert built() == 1 and checked() == 1
    assert (res / "leaderboard.md").is_file()


def test_each_job_of_a_sweep_is_built_once_and_checked_once_in_each_process(tmp_path, cli, checks, built, checked):
    """Two jobs that differ only in what no check reads (their seed) are each checked once."""
    res = tmp_path / "res"
    out = cli("-m", "representation=lambert", "seed=0,1", *SMALL, "limit=1", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    made = checks()
    assert [pid for pid, _ in made].count(HERE) == 2 and len(made) == 4, made  # each job here, and in the worker
    assert built() == 2 and checked() == 2
    assert "sweep: 2 jobs, 2 cells done" in out.stdout


def test_the_launcher_is_the_only_one_to_compose_a_job_again(tmp_path, cli, checks, monkeypatch):
    """The sweep's start composes every job (for its check); then only the launcher composes
    each job, to hand it to the task function: the sweeper does not compose the batch a third
    time to validate it."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    calls = []
    real = ConfigLoaderImpl.load_sweep_config
    monkeypatch.setattr(ConfigLoaderImpl, "load_sweep_config", lambda self, *a, **k: calls.append(1) or real(self, *a, **k))
    out = cli("-m", "representation=lambert", "seed=0,1,2", *SMALL, "limit=1", f"results_dir={tmp_path / 'res'}",
              cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert len(calls) == 3


def test_in_process_cells_check_their_job_once(tmp_path, cli, checks, built, checked):
    out = cli("-m", "representation=lambert", "+dataset.params.tag=0,1", "isolate=false", *SMALL, "limit=1",
              f"results_dir={tmp_path / 'res'}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert sorted(checks()) == [(HERE, "0"), (HERE, "1")]
    assert built() == 2 and checked() == 2


def test_the_report_is_written_by_the_pipeline(tmp_path, cli, checks, monkeypatch):
    written = []
    real = sweep.write_reports
    monkeypatch.setattr(sweep, "write_reports", lambda folder, *a, **k: written.append(Path(folder)) or real(folder, *a, **k))
    res = tmp_path / "res"
    out = cli("-m", "representation=lambert,merl", *SMALL, "limit=1", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert written == [res] and f"leaderboard: {res / 'leaderboard.md'}" in out.stdout
    package = Path(hydra_app.__file__).parent
    adapters = sorted(package.glob("*.py"))
    assert [a.name for a in adapters if a.name == "app.py"], adapters
    for adapter in adapters:  # the Hydra adapter holds no report logic
        text = adapter.read_text(encoding="utf-8")
        assert "write_reports" not in text and "from .report" not in text, adapter.name


def test_a_bad_job_stops_the_sweep_before_any_work(tmp_path, cli, checks):
    res = tmp_path / "res"
    out = cli("-m", "representation=lambert", "limit=1,0", *SMALL, f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 2, out.stdout + out.stderr
    lines = out.stderr.strip().splitlines()
    assert lines[-2].startswith("brdfbench: error: job 1 (") and lines[-2].endswith("limit=0 must be ≥ 1")
    assert lines[-1] == "brdfbench: 1 of 2 job(s) are invalid; nothing was run"
    assert checks() == [(HERE, "0")]  # job 0 checked, here only: nothing ran
    assert not res.exists()
    assert not hydra_app.PREPARED  # nothing kept for jobs that never run


def test_a_bad_lone_job_is_one_line_and_writes_nothing(tmp_path, cli, checks, checked):
    res = tmp_path / "res"
    line = one_error_line(cli("representation=lambert", "+representation.params.bogus=1", *SMALL, "limit=1",
                              f"results_dir={res}", cwd=tmp_path))
    assert "representation.params.bogus" in line
    assert checked() == 1 and checks() == []  # refused before its data was loaded
    assert not res.exists()


def test_a_config_folder_on_the_command_line_is_found_when_the_sweep_is_checked(tmp_path, cli, checks):
    """The sweep's up-front check composes each job as its launcher does, hydra.* overrides
    included (a `hydra.searchpath` option used to be refused there)."""
    conf = tmp_path / "conf" / "representation"
    conf.mkdir(parents=True)
    (conf / "mine.yaml").write_text("name: lambert\nlabel: mine\nparams: {}\n")
    res = tmp_path / "res"
    out = cli(f"hydra.searchpath=[file://{tmp_path / 'conf'}]", "representation=mine", *SMALL, "limit=1",
              f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "mine: 1 done" in out.stdout and len(checks()) == 2


def test_a_prepared_job_is_taken_once_and_only_by_its_own_overrides():
    hydra_app.PREPARED[7] = (["limit=1"], "config", "checked")
    assert hydra_app.prepared(7, ["limit=2"]) is None  # not this job's: it builds its own
    assert 7 not in hydra_app.PREPARED
    hydra_app.PREPARED[7] = (["limit=1"], "config", "checked")
    assert hydra_app.prepared(7, ["limit=1"]) == ("config", "checked")
    assert hydra_app.prepared(7, ["limit=1"]) is None


def _job(results: Path, cache, tag: int, **kw) -> RunConfig:
    return RunConfig(representation="lambert", representation_params={}, label="lambert", dataset="counted",
                     dataset_params={"size": "small", "cache_dir": str(cache), "tag": tag},
                     harness=harness_config(n_random=4096, throughput_batch=1024), limit=1, seed=tag,
                     results_dir=results, isolate=False, progress="none", **kw)


def test_run_sweep_checks_every_job_once_then_runs_them_and_writes_the_report(tmp_path, checks, synthetic_cache,
                                                                             capsys):
    res = tmp_path / "res"
    assert sweep.run_sweep([_job(res, synthetic_cache, 0), _job(res, synthetic_cache, 1)]) == 0
    assert sorted(checks()) == [(HERE, "0"), (HERE, "1")]
    assert (res / "leaderboard.md").is_file() and "sweep: 2 jobs, 2 cells done" in capsys.readouterr().out

    other = tmp_path / "other"
    bad = replace(_job(other, synthetic_cache, 1), representation_params={"bogus": 1})
    assert sweep.run_sweep([_job(other, synthetic_cache, 0), bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("brdfbench: error: job 1 (lambert): ") and "representation.params.bogus" in err[0]
    assert err[1] == "brdfbench: 1 of 2 job(s) are invalid; nothing was run"
    assert not other.exists()
