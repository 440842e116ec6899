"""Migrations of older results stores to the current schema, each in one transaction.

v1 (before `PRAGMA user_version`): one `results` table keyed by representation label,
packed convergence keys (scene "<scene>/convergence/<sampler>", metric "<m>@spp=<n>"),
no configuration parameters and no environment. Every row is carried over: the label
becomes the configuration's label (its parameters were never stored: `params` records
that), packed keys are split into the typed scene / sampler / spp columns, and exact
duplicate cells (written twice by concurrent v1 runs) keep their latest rows. A v1 store
is written in the current schema directly.

v2: as v3 without the `distance` column, and a unique key without `category` and
`distance` (set-level rows need both: MMD over each distance, a count per category). The
results table is rebuilt with every row carried over (`distance` = "").

v3: as v4 without the environments' `device` and `device_detail` columns; every figure of
a v3 store was computed on the CPU, which the columns' default says.
"""

from __future__ import annotations

import json
import re
import sqlite3
from collections.abc import Callable
from pathlib import Path

from ..errors import DataError
from .schema import DEVICE_COLUMNS, SCHEMA, SCHEMA_VERSION, UNKNOWN_ENV

_INFIX = "/convergence/"
_RUNG = re.compile(r"^(?P<base>.+)@spp=(?P<spp>\d+)$")
V1_COLUMNS = ("run_id", "representation", "dataset", "dataset_fingerprint", "material", "category", "metric", "value",
              "unit", "higher_is_better", "status", "message", "seed", "config_hash", "package_version", "git_sha",
              "timestamp")


def split_v1(scene: str, metric: str) -> tuple[str, str, int, str]:
    """(scene, sampler, spp, metric) of a v1 row's packed scene and metric."""
    sampler = ""
    if _INFIX in scene:
        scene, _, sampler = scene.partition(_INFIX)
    spp = 0
    match = _RUNG.match(metric)
    if match:
        metric, spp = match["base"], int(match["spp"])
    return scene, sampler, spp, metric


V2_COLUMNS = ("run_id", "config_hash", "dataset", "dataset_fingerprint", "scope", "material", "category", "scene",
              "sampler", "spp", "metric", "value", "unit", "higher_is_better", "status", "message", "seed",
              "package_version", "git_sha", "timestamp", "env_id", "concurrent_jobs")


def _migrate(con: sqlite3.Connection, path: Path, required: tuple[str, ...], lacking: str,
             rewrite: Callable[[list[str]], int]) -> int:
    """Check the results table has `required` columns (else a DataError: `lacking` then the
    missing ones), then `rewrite(its columns)` and set the current version, all in one
    transaction (rolled back on any error); returns the rows carried over (0 when another
    process migrated first)."""
    have = [r[1] for r in con.execute("PRAGMA table_info(results)")]
    missing = [c for c in required if c not in have]
    if missing:
        raise DataError(f"{path}: {lacking} {', '.join(missing)}; move it aside and run again")
    con.execute("BEGIN IMMEDIATE")
    if con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION:  # another process migrated it first
        con.execute("COMMIT")
        return 0
    try:
        n = rewrite(have)
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    except BaseException:
        con.execute("ROLLBACK")
        raise
    con.execute("COMMIT")
    return n


def migrate_v2(con: sqlite3.Connection, path: Path) -> int:
    """Rewrite a v2 store as v3 in place, in one transaction; returns the rows carried over."""

    def rewrite(have: list[str]) -> int:
        con.execute("ALTER TABLE results RENAME TO results_v2")
        con.execute("DROP INDEX IF EXISTS results_cell")
        for statement in SCHEMA.split(";"):
            if "CREATE TABLE results" in statement or "CREATE INDEX" in statement:
                con.execute(statement)
        columns = ", ".join(V2_COLUMNS)
        n = con.execute(f"INSERT INTO results ({columns}) SELECT {columns} FROM results_v2 ORDER BY rowid").rowcount
        con.execute("DROP TABLE results_v2")
        _add_device_columns(con)
        return n

    return _migrate(con, path, V2_COLUMNS, "a v2 results table without column(s)", rewrite)


def migrate_v3(con: sqlite3.Connection, path: Path) -> int:
    """Add v4's device columns to a v3 store's environments, in one transaction; returns the
    results rows (all kept as they are)."""

    def rewrite(have: list[str]) -> int:
        _add_device_columns(con)
        return con.execute("SELECT COUNT(*) FROM results").fetchone()[0]

    return _migrate(con, path, V2_COLUMNS + ("distance",), "a v3 results table without column(s)", rewrite)


def _add_device_columns(con: sqlite3.Connection) -> None:
    have = {r[1] for r in con.execute("PRAGMA table_info(environments)")}
    for name, definition in DEVICE_COLUMNS:
        if name not in have:
            con.execute(f"ALTER TABLE environments ADD COLUMN {name} {definition}")


def migrate_v1(con: sqlite3.Connection, path: Path) -> int:
    """Rewrite a v1 store in the current schema in place; returns the number of rows carried over."""
    return _migrate(con, path, V1_COLUMNS, "a results table that is not a brdfbench v1 store lacks column(s)",
                    lambda have: _rewrite_v1(con, "scene" if "scene" in have else "'brdf_space'"))


def _rewrite_v1(con: sqlite3.Connection, scene_sql: str) -> int:
    old = con.execute(f"SELECT {', '.join(V1_COLUMNS)}, {scene_sql} FROM results ORDER BY timestamp, rowid").fetchall()
    con.execute("ALTER TABLE results RENAME TO results_v1")
    con.execute("DROP INDEX IF EXISTS cell")
    for statement in SCHEMA.split(";"):
        if statement.strip():
            con.execute(statement)
    labels: dict[str, tuple[str, str, str]] = {}
    cells: dict[tuple, list[tuple]] = {}
    for row in old:
        rec = dict(zip(V1_COLUMNS + ("scene",), row))
        scene, sampler, spp, metric = split_v1(rec["scene"], rec["metric"])
        harness = "convergence" if sampler else ("accuracy" if scene == "brdf_space" else "render")
        labels[rec["config_hash"]] = (rec["representation"], rec["package_version"], harness)
        key = (rec["config_hash"], rec["dataset_fingerprint"], "material", rec["material"])
        out = (rec["run_id"], rec["config_hash"], rec["dataset"], rec["dataset_fingerprint"], "material",
               rec["material"], rec["category"], scene, sampler, spp, metric, rec["value"], rec["unit"],
               int(bool(rec["higher_is_better"])), rec["status"], rec["message"], rec["seed"],
               rec["package_version"], rec["git_sha"], rec["timestamp"], UNKNOWN_ENV, 0)
        cells.setdefault(key, []).append(out)
    columns = ("run_id, config_hash, dataset, dataset_fingerprint, scope, material, category, scene, sampler, spp,"
               " metric, value, unit, higher_is_better, status, message, seed, package_version, git_sha,"
               " timestamp, env_id, concurrent_jobs")
    n = 0
    for rows in cells.values():
        # the latest write of each (metric, spp) wins, as the v1 leaderboard showed it; a cell
        # with successful rows drops its failures (v1 deleted them when the cell succeeded)
        if any(r[14] == "ok" for r in rows):
            rows = [r for r in rows if r[14] == "ok"]
        latest = {}
        for r in rows:
            latest[(r[10], r[9])] = r
        con.executemany(f"INSERT INTO results ({columns}) VALUES ({', '.join('?' * 22)})", latest.values())
        n += len(latest)
    for chash, (label, version, harness) in labels.items():
        con.execute("INSERT INTO configs VALUES (?, ?, ?, ?, ?, ?)",
                    (chash, label, "", version, harness, json.dumps({"migrated_from": "v1", "params": None})))
    con.execute("DROP TABLE results_v1")
    return n
