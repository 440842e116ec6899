import sqlite3

import pytest

from brdfbench.store import ResultsStore, Row


def _row(material="m1", metric="l1", value=1.0, status="ok", chash="h1", rep="lambert"):
    return Row(
        run_id="r", representation=rep, dataset="synthetic", dataset_fingerprint="fp", material=material,
        category="plastic", metric=metric, value=value, unit="1/sr", higher_is_better=False, status=status,
        message="", seed=0, config_hash=chash, package_version="0", git_sha="x", timestamp=1.0,
    )


def test_write_and_read_back_typed_rows(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    store.write_cell([_row(metric="l1", value=0.5), _row(metric="fit_time", value=2.0)])
    df = store.frame()
    assert sorted(df.metric) == ["fit_time", "l1"]
    assert df.higher_is_better.dtype == bool
    assert store.has_cell("lambert", "h1", "fp", "m1")
    assert not store.has_cell("lambert", "h2", "fp", "m1")
    assert len(store.frame(metric="l1")) == 1
    with pytest.raises(KeyError, match="bogus"):
        store.frame(bogus="x")


def test_cell_is_all_or_nothing(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    bad = _row(metric="l1")
    with pytest.raises(ValueError, match="one cell"):
        store.write_cell([bad, _row(material="m2")])
    # A row that violates the schema mid-way rolls the whole cell back.
    broken = _row(metric=None)  # metric is NOT NULL
    with pytest.raises(sqlite3.IntegrityError):
        store.write_cell([_row(metric="a"), broken])
    assert store.frame().empty


def test_failed_cells_are_retried_and_replaced(tmp_path):
    store = ResultsStore(tmp_path / "r.sqlite")
    store.write_cell([_row(metric="error", value=None, status="failed")])
    assert not store.has_cell("lambert", "h1", "fp", "m1")
    store.write_cell([_row(metric="l1", value=0.1)])
    df = store.frame()
    assert list(df.status) == ["ok"]
