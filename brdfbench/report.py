"""Write the leaderboard files for a results folder."""

from __future__ import annotations

from pathlib import Path

from .atomic import replacing
from .errors import DataError
from .store import ResultsStore


def write_reports(results_dir: Path) -> list[Path]:
    """Regenerate `leaderboard.md` in `results_dir` from its store; returns the paths written."""
    from brdfbench_leaderboard.markdown import render

    db = results_dir / "brdfbench.sqlite"
    if not db.is_file():
        raise DataError(f"{db}: no results store here (run the benchmark first)")
    df = ResultsStore(db).frame()
    md = results_dir / "leaderboard.md"
    text = render(df, str(db))
    with replacing(md) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return [md]
