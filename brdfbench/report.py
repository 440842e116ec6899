"""Write the leaderboard files for a results folder."""

from __future__ import annotations

import os
from pathlib import Path

from .errors import DataError
from .store import ResultsStore


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_reports(results_dir: Path) -> list[Path]:
    """Regenerate `leaderboard.md` in `results_dir` from its store; returns the paths written."""
    from brdfbench_leaderboard.markdown import render

    db = results_dir / "brdfbench.sqlite"
    if not db.is_file():
        raise DataError(f"{db}: no results store here (run the benchmark first)")
    df = ResultsStore(db).frame()
    md = results_dir / "leaderboard.md"
    _write_atomic(md, render(df, str(db)))
    return [md]
