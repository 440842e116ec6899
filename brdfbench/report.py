"""Write the reports of a results folder: every registered report plugin (`brdfbench.reports`,
the built-in is the Markdown leaderboard) renders the store's rows into files there."""

from __future__ import annotations

from pathlib import Path

from . import registry
from .errors import DataError
from .store import ResultsStore


def write_reports(results_dir: Path) -> list[Path]:
    """Regenerate every report of `results_dir` from its store; returns the paths written,
    the Markdown leaderboard first where it is registered."""
    db = Path(results_dir) / "brdfbench.sqlite"
    if not db.is_file():
        raise DataError(f"{db}: no results store here (run the benchmark first)")
    df = ResultsStore(db).frame()
    names = sorted(registry.names("reports"), key=lambda n: (n != "markdown", n))
    paths: list[Path] = []
    for name in names:
        paths += registry.get("reports", name).load()(df, Path(results_dir), str(db))
    return paths
