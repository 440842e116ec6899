"""The results store's SQL schema (v4), shared by the store and its migrations."""

SCHEMA_VERSION = 4

SCHEMA = """
CREATE TABLE configs (
    config_hash TEXT PRIMARY KEY,
    label TEXT NOT NULL,
    plugin TEXT NOT NULL,
    plugin_version TEXT NOT NULL,
    harness TEXT NOT NULL,
    params TEXT NOT NULL
);
CREATE TABLE environments (
    env_id TEXT PRIMARY KEY,
    host TEXT NOT NULL,
    cpu_model TEXT NOT NULL,
    cpu_count INTEGER NOT NULL,
    threads INTEGER NOT NULL,
    launcher TEXT NOT NULL,
    platform TEXT NOT NULL,
    device TEXT NOT NULL DEFAULT 'cpu',
    device_detail TEXT NOT NULL DEFAULT 'cpu'
);
CREATE TABLE results (
    run_id TEXT NOT NULL,
    config_hash TEXT NOT NULL,
    dataset TEXT NOT NULL,
    dataset_fingerprint TEXT NOT NULL,
    scope TEXT NOT NULL CHECK (scope IN ('material', 'set')),
    material TEXT NOT NULL,
    category TEXT NOT NULL,
    scene TEXT NOT NULL,
    sampler TEXT NOT NULL,
    spp INTEGER NOT NULL,
    metric TEXT NOT NULL,
    value REAL,
    unit TEXT NOT NULL,
    higher_is_better INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    message TEXT NOT NULL,
    seed INTEGER NOT NULL,
    package_version TEXT NOT NULL,
    git_sha TEXT NOT NULL,
    timestamp REAL NOT NULL,
    env_id TEXT NOT NULL,
    concurrent_jobs INTEGER NOT NULL,
    distance TEXT NOT NULL DEFAULT '',
    UNIQUE (config_hash, dataset_fingerprint, scope, material, category, metric, distance, spp)
);
CREATE INDEX results_cell ON results (config_hash, dataset_fingerprint, scope, material);
"""

#: The environment of rows migrated from a v1 store, which recorded none.
UNKNOWN_ENV = "unknown"

#: Columns v4 added to `environments` (where a figure was computed), with their SQL
#: definitions: figures of older stores were all computed on the CPU.
DEVICE_COLUMNS = (("device", "TEXT NOT NULL DEFAULT 'cpu'"), ("device_detail", "TEXT NOT NULL DEFAULT 'cpu'"))
