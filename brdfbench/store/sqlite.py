"""The results store: typed rows in SQLite, one transaction per benchmark cell.

Schema v4 (`PRAGMA user_version = 4`):
- `configs`: config hash → label, plugin, its version, harness, and the resolved
  parameters behind the hash (JSON), so two configurations never share a row;
- `environments`: where figures were measured (host, CPU model, cores, threads, launcher,
  and the device that computed them: "cpu" or a GPU with its model and versions);
- `results`: one row per (configuration, dataset fingerprint, scope, material or set,
  category, metric, distance, spp) — a unique key, so concurrent writers cannot duplicate
  a cell — with typed scene / sampler / spp / scope / distance columns and the environment
  and concurrency of its cell.

A cell is (config hash, dataset fingerprint, scope, material): `write_cell` replaces a
failed cell and leaves a finished one as it is (the first complete writer wins), so
writing is idempotent. Stores written by v1 (no user_version), v2 and v3 migrate in one transaction.
A store that cannot be read or written is a DataError naming the file and what to do.
"""

from __future__ import annotations

import json
import sqlite3
import time
from contextlib import closing, contextmanager
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Iterator

import pandas as pd

from ..errors import DataError
from .migrations import migrate_v1, migrate_v2, migrate_v3
from .protocol import CELL, ConfigRecord, Environment, Row, Store
from .schema import SCHEMA, SCHEMA_VERSION

__all__ = ["CELL", "COLUMNS", "SCHEMA_VERSION", "ConfigRecord", "Environment", "ResultsStore", "Row", "STORE_FILE",
           "sqlite_store"]

#: The store's file name inside a results folder.
STORE_FILE = "brdfbench.sqlite"



COLUMNS = [f.name for f in fields(Row)]


def sqlite_store(results_dir: Path, create: bool = True, file: str = STORE_FILE) -> "ResultsStore":
    """The `sqlite` store plugin: `file` inside the results folder (`create=False`: it must exist)."""
    path = Path(results_dir) / file
    if not create and path.is_dir():
        raise DataError(f"{path}: the results store path is a directory, not a store file; move it aside")
    if not create and not path.is_file():
        raise DataError(f"{path}: no results store here (run the benchmark first)")
    return ResultsStore(path)


class ResultsStore(Store):
    """One SQLite file; every method opens its own connection (safe across processes)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.location = str(self.path)
        if self.path.is_dir():
            raise DataError(f"{self.path}: the results store path is a directory; give a file path")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataError(f"{self.path.parent}: cannot create the results folder ({exc.strerror})") from None
        with self._connection() as con:  # no WAL switch before the file is known to be a store
            self._open(con)
        with self._connection(write=True):
            pass

    def _open(self, con: sqlite3.Connection) -> None:
        """Check the schema; create it in an empty file, migrate an older one."""
        version = con.execute("PRAGMA user_version").fetchone()[0]
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if version == SCHEMA_VERSION:
            missing = {"configs", "environments", "results"} - tables
            if missing:
                raise DataError(f"{self.path}: schema v{version} store lacks table(s) {', '.join(sorted(missing))}; "
                                "move it aside and run again")
            return
        if version in (2, 3) and {"configs", "environments", "results"} <= tables:
            (migrate_v2 if version == 2 else migrate_v3)(con, self.path)
            return
        if version > SCHEMA_VERSION:
            raise DataError(f"{self.path}: written by a newer brdfbench (schema v{version}, this one reads up to "
                            f"v{SCHEMA_VERSION}); upgrade brdfbench or use another results folder")
        if version != 0:
            raise DataError(f"{self.path}: unknown store schema v{version}; move it aside and run again")
        if not tables:
            con.execute("BEGIN IMMEDIATE")  # another process may be creating it right now: look again under the lock
            try:
                if not con.execute("SELECT 1 FROM sqlite_master WHERE type='table' LIMIT 1").fetchone():
                    for statement in SCHEMA.split(";"):
                        if statement.strip():
                            con.execute(statement)
                    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            except BaseException:
                con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")
            self._open(con)
        elif "results" in tables and "configs" not in tables:
            migrate_v1(con, self.path)
        else:
            raise DataError(f"{self.path}: an SQLite file that is not a brdfbench results store (tables: "
                            f"{', '.join(sorted(tables))}); move it aside or choose another results_dir")

    # -- connections -------------------------------------------------------------
    @contextmanager
    def _connection(self, write: bool = False) -> Iterator[sqlite3.Connection]:
        """A connection with WAL and a long busy timeout; SQLite faults become DataErrors naming the file."""
        try:
            with closing(sqlite3.connect(self.path, timeout=120, isolation_level=None)) as con:
                if write:
                    mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
                    if mode.lower() != "wal":  # e.g. a read-only folder: WAL needs its -wal and -shm files
                        con.execute("PRAGMA journal_mode=DELETE")
                yield con
        except (sqlite3.IntegrityError, sqlite3.ProgrammingError, sqlite3.InterfaceError):  # the writer's bug, not the file's
            raise
        except sqlite3.DatabaseError as exc:
            raise _store_error(self.path, exc) from None

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        with self._connection(write=True) as con:
            con.execute("BEGIN IMMEDIATE")
            try:
                yield con
            except BaseException:
                con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")

    # -- configurations and environments ----------------------------------------------
    def write_config(self, record: ConfigRecord) -> None:
        """Record what a config hash stands for (the label follows the latest run)."""
        with self._transaction() as con:
            con.execute(
                "INSERT INTO configs VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT(config_hash) DO UPDATE SET label=excluded.label,"
                " plugin=excluded.plugin, plugin_version=excluded.plugin_version, harness=excluded.harness,"
                " params=excluded.params",
                (record.config_hash, record.label, record.plugin, record.plugin_version, record.harness,
                 json.dumps(record.params, sort_keys=True, default=str)),
            )

    def write_environment(self, env: Environment) -> None:
        with self._transaction() as con:
            names = [f.name for f in fields(Environment)]
            con.execute(f"INSERT OR IGNORE INTO environments ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})",
                        tuple(asdict(env).values()))

    # -- cells -------------------------------------------------------------------
    def done_cells(self, config_hash: str, dataset_fingerprint: str, scope: str = "material") -> set[str]:
        """Materials (or sets) of this configuration and data that hold successful rows."""
        with self._connection() as con:
            cur = con.execute(
                "SELECT DISTINCT material FROM results WHERE config_hash=? AND dataset_fingerprint=? AND scope=?"
                " AND status='ok'", (config_hash, dataset_fingerprint, scope))
            return {r[0] for r in cur}

    def write_cell(self, rows: list[Row]) -> bool:
        """Insert one cell's rows in one transaction; returns False when the cell was already done.

        Earlier failed rows of the cell are replaced; a finished cell is kept (first writer wins)."""
        if not rows:
            return False
        keys = {tuple(getattr(r, k) for k in CELL) for r in rows}
        if len(keys) != 1:
            raise ValueError(f"write_cell takes the rows of one cell, got {len(keys)} cells")
        key = next(iter(keys))
        where = " AND ".join(f"{k}=?" for k in CELL)
        with self._transaction() as con:
            if con.execute(f"SELECT 1 FROM results WHERE {where} AND status='ok' LIMIT 1", key).fetchone():
                return False
            con.execute(f"DELETE FROM results WHERE {where}", key)
            con.executemany(
                f"INSERT INTO results ({', '.join(COLUMNS)}) VALUES ({', '.join('?' * len(COLUMNS))})",
                [tuple(asdict(r).values()) for r in rows],
            )
        return True

    # -- reading -----------------------------------------------------------------
    def configs(self) -> list[ConfigRecord]:
        with self._connection() as con:
            rows = con.execute("SELECT config_hash, label, plugin, plugin_version, harness, params FROM configs"
                               " ORDER BY config_hash").fetchall()
        return [ConfigRecord(*r[:5], params=json.loads(r[5])) for r in rows]

    def environments(self) -> list[Environment]:
        with self._connection() as con:
            rows = con.execute(f"SELECT {', '.join(f.name for f in fields(Environment))} FROM environments"
                               " ORDER BY env_id").fetchall()
        return [Environment(*r) for r in rows]

    def cells(self) -> Iterator[list[Row]]:
        """Every cell's rows in insertion order, one list per cell."""
        with self._connection() as con:
            cur = con.execute(f"SELECT {', '.join(COLUMNS)} FROM results ORDER BY {', '.join(CELL)}, rowid")
            cell: list[Row] = []
            for values in cur:
                row = Row(**dict(zip(COLUMNS, values)))
                if cell and tuple(getattr(cell[0], k) for k in CELL) != tuple(getattr(row, k) for k in CELL):
                    yield cell
                    cell = []
                cell.append(_typed(row, self.path))
            if cell:
                yield cell

    def frame(self, **where: Any) -> pd.DataFrame:
        """All rows (optionally filtered by column equality) with their configuration and
        environment: `representation` is the configuration's label, `params` its JSON."""
        unknown = set(where) - set(COLUMNS)
        if unknown:
            raise KeyError(f"unknown results column(s): {', '.join(sorted(unknown))}")
        clause = " AND ".join(f"r.{k}=?" for k in where)
        sql = ("SELECT r.rowid AS row_id, r.*, COALESCE(c.label, r.config_hash) AS representation,"
               " COALESCE(c.plugin, '') AS plugin, COALESCE(c.plugin_version, '') AS plugin_version,"
               " COALESCE(c.harness, '') AS harness, COALESCE(c.params, 'null') AS params,"
               " COALESCE(e.host, '') AS host, COALESCE(e.cpu_model, '') AS cpu_model,"
               " COALESCE(e.cpu_count, 0) AS cpu_count, COALESCE(e.threads, 0) AS threads,"
               " COALESCE(e.launcher, '') AS launcher, COALESCE(e.platform, '') AS platform,"
               " COALESCE(e.device, 'cpu') AS device,"
               " COALESCE(e.device_detail, 'cpu') AS device_detail"
               " FROM results r LEFT JOIN configs c ON c.config_hash = r.config_hash"
               " LEFT JOIN environments e ON e.env_id = r.env_id" + (f" WHERE {clause}" if clause else ""))
        with self._connection() as con:
            try:
                df = pd.read_sql_query(sql, con, params=tuple(where.values()))
            except pd.errors.DatabaseError as exc:  # pandas wraps SQLite's own error
                cause = exc.__cause__ if isinstance(exc.__cause__, sqlite3.DatabaseError) else sqlite3.DatabaseError(str(exc).rsplit(": ", 1)[-1])
                raise _store_error(self.path, cause) from None
        _check_values(df, self.path)
        df["value"] = pd.to_numeric(df["value"]).astype(float)
        df["higher_is_better"] = df["higher_is_better"].astype(bool)
        return df


def _typed(row: Row, path: Path) -> Row:
    """A row as read back (SQLite keeps booleans as integers); a non-numeric value is a damaged store."""
    from dataclasses import replace

    if not _numeric(row.value):
        raise DataError(f"{path}: a {row.metric} row of {row.material} holds a non-numeric value {row.value!r}; "
                        "the store is damaged: move it aside and run again")
    return replace(row, higher_is_better=bool(row.higher_is_better),
                   value=None if row.value is None else float(row.value))


def _numeric(value: Any) -> bool:
    """A stored value is a number or NULL (SQLite columns take any type)."""
    return value is None or (isinstance(value, (int, float)) and not isinstance(value, bool))


def _check_values(df: pd.DataFrame, path: Path) -> None:
    """A value that is not a number (SQLite stores any type) is a damaged store, named by row."""
    for row_id, value in zip(df["row_id"], df["value"]):
        if _numeric(value):
            continue
        raise DataError(f"{path}: row {row_id} holds a non-numeric value {value!r}; "
                        "the store is damaged: move it aside and run again")


def _store_error(path: Path, exc: sqlite3.DatabaseError) -> DataError:
    """One line naming the store and what to do, for SQLite's faults."""
    text = str(exc)
    low = text.lower()
    if "disk is full" in low or "disk i/o" in low:
        hint = "free disk space and run again (the store was left as it was)"
    elif "readonly" in low or "read-only" in low or "unable to open" in low:
        hint = "the store or its folder is not writable: fix the permissions or choose another results_dir"
    elif "not a database" in low or "malformed" in low or "corrupt" in low:
        hint = "the file is damaged or not a brdfbench store: move it aside and run again"
    elif "locked" in low or "busy" in low:
        hint = "another process holds the store locked; wait for it, or use another results_dir"
    else:
        hint = "move it aside and run again"
    return DataError(f"{path}: results store error ({text}); {hint}")


def now() -> float:
    return time.time()
