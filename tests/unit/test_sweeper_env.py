"""The brdfbench sweeper names joblib's pool in the environment for its jobs only: after the
sweep, finished or failed, the variable is as it was (a later sweep in the same process,
on one worker, must not record `parallel:N`)."""

from __future__ import annotations

import os
from types import SimpleNamespace

import pytest
from omegaconf import OmegaConf

import hydra_plugins.brdfbench_sweeper as S
from brdfbench import parallelism


class Launcher:
    def __init__(self, seen, fail=False):
        self.seen, self.fail = seen, fail

    def launch(self, batch, initial_job_idx):
        self.seen.append(os.environ.get(parallelism.LAUNCHER_ENV))
        if self.fail:
            raise RuntimeError("a job failed")
        return [SimpleNamespace(return_value=None) for _ in batch]


def _sweeper(monkeypatch, tmp_path, launcher):
    sweeper = S.SectionSweeper()
    sweeper.config = OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path)}}})
    sweeper.launcher, sweeper.hydra_context = object(), SimpleNamespace(config_loader=None)

    def parallel(jobs):  # what _parallel does where several jobs run at once
        os.environ[parallelism.LAUNCHER_ENV] = "parallel:2"
        return launcher, jobs

    monkeypatch.setattr(sweeper, "_parallel", parallel)
    monkeypatch.setattr(sweeper, "validate_batch_is_legal", lambda batch: None)
    monkeypatch.setattr(S, "job_overrides", lambda *args: [["a=1"], ["a=2"]])
    monkeypatch.setattr(S.OverridesParser, "create", staticmethod(lambda config_loader: None))
    return sweeper


@pytest.mark.parametrize("before", [None, "slurm"])
@pytest.mark.parametrize("fail", [False, True])
def test_the_pool_is_named_for_the_jobs_only(monkeypatch, tmp_path, before, fail):
    if before is None:
        monkeypatch.delenv(parallelism.LAUNCHER_ENV, raising=False)
    else:
        monkeypatch.setenv(parallelism.LAUNCHER_ENV, before)
    seen = []
    sweeper = _sweeper(monkeypatch, tmp_path, Launcher(seen, fail))
    if fail:
        with pytest.raises(RuntimeError, match="a job failed"):
            sweeper.sweep([])
    else:
        sweeper.sweep([])
    assert seen and set(seen) == {"parallel:2"}
    assert os.environ.get(parallelism.LAUNCHER_ENV) == before
