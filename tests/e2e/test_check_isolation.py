"""`brdfbench check` runs each check in a worker process under a time limit: a third-party
plugin that segfaults, ends the process or hangs inside one check fails that check, naming
the cause, and the other checks still run (in a fresh worker) and pass."""

import os
import subprocess
import sys
import textwrap
import time

import pytest

PLUGIN = '''
"""Third-party-style plugins that end or stall their process inside one check."""
import ctypes
import math
import os
import signal
import time

import torch
from brdfbench.protocols.representation import Representation
from brdfbench.plugins.specs import RepresentationSpec
from brdfbench.state_checks import expect_tensor

TAGS = frozenset({"fittable", "reciprocal", "isotropic"})


class Diffuse(Representation):
    tags = TAGS

    def __init__(self):
        super().__init__()
        self.kd = torch.full((3,), 0.3, dtype=torch.float64)

    def fit(self, target, *, seed=0):
        values = torch.from_numpy(target.table.values).clamp_min(0).reshape(3, -1)
        self.kd = values.median(dim=1).values.double() * math.pi
        return self

    def _eval(self, wi, wo):
        return (self.kd / math.pi).to(wi.dtype).expand(wi.shape[0], 3).clone()

    def state_dict(self):
        return {"kd": self.kd}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        model.kd = expect_tensor(tensors, "kd", (3,), owner="hostile model", nonneg=True)
        return model


class Segfaults(Diffuse):
    """Crashes loading a sound model file (save_load_roundtrip)."""

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = super().from_state(params, tensors, metadata)  # a broken file is refused first
        ctypes.string_at(0)
        return model


_fits = 0


def _second_fit() -> bool:
    """True on a process's second fit: the shared model is the first, fit_deterministic's the second."""
    global _fits
    _fits += 1
    return _fits == 2


class Exits(Diffuse):
    """Ends the process on its second fit (fit_deterministic)."""

    def fit(self, target, *, seed=0):
        if _second_fit():
            os._exit(3)
        return super().fit(target, seed=seed)


class Hangs(Diffuse):
    """Ignores SIGTERM and SIGINT and sleeps forever on its second fit (fit_deterministic)."""

    def fit(self, target, *, seed=0):
        if _second_fit():
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            while True:
                time.sleep(1)
        return super().fit(target, seed=seed)


def _spec(name, cls):
    return RepresentationSpec(name=name, description=f"{cls.__doc__} (test plugin)",
                              target=f"hostile_brdf:{cls.__name__}", tags=TAGS)


SEGFAULTS = _spec("hostile_segfault", Segfaults)
EXITS = _spec("hostile_exit", Exits)
HANGS = _spec("hostile_hang", Hangs)
IMPORT_CRASH = RepresentationSpec(name="hostile_import", description="segfaults on import (test plugin)",
                                  target="hostile_import_crash:Anything", tags=TAGS)
'''

#: A plugin module that crashes its process as it is imported.
CRASHES_ON_IMPORT = "import ctypes\nctypes.string_at(0)\n"

ENTRY_POINTS = """[brdfbench.representations]
hostile_segfault = hostile_brdf:SEGFAULTS
hostile_exit = hostile_brdf:EXITS
hostile_hang = hostile_brdf:HANGS
hostile_import = hostile_brdf:IMPORT_CRASH
"""

CHECKED = ("protocol", "eval_shapes_and_dtypes", "adversarial_finite_nonnegative", "isotropy", "cost_declared")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A folder holding the plugin module and a dist-info that declares its entry points."""
    root = tmp_path_factory.mktemp("site")
    (root / "hostile_brdf.py").write_text(textwrap.dedent(PLUGIN))
    (root / "hostile_import_crash.py").write_text(CRASHES_ON_IMPORT)
    info = root / "hostile_brdf-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hostile-brdf\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return root


def _check(name, site, cwd, *extra):
    env = dict(os.environ, PYTHONPATH=f"{site}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "brdfbench.cli", "check", name, "--pairs", "20000", *extra],
                         cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    return out, time.monotonic() - start


def _lines(summary: str) -> dict[str, str]:
    """check -> outcome, from a report's summary."""
    rows = (line.split() for line in summary.splitlines() if line.startswith("  ") and not line.startswith("   "))
    return {row[1]: row[0] for row in rows if len(row) == 2}


@pytest.mark.parametrize("name,failing,cause,limit", [
    ("hostile_segfault", "save_load_roundtrip", "worker died: segmentation fault (SIGSEGV) during this check", 120),
    ("hostile_exit", "fit_deterministic", "worker died: exited with status 3", 120),
    ("hostile_hang", "fit_deterministic", "exceeded the time limit of 10 s (worker killed)", 10 + 120),
])
def test_a_crash_exit_or_hang_fails_that_check_and_the_rest_run(site, tmp_path, name, failing, cause, limit):
    out, took = _check(name, site, tmp_path, "--timeout", "10")
    assert out.returncode == 1, out.stdout + out.stderr
    outcomes = _lines(out.stdout)
    assert outcomes[failing] == "failed", out.stdout
    assert cause in out.stdout.split(f"failed   {failing}", 1)[1].splitlines()[1], out.stdout
    assert [c for c, o in outcomes.items() if o not in ("passed", "skipped")] == [failing], out.stdout
    # checks before the failure, and after it in a fresh worker (which fits the model again)
    assert set(CHECKED) | {"save_load_roundtrip", "fit_deterministic", "load_refuses_broken_state"} <= set(outcomes)
    assert "1 failed" in out.stdout
    assert f"failed   {failing}" in out.stderr  # a progress line per check
    assert took < limit


def test_a_plugin_that_crashes_on_import_fails_the_load_check(site, tmp_path):
    """The command never imports the plugin's code itself: the first worker does."""
    out, took = _check("hostile_import", site, tmp_path, "--timeout", "20")
    assert out.returncode == 1, out.stdout + out.stderr
    assert _lines(out.stdout) == {"load": "failed"}, out.stdout
    assert "worker died: segmentation fault (SIGSEGV) while loading the plugin" in out.stdout
    assert took < 120


def test_a_healthy_builtin_passes_under_isolation(tmp_path):
    out, _ = _check("lambert", tmp_path, tmp_path, "--timeout", "120")
    assert out.returncode == 0, out.stdout + out.stderr
    outcomes = _lines(out.stdout)
    assert set(CHECKED) <= set(outcomes) and "failed" not in outcomes.values(), out.stdout


def test_in_process_registrations_reach_the_worker(site, monkeypatch):
    """A plugin registered with `registry.register` (not an entry point) is checked in the worker."""
    from brdfbench.plugins import registry
    from brdfbench.plugins.specs import RepresentationSpec
    from brdfbench.testing.isolated import check_isolated

    monkeypatch.syspath_prepend(str(site))
    spec = RepresentationSpec(name="registered_exit", description="test plugin", target="hostile_brdf:Exits",
                              tags=frozenset({"fittable", "reciprocal", "isotropic"}),
                              xfail_checks={"fit_deterministic": "known: ends the process"})
    registry.register("representations", spec)
    seen = []
    try:
        report = check_isolated("representation", "registered_exit", n_pairs=20_000, timeout_s=120,
                                on_result=lambda check, outcome, s: seen.append((check, outcome)))
    finally:
        registry.unregister("representations", spec.name)
    assert report.outcomes["fit_deterministic"] == "xfailed", report.summary()
    assert "expected: known: ends the process; worker died: exited with status 3" in report.details["fit_deterministic"]
    assert report.passed and report.outcomes["save_load_roundtrip"] == "passed", report.summary()
    assert seen == list(report.outcomes.items())


# --------------------------------------------------------------------------- samplers

BROKEN_SAMPLER = '''
"""A third-party-style sampler whose pdf is twice its sampling density."""
from brdfbench.sampling.builtin import GGX


class DoubledPdf(GGX):
    def _pdf(self, wi, wo):
        return 2.0 * super()._pdf(wi, wo)
'''


def test_a_sampler_is_checked_in_isolation_with_its_chi2_cells(tmp_path):
    """`--kind sampler`: the sampler kit's fixed checks and its quick χ² sweep, each check in
    the worker; `phong` is a representation and a sampler, and the flag picks the sampler."""
    out, _ = _check("phong", tmp_path, tmp_path, "--kind", "sampler", "--timeout", "120")
    assert out.returncode == 0, out.stdout + out.stderr
    outcomes = _lines(out.stdout)
    chi2 = [c for c in outcomes if c.startswith("chi2[")]
    assert len(chi2) >= 10 and {"protocol", "shapes_and_dtypes", "pdf_zero_below_horizon"} <= set(outcomes), out.stdout
    assert set(outcomes.values()) <= {"passed", "skipped"} and "is also a" not in out.stderr


def test_a_broken_sampler_fails_its_chi2_cells_in_the_worker(tmp_path, monkeypatch):
    from brdfbench.plugins import registry
    from brdfbench.plugins.specs import SamplerSpec
    from brdfbench.testing.isolated import check_isolated

    (tmp_path / "broken_sampler.py").write_text(BROKEN_SAMPLER)
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = SamplerSpec(name="doubled_pdf", description="test sampler", target="broken_sampler:DoubledPdf",
                       tags=frozenset({"microfacet"}))
    registry.register("samplers", spec)
    try:
        report = check_isolated("sampler", "doubled_pdf", n_pairs=20_000, timeout_s=120)
    finally:
        registry.unregister("samplers", spec.name)
    chi2 = {k: v for k, v in report.outcomes.items() if k.startswith("chi2[")}
    assert chi2 and "failed" in chi2.values(), report.summary()
    assert not report.passed
