"""Write the leaderboard files for a results folder."""

from __future__ import annotations

from pathlib import Path

from .atomic import replacing
from .errors import DataError
from .store import ResultsStore


def write_reports(results_dir: Path) -> list[Path]:
    """Regenerate `leaderboard.md` in `results_dir` from its store, with its figures (the
    convergence plots, PNG) beside it; returns the paths written, the leaderboard first."""
    from brdfbench_leaderboard.markdown import render
    from brdfbench_leaderboard.plots import convergence_figures

    db = results_dir / "brdfbench.sqlite"
    if not db.is_file():
        raise DataError(f"{db}: no results store here (run the benchmark first)")
    df = ResultsStore(db).frame()
    figures = []
    for name, figure in convergence_figures(df).items():
        with replacing(results_dir / name) as tmp:
            figure.savefig(tmp, format="png", dpi=120)
        figures.append(results_dir / name)
    md = results_dir / "leaderboard.md"
    text = render(df, str(db), plots={p.name for p in figures})
    with replacing(md) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return [md, *figures]
