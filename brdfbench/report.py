"""Write the reports of a results folder: every registered report plugin (`brdfbench.reports`,
the built-in is the Markdown leaderboard) renders the store's rows into files there."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .plugins import registry
from .store.protocol import open_store


def write_reports(results_dir: Path, store: str = "sqlite", store_params: dict[str, Any] | None = None) -> list[Path]:
    """Regenerate every report of `results_dir` from its store (which must exist already);
    returns the paths written, those of the report of lowest `order` first (the leaderboard)."""
    opened = open_store(store, results_dir, {**(store_params or {}), "create": False})
    df = opened.frame()
    specs = sorted(registry.all_specs("reports"), key=lambda spec: (spec.order, spec.name))
    paths: list[Path] = []
    for spec in specs:
        paths += spec.load()(df, Path(results_dir), opened.location)
    return paths
