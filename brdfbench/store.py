"""The results store: typed rows in SQLite, written atomically per benchmark cell.

A cell is one (representation label, config hash, dataset fingerprint, material): all of
its rows are inserted in one transaction, so a crash never leaves half a cell. A re-run
skips cells that already hold successful rows; failed cells are retried.
"""

from __future__ import annotations

import sqlite3
import time
from contextlib import closing
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import pandas as pd

SCHEMA = """
CREATE TABLE IF NOT EXISTS results (
    run_id TEXT NOT NULL,
    representation TEXT NOT NULL,
    dataset TEXT NOT NULL,
    dataset_fingerprint TEXT NOT NULL,
    material TEXT NOT NULL,
    category TEXT NOT NULL,
    metric TEXT NOT NULL,
    value REAL,
    unit TEXT NOT NULL,
    higher_is_better INTEGER NOT NULL,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    seed INTEGER NOT NULL,
    config_hash TEXT NOT NULL,
    package_version TEXT NOT NULL,
    git_sha TEXT NOT NULL,
    timestamp REAL NOT NULL,
    scene TEXT NOT NULL DEFAULT 'brdf_space'
);
CREATE INDEX IF NOT EXISTS cell ON results (representation, config_hash, dataset_fingerprint, material);
"""


@dataclass(frozen=True)
class Row:
    run_id: str
    representation: str
    dataset: str
    dataset_fingerprint: str
    material: str
    category: str
    metric: str
    value: float | None
    unit: str
    higher_is_better: bool
    status: str  # "ok" or "failed"
    message: str
    seed: int
    config_hash: str
    package_version: str
    git_sha: str
    timestamp: float
    scene: str = "brdf_space"  # the scene the metrics were measured in (brdf_space: no rendering)


COLUMNS = [f.name for f in fields(Row)]


class ResultsStore:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with closing(self._connect()) as con, con:
            con.executescript(SCHEMA)
            have = {row[1] for row in con.execute("PRAGMA table_info(results)")}
            if "scene" not in have:  # a store written before scenes were rendered
                con.execute("ALTER TABLE results ADD COLUMN scene TEXT NOT NULL DEFAULT 'brdf_space'")

    def _connect(self) -> sqlite3.Connection:
        con = sqlite3.connect(self.path, timeout=120)
        con.execute("PRAGMA journal_mode=WAL")
        return con

    def has_cell(self, representation: str, config_hash: str, dataset_fingerprint: str, material: str) -> bool:
        with closing(self._connect()) as con:
            cur = con.execute(
                "SELECT 1 FROM results WHERE representation=? AND config_hash=? AND dataset_fingerprint=?"
                " AND material=? AND status='ok' LIMIT 1",
                (representation, config_hash, dataset_fingerprint, material),
            )
            return cur.fetchone() is not None

    def write_cell(self, rows: list[Row]) -> None:
        """Insert one cell's rows atomically, replacing earlier failed rows of that cell."""
        if not rows:
            return
        keys = {(r.representation, r.config_hash, r.dataset_fingerprint, r.material) for r in rows}
        if len(keys) != 1:
            raise ValueError(f"write_cell takes the rows of one cell, got {len(keys)} cells")
        with closing(self._connect()) as con, con:
            con.execute(
                "DELETE FROM results WHERE representation=? AND config_hash=? AND dataset_fingerprint=?"
                " AND material=? AND status='failed'",
                next(iter(keys)),
            )
            con.executemany(
                f"INSERT INTO results ({', '.join(COLUMNS)}) VALUES ({', '.join('?' * len(COLUMNS))})",
                [tuple(asdict(r).values()) for r in rows],
            )

    def frame(self, **where: str) -> pd.DataFrame:
        """All rows (optionally filtered by column equality) as a DataFrame."""
        unknown = set(where) - set(COLUMNS)
        if unknown:
            raise KeyError(f"unknown results column(s): {', '.join(sorted(unknown))}")
        clause = " AND ".join(f"{k}=?" for k in where)
        sql = "SELECT * FROM results" + (f" WHERE {clause}" if clause else "")
        with closing(self._connect()) as con:
            df = pd.read_sql_query(sql, con, params=tuple(where.values()))
        df["higher_is_better"] = df["higher_is_better"].astype(bool)
        return df


def now() -> float:
    return time.time()
