"""The speed-regression gate (`.ci/gate`, `brdfbench.gating`): its verdict from measured
runs, the import overlay that runs each commit's own code, and (slow) the demonstration:
a deliberate slowdown is caught, a no-op change passes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from brdfbench import gating

REPO = Path(__file__).resolve().parents[2]


def _runs(base, head, again):
    return {"base": [{"b": x} for x in base], "head": [{"b": x} for x in head], "base_again": [{"b": x} for x in again]}


def test_threshold_comes_from_the_measured_noise_and_never_below_the_floor():
    quiet = gating.decide(_runs([1.0, 1.0, 1.0], [1.05, 1.04, 1.06], [1.01, 1.0, 1.02]), floor_pct=10)
    assert quiet.threshold_pct == 10 and not quiet.regressions  # 1 % A/A noise: the floor rules
    noisy = gating.decide(_runs([1.0, 1.0, 1.0], [1.3, 1.3, 1.3], [1.2, 1.2, 1.2]), floor_pct=10)
    assert noisy.noise_pct == pytest.approx(20) and noisy.threshold_pct == 40 and not noisy.regressions


def test_a_slowdown_past_the_threshold_fails_through_pytest_benchmarks_check():
    v = gating.decide(_runs([1.0, 1.1, 0.9], [2.0, 2.1, 1.9], [1.0, 1.05, 0.95]), floor_pct=10)
    [r] = v.regressions
    assert r.change_pct == pytest.approx(100) and "PercentageRegressionCheck" in r.failure
    assert "REGRESSION" in gating.report(v, "a", "b")


def test_medians_resist_one_wild_run():
    v = gating.decide(_runs([1.0, 1.0, 50.0], [1.0, 1.01, 1.0], [1.0, 0.99, 1.0]), floor_pct=10)
    assert not v.regressions and v.results[0].base == 1.0


def test_bad_commit_is_a_gate_error(tmp_path):
    assert gating.main(["--repo", str(REPO), "no-such-ref", "HEAD"]) == 2


def test_the_overlay_imports_the_worktrees_code_and_plugins(tmp_path):
    tree = tmp_path / "tree"
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), "HEAD"], check=True,
                   capture_output=True)
    try:
        (tree / "brdfbench" / "marker_module.py").write_text("X = 1\n")
        lay = gating.overlay(tree, tmp_path / "lay")
        probe = ("import brdfbench, brdfbench.marker_module, brdfbench_representations as r; "
                 "from importlib.metadata import entry_points; "
                 "print(brdfbench.__file__); print(r.__file__); "
                 "print(sorted(e.name for e in entry_points(group='brdfbench.representations'))[:2])")
        out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env={"PYTHONPATH": str(lay), "PATH": ""},
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        core, reps, names = out.stdout.splitlines()
        assert core.startswith(str(lay)) and reps.startswith(str(lay))
        assert names.startswith("[")
    finally:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)], capture_output=True)


SLOW_BENCH = "tests/benchmarks/test_speed.py::test_half_diff_fp32"
SLOWDOWN = '''

_to_half_diff_fast = to_half_diff


def to_half_diff(wi, wo):  # a deliberate slowdown: the work done twice
    _to_half_diff_fast(wi, wo)
    return _to_half_diff_fast(wi, wo)
'''


@pytest.mark.slow
def test_demonstration_catches_a_slowdown_and_passes_a_no_op(tmp_path):
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    git = ["git", "-C", str(clone), "-c", "user.name=gate", "-c", "user.email=gate@example.invalid"]
    coords = clone / "brdfbench" / "coords.py"
    coords.write_text(coords.read_text() + "\n# a comment: a no-op change\n")
    subprocess.run([*git, "commit", "-qam", "no-op"], check=True)
    coords.write_text(coords.read_text() + SLOWDOWN)
    subprocess.run([*git, "commit", "-qam", "slowdown"], check=True)
    args = ["--repo", str(clone), "--benchmarks", SLOW_BENCH, "--rounds", "3"]
    assert gating.main([*args, "HEAD~2", "HEAD~1"]) == 0  # the no-op passes
    assert gating.main([*args, "HEAD~1", "HEAD"]) == 1  # the slowdown is caught
