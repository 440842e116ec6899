"""Speed-regression gate: a base and a head commit benchmarked in one job on one machine.

Both commits are checked out as git worktrees; each side runs the pytest-benchmark
benchmarks with its own code (an import overlay puts its packages and entry points first
on the path, over the one installed environment). Runs are interleaved: every round runs
base, head and base again (an A/A pair), in an order that rotates per round, so a drift
of the machine's speed reaches both sides alike; benchmarks run single-threaded by default
(`--threads`), since a thread waiting for a busy core swings multi-threaded timings wildly. A side's figure for a benchmark is the
median over its runs of pytest-benchmark's per-run median.

The threshold comes from the noise the job itself measured: the largest A/A difference
between the two base runs' medians (over benchmarks), times `NOISE_FACTOR`, and never
below `--floor`. A benchmark whose head median exceeds the base median by more than the
threshold fails, through pytest-benchmark's own `median:N%` regression check. Exit 0:
no regression; 1: a regression; 2: the gate could not measure (bad commit, failing
benchmark).

    .ci/gate BASE HEAD [--benchmarks tests/benchmarks/test_speed.py] [--rounds 5]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path

NOISE_FACTOR = 2.0
DEFAULT_FLOOR = 10.0  # % : no threshold below this, whatever the A/A pair showed
DEFAULT_BENCHMARKS = ("tests/benchmarks/test_speed.py",)
SIDES = ("base", "head", "base_again")


class GateError(Exception):
    """The gate could not measure (exit 2)."""


def _git(repo: Path, *args: str) -> str:
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise GateError(f"git {' '.join(args)}: {done.stderr.strip() or done.stdout.strip()}")
    return done.stdout.strip()


def overlay(worktree: Path, into: Path) -> Path:
    """A folder that, first on PYTHONPATH, makes the worktree's code and plugins the ones
    imported: a link per package of its pyproject, and a dist-info with its entry points."""
    project = tomllib.loads((worktree / "pyproject.toml").read_text(encoding="utf-8"))
    into.mkdir(parents=True, exist_ok=True)
    dirs = project.get("tool", {}).get("setuptools", {}).get("package-dir", {})
    for name, folder in dirs.items():
        (into / name).symlink_to((worktree / folder).resolve(), target_is_directory=True)
    if (worktree / "hydra_plugins").is_dir():
        (into / "hydra_plugins").symlink_to((worktree / "hydra_plugins").resolve(), target_is_directory=True)
    meta = project["project"]
    info = into / f"{meta['name'].replace('-', '_')}-{meta.get('version', '0')}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {meta['name']}\nVersion: {meta.get('version', '0')}\n",
                                   encoding="utf-8")
    groups = dict(meta.get("entry-points", {}))
    if meta.get("scripts"):
        groups["console_scripts"] = meta["scripts"]
    lines = []
    for group, entries in groups.items():
        lines.append(f"[{group}]")
        lines += [f"{k} = {v}" for k, v in entries.items()]
        lines.append("")
    (info / "entry_points.txt").write_text("\n".join(lines), encoding="utf-8")
    return into


def run_side(worktree: Path, overlay_dir: Path, benchmarks: list[str], out: Path, python: str,
             threads: int = 1) -> dict[str, float]:
    """One pytest-benchmark run of a side: benchmark name → its median (s)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(overlay_dir), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
           "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    cmd = [python, "-m", "pytest", *benchmarks, "--benchmark-enable", f"--benchmark-json={out}",
           "-q", "-p", "no:cacheprovider", "-m", ""]
    done = subprocess.run(cmd, cwd=worktree, env=env, capture_output=True, text=True)
    if done.returncode != 0 or not out.is_file():
        tail = "\n".join((done.stdout + done.stderr).strip().splitlines()[-15:])
        raise GateError(f"benchmarks failed in {worktree} (exit {done.returncode}):\n{tail}")
    doc = json.loads(out.read_text(encoding="utf-8"))
    found = {b["fullname"]: float(b["stats"]["median"]) for b in doc["benchmarks"]}
    if not found:
        raise GateError(f"no benchmark ran in {worktree} for {' '.join(benchmarks)} (names a test without the "
                        "benchmark fixture, or one that skipped)")
    return found


@dataclass(frozen=True)
class Result:
    name: str
    base: float  # s, median over runs of the per-run medians
    head: float
    base_again: float
    change_pct: float  # head against base
    aa_pct: float  # base again against base: the job's own noise
    failure: str | None


@dataclass(frozen=True)
class Verdict:
    results: list[Result]
    noise_pct: float
    threshold_pct: int
    rounds: int

    @property
    def regressions(self) -> list[Result]:
        return [r for r in self.results if r.failure]


def decide(runs: dict[str, list[dict[str, float]]], floor_pct: float = DEFAULT_FLOOR, rounds: int = 0) -> Verdict:
    """The verdict from each side's runs (benchmark → per-run median)."""
    from pytest_benchmark.utils import parse_compare_fail

    names = sorted(set.intersection(*(set(r) for side in SIDES for r in runs[side])))
    if not names:
        raise GateError("no benchmark ran on every side")
    med = {side: {n: statistics.median(r[n] for r in runs[side]) for n in names} for side in SIDES}
    aa = {n: 100 * (med["base_again"][n] / med["base"][n] - 1) for n in names}
    noise = max(abs(v) for v in aa.values())
    threshold = int(math.ceil(max(floor_pct, NOISE_FACTOR * noise)))
    check = parse_compare_fail(f"median:{threshold}%")
    results = []
    for n in names:
        failure = check.fails({"median": med["head"][n]}, {"median": med["base"][n]})
        results.append(Result(n, med["base"][n], med["head"][n], med["base_again"][n],
                              100 * (med["head"][n] / med["base"][n] - 1), aa[n], failure))
    return Verdict(results, noise, threshold, rounds)


def report(v: Verdict, base: str, head: str) -> str:
    lines = [f"gate: {base} → {head}, {v.rounds} interleaved rounds (base, head, base again)",
             f"gate: A/A noise (base again against base, largest over benchmarks) {v.noise_pct:.1f} %; "
             f"threshold {v.threshold_pct} % (max of the floor and {NOISE_FACTOR:g}× the noise)",
             f"{'benchmark':<60} {'base':>11} {'head':>11} {'change':>8} {'A/A':>7}"]
    for r in v.results:
        lines.append(f"{r.name[-60:]:<60} {r.base * 1e3:>9.3f}ms {r.head * 1e3:>9.3f}ms {r.change_pct:>+7.1f}% "
                     f"{r.aa_pct:>+6.1f}%" + ("  REGRESSION" if r.failure else ""))
    lines.append(f"gate: {len(v.regressions)} regression(s)" if v.regressions else "gate: no regression")
    return "\n".join(lines)


def gate(repo: Path, base: str, head: str, benchmarks: list[str], rounds: int, floor_pct: float,
         python: str = sys.executable, keep: Path | None = None, threads: int = 1) -> Verdict:
    base_sha, head_sha = _git(repo, "rev-parse", "--verify", f"{base}^{{commit}}"), _git(repo, "rev-parse", "--verify",
                                                                                        f"{head}^{{commit}}")
    work = Path(tempfile.mkdtemp(prefix="brdfbench-gate-"))
    trees = {}
    try:
        for side, sha in (("base", base_sha), ("head", head_sha)):
            tree = work / side
            _git(repo, "worktree", "add", "--detach", str(tree), sha)
            trees[side] = (tree, overlay(tree, work / f"{side}-overlay"))
        trees["base_again"] = trees["base"]
        runs: dict[str, list[dict[str, float]]] = {side: [] for side in SIDES}
        for r in range(rounds):
            order = SIDES[r % 3:] + SIDES[:r % 3]
            for side in order:
                tree, lay = trees[side]
                out = work / f"{side}-{r}.json"
                runs[side].append(run_side(tree, lay, benchmarks, out, python, threads))
                print(f"gate: round {r + 1}/{rounds}: {side} done", file=sys.stderr, flush=True)
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            for f in work.glob("*.json"):
                shutil.copy(f, keep / f.name)
        return decide(runs, floor_pct, rounds)
    finally:
        for side in ("base", "head"):
            if side in trees:
                subprocess.run(["git", "-C", str(repo), "worktree", "remove", "--force", str(trees[side][0])],
                               capture_output=True)
        shutil.rmtree(work, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=".ci/gate", description=__doc__.split("\n\n")[0])
    p.add_argument("base", help="base commit (e.g. origin/main)")
    p.add_argument("head", help="head commit (e.g. HEAD)")
    p.add_argument("--benchmarks", nargs="+", default=list(DEFAULT_BENCHMARKS),
                   help="pytest paths / node ids of the benchmarks, relative to the repository")
    p.add_argument("--rounds", type=int, default=5, help="interleaved rounds (each runs base, head, base again)")
    p.add_argument("--floor", type=float, default=DEFAULT_FLOOR, help="lowest threshold, in %% (default %(default)s)")
    p.add_argument("--repo", type=Path, default=Path.cwd(), help="the git repository (default: here)")
    p.add_argument("--keep", type=Path, help="copy every run's pytest-benchmark JSON here")
    p.add_argument("--threads", type=int, default=1,
                   help="torch / OpenMP threads of the benchmarks (default 1: on a loaded machine a thread that "
                        "waits for a busy core makes multi-threaded timings swing by orders of magnitude)")
    args = p.parse_args(argv)
    if args.rounds < 1:
        p.error("--rounds must be at least 1")
    if args.threads < 1:
        p.error("--threads must be at least 1")
    if not (args.floor >= 0):
        p.error("--floor must be a non-negative percentage")
    try:
        verdict = gate(args.repo, args.base, args.head, args.benchmarks, args.rounds, args.floor, keep=args.keep,
                       threads=args.threads)
    except GateError as exc:
        print(f"gate: error: {exc}", file=sys.stderr)
        return 2
    print(report(verdict, args.base, args.head))
    return 1 if verdict.regressions else 0


if __name__ == "__main__":
    sys.exit(main())
