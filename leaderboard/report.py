"""The Markdown report plugin (`brdfbench.reports` entry point `markdown`): the leaderboard
text with its figures (the convergence plots, PNG) beside it, each file written atomically."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from brdfbench.atomic import replacing

from .markdown import render
from .plots import convergence_figures


def markdown_report(df: pd.DataFrame, results_dir: Path, source: str) -> list[Path]:
    """Write `leaderboard.md` and its figures into `results_dir`; the leaderboard first."""
    figures = []
    for name, figure in convergence_figures(df).items():
        with replacing(results_dir / name) as tmp:
            figure.savefig(tmp, format="png", dpi=120)
        figures.append(results_dir / name)
    md = results_dir / "leaderboard.md"
    text = render(df, source, plots={p.name for p in figures})
    with replacing(md) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return [md, *figures]
