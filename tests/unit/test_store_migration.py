"""A store written by brdfbench's v1 schema (no user_version) migrates to v2 and loses nothing."""

import sqlite3

import pytest

from brdfbench.store.sqlite import SCHEMA_VERSION, ResultsStore
from brdfbench_leaderboard import markdown

#: The v1 DDL, as v1's store.py created it (the `scene` column was added by ALTER TABLE in
#: later v1 releases; `old` leaves it out, as the first v1 stores did).
V1 = """
CREATE TABLE IF NOT EXISTS results (
    run_id TEXT NOT NULL, representation TEXT NOT NULL, dataset TEXT NOT NULL, dataset_fingerprint TEXT NOT NULL,
    material TEXT NOT NULL, category TEXT NOT NULL, metric TEXT NOT NULL, value REAL, unit TEXT NOT NULL,
    higher_is_better INTEGER NOT NULL, status TEXT NOT NULL, message TEXT NOT NULL, seed INTEGER NOT NULL,
    config_hash TEXT NOT NULL, package_version TEXT NOT NULL, git_sha TEXT NOT NULL, timestamp REAL NOT NULL
    {scene}
);
CREATE INDEX IF NOT EXISTS cell ON results (representation, config_hash, dataset_fingerprint, material);
"""
COLS = ("run_id, representation, dataset, dataset_fingerprint, material, category, metric, value, unit, "
        "higher_is_better, status, message, seed, config_hash, package_version, git_sha, timestamp")


def _v1(path, with_scene=True):
    con = sqlite3.connect(path)
    con.executescript(V1.format(scene=", scene TEXT NOT NULL DEFAULT 'brdf_space'" if with_scene else ""))
    rows = []
    t = 1.0
    for rep, chash in (("merl", "aaaa"), ("cook-torrance", "bbbb")):
        for mat in ("m1", "m2"):
            for metric, value, unit in (("l1", 0.1, "1/sr"), ("fit_time", 2.0, "s"), ("evals_per_s", 1e6, "evals/s")):
                rows.append(("r1", rep, "synthetic", "fp", mat, "plastic", metric, value, unit, int(metric == "evals_per_s"),
                             "ok", "", 0, chash, "0.1.0", "abc", t, "brdf_space"))
                t += 1
    # the concurrent-writer bug of v1: one cell written twice under two run ids
    rows.append(("r2", "merl", "synthetic", "fp", "m1", "plastic", "l1", 0.1, "1/sr", 0, "ok", "", 0, "aaaa", "0.1.0",
                 "abc", t + 1, "brdf_space"))
    # a failure that was never resolved
    rows.append(("r1", "ggx", "synthetic", "fp", "m1", "plastic", "error", None, "", 0, "failed", "boom", 0, "cccc",
                 "0.1.0", "abc", t + 2, "brdf_space"))
    # convergence rows with packed keys
    for n in (1, 4):
        rows.append(("r3", "lambert", "synthetic", "fp", "m1", "plastic", f"rmse_hdr@spp={n}", 0.2 / n, "radiance", 0,
                     "ok", "", 0, "dddd", "0.1.0", "abc", t + 3 + n, "sphere_envmap/convergence/ggx(alpha=0.2)"))
    if not with_scene:
        rows = [r[:-1] for r in rows if r[-1] == "brdf_space"]
    cols = COLS + (", scene" if with_scene else "")
    con.executemany(f"INSERT INTO results ({cols}) VALUES ({', '.join('?' * len(rows[0]))})", rows)
    con.commit()
    con.close()
    return rows


@pytest.mark.parametrize("with_scene", [True, False])
def test_a_v1_store_migrates_and_loses_nothing(tmp_path, with_scene):
    path = tmp_path / "brdfbench.sqlite"
    written = _v1(path, with_scene)
    store = ResultsStore(path)
    df = store.frame()
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert len(df) == len(written) - 1  # the duplicated cell's row is kept once
    assert set(df.representation) == {r[1] for r in written}
    failure = df[df.status == "failed"]
    assert list(failure.message) == ["boom"] and list(failure.representation) == ["ggx"]
    if with_scene:
        conv = df[df.config_hash == "dddd"].sort_values("spp")
        assert list(conv.scene) == ["sphere_envmap"] * 2 and list(conv.sampler) == ["ggx(alpha=0.2)"] * 2
        assert list(conv.metric) == ["rmse_hdr"] * 2 and list(conv.spp) == [1, 4] and list(conv.harness) == ["convergence"] * 2
    # the old cells are still "done" for their config hash: a re-run of v1's configs recomputes nothing
    assert store.has_cell("aaaa", "fp", "m2")
    text = markdown.render(df, str(path))
    assert "`merl`" in text and "`cook-torrance`" in text and "boom" in text
    ResultsStore(path)  # opening again is a no-op


def test_a_failed_migration_leaves_the_store_as_it_was(tmp_path):
    path = tmp_path / "brdfbench.sqlite"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE results (run_id TEXT, representation TEXT)")  # not v1's columns
    con.commit()
    con.close()
    before = path.read_bytes()
    with pytest.raises(Exception, match="not a brdfbench v1 store"):
        ResultsStore(path)
    assert path.read_bytes() == before


#: The v2 DDL, as v2's store_schema.py created it (no `distance` column; a unique key
#: without `category` and `distance`).
V2 = """
CREATE TABLE configs (config_hash TEXT PRIMARY KEY, label TEXT NOT NULL, plugin TEXT NOT NULL,
    plugin_version TEXT NOT NULL, harness TEXT NOT NULL, params TEXT NOT NULL);
CREATE TABLE environments (env_id TEXT PRIMARY KEY, host TEXT NOT NULL, cpu_model TEXT NOT NULL,
    cpu_count INTEGER NOT NULL, threads INTEGER NOT NULL, launcher TEXT NOT NULL, platform TEXT NOT NULL);
CREATE TABLE results (
    run_id TEXT NOT NULL, config_hash TEXT NOT NULL, dataset TEXT NOT NULL, dataset_fingerprint TEXT NOT NULL,
    scope TEXT NOT NULL CHECK (scope IN ('material', 'set')), material TEXT NOT NULL, category TEXT NOT NULL,
    scene TEXT NOT NULL, sampler TEXT NOT NULL, spp INTEGER NOT NULL, metric TEXT NOT NULL, value REAL,
    unit TEXT NOT NULL, higher_is_better INTEGER NOT NULL, status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    message TEXT NOT NULL, seed INTEGER NOT NULL, package_version TEXT NOT NULL, git_sha TEXT NOT NULL,
    timestamp REAL NOT NULL, env_id TEXT NOT NULL, concurrent_jobs INTEGER NOT NULL,
    UNIQUE (config_hash, dataset_fingerprint, scope, material, metric, spp)
);
CREATE INDEX results_cell ON results (config_hash, dataset_fingerprint, scope, material);
PRAGMA user_version = 2;
"""


def _v2(path):
    con = sqlite3.connect(path)
    con.executescript(V2)
    con.execute("INSERT INTO configs VALUES ('aaaa', 'merl (mode=nearest)', 'merl', '0.1.0', 'accuracy', '{\"mode\": \"nearest\"}')")
    con.execute("INSERT INTO environments VALUES ('e1', 'host', 'cpu', 2, 2, 'basic', 'linux')")
    rows = []
    for i, (mat, metric, value, spp) in enumerate((("m1", "l1", 0.1, 0), ("m1", "fit_time", 2.0, 0),
                                                    ("m2", "l1", 0.2, 0), ("m2", "rmse_hdr", 0.3, 16))):
        rows.append(("r1", "aaaa", "synthetic", "fp", "material", mat, "plastic", "brdf_space", "", spp, metric, value,
                     "1/sr", 0, "ok", "", 0, "0.1.0", "abc", float(i), "e1", 1))
    rows.append(("r1", "aaaa", "synthetic", "fp", "material", "m3", "metal", "brdf_space", "", 0, "error", None, "", 0,
                 "failed", "boom", 0, "0.1.0", "abc", 9.0, "e1", 1))
    con.executemany(f"INSERT INTO results VALUES ({', '.join('?' * 22)})", rows)
    con.commit()
    con.close()
    return rows


def test_a_v2_store_migrates_to_the_current_schema_and_loses_nothing(tmp_path):
    path = tmp_path / "brdfbench.sqlite"
    written = _v2(path)
    store = ResultsStore(path)
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 4
    got = con.execute("SELECT * FROM results ORDER BY rowid").fetchall()
    con.close()
    assert [(e.env_id, e.device, e.device_detail) for e in store.environments()] == [("e1", "cpu", "cpu")]
    assert [r[:22] for r in got] == written and all(r[22] == "" for r in got)
    assert [c.label for c in store.configs()] == ["merl (mode=nearest)"]
    assert store.done_cells("aaaa", "fp") == {"m1", "m2"}
    # the new key: two rows of one cell and metric that differ in category or distance both fit
    from dataclasses import replace

    base = next(store.cells())[0]
    cell = [replace(base, material="set-0", scope="set", metric="mmd", distance=d, category=c)
            for d in ("l1", "l1_log") for c in ("set", "diffuse")]
    assert store.write_cell(cell)
    assert len(store.frame(material="set-0")) == 4
    ResultsStore(path)  # opening a migrated store again is a no-op


def _v3(path):
    """A v3 store: v2's tables with the `distance` column and v3's unique key."""
    rows = _v2(path)
    con = sqlite3.connect(path)
    con.executescript("""
ALTER TABLE results RENAME TO results_v2;
DROP INDEX results_cell;
CREATE TABLE results (
    run_id TEXT NOT NULL, config_hash TEXT NOT NULL, dataset TEXT NOT NULL, dataset_fingerprint TEXT NOT NULL,
    scope TEXT NOT NULL CHECK (scope IN ('material', 'set')), material TEXT NOT NULL, category TEXT NOT NULL,
    scene TEXT NOT NULL, sampler TEXT NOT NULL, spp INTEGER NOT NULL, metric TEXT NOT NULL, value REAL,
    unit TEXT NOT NULL, higher_is_better INTEGER NOT NULL, status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    message TEXT NOT NULL, seed INTEGER NOT NULL, package_version TEXT NOT NULL, git_sha TEXT NOT NULL,
    timestamp REAL NOT NULL, env_id TEXT NOT NULL, concurrent_jobs INTEGER NOT NULL, distance TEXT NOT NULL DEFAULT '',
    UNIQUE (config_hash, dataset_fingerprint, scope, material, category, metric, distance, spp)
);
CREATE INDEX results_cell ON results (config_hash, dataset_fingerprint, scope, material);
INSERT INTO results SELECT *, '' FROM results_v2;
DROP TABLE results_v2;
PRAGMA user_version = 3;
""")
    con.commit()
    con.close()
    return rows


def test_a_v3_store_gains_the_device_columns_and_loses_nothing(tmp_path):
    path = tmp_path / "brdfbench.sqlite"
    written = _v3(path)
    before = sqlite3.connect(path).execute("SELECT * FROM results ORDER BY rowid").fetchall()
    store = ResultsStore(path)
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert con.execute("SELECT * FROM results ORDER BY rowid").fetchall() == before
    con.close()
    assert [r[:22] for r in before] == written
    # every figure of a v3 store was computed on the CPU
    assert [(e.env_id, e.device, e.device_detail) for e in store.environments()] == [("e1", "cpu", "cpu")]
    from brdfbench.store.protocol import Environment

    gpu = Environment("e2", "host", "cpu", 16, 16, "basic", "linux", "cuda:0", "NVIDIA H200, 139.8 GiB")
    store.write_environment(gpu)
    assert {e.env_id: e.device for e in store.environments()} == {"e1": "cpu", "e2": "cuda:0"}
    ResultsStore(path)  # opening a migrated store again is a no-op
