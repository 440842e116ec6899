"""Store backends are plugins (group `stores`), and stores written apart merge into one."""

from __future__ import annotations

from pathlib import Path

import pytest

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError, DataError, PluginError
from brdfbench.plugins.specs import StoreSpec
from brdfbench.store.sqlite import ResultsStore, sqlite_store
from brdfbench.store.protocol import ConfigRecord, Environment, Row, Store, merge, open_store


def _row(material="m1", metric="l1", value=1.0, status="ok", chash="h1", env="e1"):
    return Row(run_id="r", config_hash=chash, dataset="synthetic", dataset_fingerprint="fp", material=material,
               category="plastic", metric=metric, value=value, unit="1/sr", higher_is_better=metric == "evals_per_s",
               status=status, message="" if status == "ok" else "boom", seed=0, package_version="0", git_sha="x",
               timestamp=1.0, env_id=env)


def _store(path: Path, cells: dict[str, list[Row]], config=("h1", "lambert"), env="e1") -> ResultsStore:
    store = ResultsStore(path)
    store.write_config(ConfigRecord(config[0], config[1], "lambert", "0.1", "accuracy", {"params": {}}))
    store.write_environment(Environment(env, f"host-{env}", "cpu", 2, 2, "basic", "Linux"))
    for rows in cells.values():
        store.write_cell(rows)
    return store


def _values(store: Store) -> dict:
    return {(r.material, r.metric): (r.value, r.status) for rows in store.cells() for r in rows}


def test_the_sqlite_store_is_a_registered_plugin(tmp_path):
    assert "sqlite" in registry.names("stores")
    store = open_store("sqlite", tmp_path, {})
    assert isinstance(store, Store) and store.location == str(tmp_path / "brdfbench.sqlite")
    assert open_store("sqlite", tmp_path, {"file": "other.sqlite"}).location == str(tmp_path / "other.sqlite")
    with pytest.raises(DataError, match=r"nowhere/brdfbench.sqlite: no results store here"):
        open_store("sqlite", tmp_path / "nowhere", {"create": False})
    assert not (tmp_path / "nowhere").exists()
    with pytest.raises(ConfigError, match="store=sqlite: bad store_params"):
        open_store("sqlite", tmp_path, {"bogus": 1})
    with pytest.raises(PluginError, match="Did you mean 'sqlite'"):
        open_store("sqlit", tmp_path)


def test_a_plugin_that_returns_no_store_is_refused(tmp_path):
    registry.register("stores", StoreSpec(name="not_a_store", description="test", target="builtins:str"))
    try:
        with pytest.raises(ConfigError, match="returned a str, not a brdfbench.store.protocol.Store"):
            open_store("not_a_store", tmp_path)
    finally:
        registry.unregister("stores", "not_a_store")


def test_cells_read_back_whole_and_typed(tmp_path):
    store = _store(tmp_path / "a.sqlite", {"m1": [_row(), _row(metric="evals_per_s", value=5.0)],
                                           "m2": [_row("m2", "error", None, "failed")]})
    cells = list(store.cells())
    assert [sorted(r.metric for r in rows) for rows in cells] == [["evals_per_s", "l1"], ["error"]]
    assert all(isinstance(r.higher_is_better, bool) for rows in cells for r in rows)
    assert store.configs()[0].label == "lambert" and store.environments()[0].host == "host-e1"


def test_merge_copies_everything_once_whatever_the_order(tmp_path):
    a = _store(tmp_path / "a.sqlite", {"m1": [_row(value=0.1)], "m2": [_row("m2", "error", None, "failed")]})
    b = _store(tmp_path / "b.sqlite", {"m2": [_row("m2", value=0.2)], "m3": [_row("m3", value=0.3)],
                                       "m1": [_row(value=0.9)]}, env="e2")
    ab, ba = ResultsStore(tmp_path / "ab.sqlite"), ResultsStore(tmp_path / "ba.sqlite")
    assert merge(a, ab) == {"written": 2, "kept": 0}
    assert merge(b, ab) == {"written": 2, "kept": 1}  # m2's failure is replaced; m1 was finished in a
    merge(b, ba), merge(a, ba)
    want = {("m1", "l1"): (0.1, "ok"), ("m2", "l1"): (0.2, "ok"), ("m3", "l1"): (0.3, "ok")}
    assert _values(ab) == want
    assert _values(ba) == {**want, ("m1", "l1"): (0.9, "ok")}  # first complete writer wins, as in a sweep
    assert {e.env_id for e in ab.environments()} == {"e1", "e2"} and len(ab.configs()) == 1
    assert merge(a, ab) == {"written": 0, "kept": 2}  # merging again changes nothing
    assert len(ab.frame()) == 3


def test_a_damaged_value_stops_the_merge_naming_the_store(tmp_path):
    import sqlite3

    a = _store(tmp_path / "a.sqlite", {"m1": [_row()]})
    with sqlite3.connect(a.path) as con:
        con.execute("UPDATE results SET value='abc'")
    with pytest.raises(DataError, match=r"a\.sqlite: a l1 row of m1 holds a non-numeric value 'abc'"):
        merge(a, ResultsStore(tmp_path / "into.sqlite"))


def test_the_runner_writes_through_the_chosen_store(tmp_path, synthetic_cache):
    from brdfbench.pipeline.config import RunConfig, harness_config
    from brdfbench.pipeline.sweep import run_job as run

    registry.register("stores", StoreSpec(name="sqlite_elsewhere", description="test: the sqlite store, renamed",
                                          target=f"{__name__}:elsewhere"))
    try:
        cfg = RunConfig(representation="lambert", representation_params={}, label="lambert", dataset="synthetic",
                        dataset_params={"size": "small", "cache_dir": str(synthetic_cache)},
                        harness=harness_config(n_random=1024, throughput_batch=256), results_dir=tmp_path, limit=1,
                        progress="none", isolate=False, store="sqlite_elsewhere", store_params={"name": "x.sqlite"})
        assert run(cfg)["done"] == 1
        assert not (tmp_path / "brdfbench.sqlite").exists()
        assert set(ResultsStore(tmp_path / "x.sqlite").frame().material) == {"synth-plastic-green-00"}
        with pytest.raises(ConfigError, match=r"unknown key store_params.nme; store_params takes: name$"):
            run(RunConfig(**{**cfg.__dict__, "store_params": {"nme": "x.sqlite"}}))
        with pytest.raises(ConfigError, match=r"store_params.create is set by brdfbench, not by a config"):
            run(RunConfig(**{**cfg.__dict__, "store_params": {"create": False}}))
    finally:
        registry.unregister("stores", "sqlite_elsewhere")


def elsewhere(results_dir: Path, create: bool = True, name: str = "elsewhere.sqlite") -> ResultsStore:
    """A third-party store factory for the test above."""
    return sqlite_store(results_dir, create=create, file=name)
