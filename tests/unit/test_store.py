"""The results store: typed rows, one transaction per cell, a unique key, damaged files named."""

import multiprocessing as mp
import os
import sqlite3

import pytest

from brdfbench.errors import DataError
from brdfbench.store.sqlite import SCHEMA_VERSION, ConfigRecord, ResultsStore, Row


def _row(material="m1", metric="l1", value=1.0, status="ok", chash="h1", spp=0):
    return Row(
        run_id="r", config_hash=chash, dataset="synthetic", dataset_fingerprint="fp", material=material,
        category="plastic", metric=metric, value=value, unit="1/sr", higher_is_better=False, status=status,
        message="", seed=0, package_version="0", git_sha="x", timestamp=1.0, spp=spp,
    )


def test_write_and_read_back_typed_rows(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    store.write_config(ConfigRecord("h1", "lambert", "lambert", "0.1", "accuracy", {"params": {}}))
    assert store.write_cell([_row(metric="l1", value=0.5), _row(metric="fit_time", value=2.0)])
    df = store.frame()
    assert sorted(df.metric) == ["fit_time", "l1"]
    assert df.higher_is_better.dtype == bool and set(df.representation) == {"lambert"}
    assert store.has_cell("h1", "fp", "m1")
    assert not store.has_cell("h2", "fp", "m1")
    assert len(store.frame(metric="l1")) == 1
    with pytest.raises(KeyError, match="bogus"):
        store.frame(bogus="x")
    with sqlite3.connect(tmp_path / "r.sqlite") as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_cell_is_all_or_nothing(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    with pytest.raises(ValueError, match="one cell"):
        store.write_cell([_row(metric="l1"), _row(material="m2")])
    # A row that violates the schema mid-way rolls the whole cell back.
    with pytest.raises(sqlite3.IntegrityError):
        store.write_cell([_row(metric="a"), _row(metric=None)])
    assert store.frame().empty


def test_failed_cells_are_replaced_and_finished_cells_kept(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    store.write_cell([_row(metric="error", value=None, status="failed")])
    assert not store.has_cell("h1", "fp", "m1")
    assert store.write_cell([_row(metric="l1", value=0.1)])
    assert not store.write_cell([_row(metric="l1", value=0.9)])  # the first complete writer wins
    df = store.frame()
    assert list(df.status) == ["ok"] and list(df.value) == [0.1]


def test_the_unique_key_refuses_a_duplicate_row(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    with pytest.raises(sqlite3.IntegrityError):
        store.write_cell([_row(metric="l1"), _row(metric="l1")])
    assert store.write_cell([_row(metric="rmse_hdr", spp=1), _row(metric="rmse_hdr", spp=2)])  # spp is in the key


def _write_many(path, worker):
    store = ResultsStore(path)
    for i in range(40):
        store.write_cell([_row(material=f"m{i}", metric=m, value=float(worker)) for m in ("l1", "fit_time")])


def test_concurrent_writers_never_duplicate_a_cell(tmp_path):
    path = tmp_path / "r.sqlite"
    ResultsStore(path)
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_write_many, args=(path, w)) for w in range(3)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    df = ResultsStore(path).frame()
    assert len(df) == 80 and df.groupby(["material", "metric"]).size().max() == 1
    assert df.groupby("material")["value"].nunique().max() == 1  # each cell whole, from one writer


@pytest.mark.parametrize("content, match", [
    (b"SQLite format 3\x00" + b"\x00" * 84 + b"garbage" * 200, "damaged|not a brdfbench store"),
    (os.urandom(8192), "damaged|not a brdfbench store"),
    (b"this is a text file, not a store\n" * 40, "damaged|not a brdfbench store"),
])
def test_a_damaged_store_is_named_and_left_as_it_was(tmp_path, content, match):
    path = tmp_path / "brdfbench.sqlite"
    path.write_bytes(content)
    with pytest.raises(DataError, match=match) as err:
        ResultsStore(path)
    assert str(path) in str(err.value) and "move it aside" in str(err.value)
    assert path.read_bytes() == content


def test_a_truncated_store_is_named(tmp_path):
    path = tmp_path / "brdfbench.sqlite"
    store = ResultsStore(path)
    for i in range(200):
        store.write_cell([_row(material=f"m{i}", metric="l1")])
    with sqlite3.connect(path) as con:
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=str(path)):
        ResultsStore(path).frame()


def test_another_schema_and_a_directory_are_named(tmp_path):
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as con:
        con.execute("CREATE TABLE people (name TEXT)")
    with pytest.raises(DataError, match="not a brdfbench results store"):
        ResultsStore(other)
    (tmp_path / "dir.sqlite").mkdir()
    with pytest.raises(DataError, match="is a directory"):
        ResultsStore(tmp_path / "dir.sqlite")
    newer = tmp_path / "newer.sqlite"
    with sqlite3.connect(newer) as con:
        con.execute("PRAGMA user_version = 99")
    with pytest.raises(DataError, match="newer brdfbench"):
        ResultsStore(newer)


def test_a_non_numeric_value_is_named_by_row(tmp_path):
    path = tmp_path / "r.sqlite"
    store = ResultsStore(path)
    store.write_cell([_row(metric="l1")])
    with sqlite3.connect(path) as con:
        con.execute("UPDATE results SET value = 'abc'")
    with pytest.raises(DataError, match=r"row 1 holds a non-numeric value 'abc'"):
        store.frame()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes read-only files")
def test_a_read_only_store_is_named(tmp_path):
    path = tmp_path / "r.sqlite"
    ResultsStore(path).write_cell([_row()])
    path.chmod(0o444)
    tmp_path.chmod(0o555)
    try:
        with pytest.raises(DataError, match="not writable"):
            ResultsStore(path).write_cell([_row(material="m2")])
    finally:
        tmp_path.chmod(0o755)
