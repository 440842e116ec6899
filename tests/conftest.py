"""Shared fixtures: a small cached synthetic set, isolated results folders."""

from __future__ import annotations

import contextlib
import io
import logging
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Under pytest-xdist each worker runs single-threaded, and so do the processes it starts
# (CLI runs, cell workers): two workers on two cores, not four threads fighting for them.
# Set before torch is imported by any test module.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_var] = "1"
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    """Benchmarks time in one process: --benchmark-enable turns the xdist workers off
    (pytest-benchmark cannot time under xdist, and two workers would halve each other)."""
    if config.getoption("benchmark_enable", default=False) and hasattr(config.option, "numprocesses"):
        config.option.numprocesses = 0
        config.option.dist = "no"


@pytest.fixture(scope="session")
def synthetic_cache(tmp_path_factory) -> Path:
    """One cache folder for the whole session, so the small set is generated once."""
    return tmp_path_factory.mktemp("synthetic-cache")


@pytest.fixture(scope="session")
def small_dataset(synthetic_cache):
    from brdfbench.data.synthetic import synthetic_dataset

    return synthetic_dataset("small", seed=0, cache_dir=str(synthetic_cache))


@pytest.fixture(autouse=True)
def _isolated_cache(monkeypatch, synthetic_cache):
    monkeypatch.setenv("BRDFBENCH_CACHE", str(synthetic_cache))
    yield


def pytest_report_header(config):
    workers = getattr(config.option, "numprocesses", None)
    return (f"brdfbench tests; xdist workers={workers or 0} (one thread each); "
            f"torch threads in this process={os.environ.get('OMP_NUM_THREADS', 'default')}")


@dataclass
class CliResult:
    """What a `brdfbench` invocation returned: the exit status and its two streams."""

    returncode: int
    stdout: str
    stderr: str


def _exit_status(code) -> int:
    if code is None:
        return 0
    return code if isinstance(code, int) else 1


def run_in_process(args, cwd) -> CliResult:
    """`brdfbench *args` through `brdfbench.cli.main` in this process, as the console script
    calls it: the same parsing, validation, Hydra composition and exit status, without a new
    interpreter; cells still run in the (shared) worker process. Restores what the CLI
    changes in this process (cwd, argv, environment, logging, Hydra's global state)."""
    from hydra.core.global_hydra import GlobalHydra

    from brdfbench import cli

    out, err = io.StringIO(), io.StringIO()
    saved_env, saved_argv, saved_cwd = dict(os.environ), sys.argv[:], os.getcwd()
    root = logging.getLogger()
    saved_log = (root.handlers[:], root.level)
    try:
        os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = cli.main([str(a) for a in args])
            except SystemExit as exc:
                status = _exit_status(exc.code)
    finally:
        os.chdir(saved_cwd)
        sys.argv[:] = saved_argv
        os.environ.clear()
        os.environ.update(saved_env)
        root.handlers[:] = saved_log[0]
        root.setLevel(saved_log[1])
        GlobalHydra.instance().clear()
    return CliResult(status, out.getvalue(), err.getvalue())


def run_subprocess(args, cwd, env=None, timeout=900) -> CliResult:
    """`brdfbench *args` in a fresh interpreter: for what only a real process shows (signals,
    exit at interpreter shutdown, worker lifetime)."""
    done = subprocess.run([sys.executable, "-m", "brdfbench.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env=env, timeout=timeout)
    return CliResult(done.returncode, done.stdout, done.stderr)


@pytest.fixture
def cli():
    """`cli(*args, cwd=...)`: run `brdfbench *args` through `brdfbench.cli.main` in this process."""
    return lambda *args, cwd: run_in_process(args, cwd)


@pytest.fixture(scope="session")
def cli_session(synthetic_cache):
    """`cli_session(*args, cwd=...)`: `cli` for module and session fixtures (the session's synthetic cache)."""
    def run(*args, cwd):
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("BRDFBENCH_CACHE", str(synthetic_cache))
            return run_in_process(args, cwd)

    return run


@pytest.fixture
def cli_process():
    """`cli_process(*args, cwd=..., env=None)`: run `brdfbench *args` in a fresh interpreter."""
    return lambda *args, cwd, env=None: run_subprocess(args, cwd, env)


@pytest.fixture(scope="session")
def nbrdf_release_dir() -> Path:
    """The published NBRDF networks (../shared/data/neural-brdf); the test skips where absent."""
    from brdfbench.data.nbrdf_release import find_release_dir

    found = find_release_dir()
    if found is None:
        pytest.skip("NBRDF release (shared/data/neural-brdf) not found; set BRDFBENCH_NBRDF_DIR")
    return found


@pytest.fixture(scope="session")
def nbrdf_release(nbrdf_release_dir):
    """The release as a dataset, opened once per session."""
    from brdfbench.data.nbrdf_release import nbrdf_release_dataset

    return nbrdf_release_dataset(str(nbrdf_release_dir))


@pytest.fixture(scope="session")
def fitted():
    """`fitted(name, **params)`: the registered representation `name` fitted to the kit's
    reference material (trained first, on `train` materials, where it needs training), made
    once per session and shared by every test file that asks for the same one. Tests must
    not change the model they get."""
    import json

    from brdfbench.plugins import registry
    from brdfbench.testing.kit import reference_material

    cache: dict = {}

    def get(name: str, *, train=None, **params):
        spec = registry.get("representations", name)
        trains = spec.load().needs_training
        key = (name, json.dumps(params, sort_keys=True), tuple(m.name for m in train or ()) if trains else None)
        if key not in cache:
            model = spec.create(**params)
            if model.needs_training:
                model.train(list(train or ()))
            if "fittable" in spec.tags:
                model.fit(reference_material())
            cache[key] = model
        return cache[key]

    return get


@pytest.fixture
def plugin():
    """`plugin(cls, name=None)`: register a test representation class (Lambert's tags) in
    this process for the test's life; returns its name (default: the class name, lowercased)."""
    from brdfbench.plugins import registry
    from brdfbench.plugins.specs import RepresentationSpec
    from brdfbench_representations.lambert import Lambert

    added = []

    def add(cls, name=None):
        name = name or cls.__name__.lower()
        registry.register("representations", RepresentationSpec(
            name=name, description="test", target=f"{cls.__module__}:{cls.__name__}", tags=Lambert.tags))
        added.append(name)
        return name

    yield add
    for name in added:
        registry.unregister("representations", name)
