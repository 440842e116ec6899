"""Aggregate store rows into per-configuration summaries, one per report section.

A configuration (its config hash) is one row of a table, never merged with another. Its
label is the configuration's label; where two configurations in a section share a label,
each gets the parameters in which they differ: `nbrdf (hidden=[8, 8])`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import pandas as pd

from brdfbench.harness.lobes import TARGET_HALF_WIDTH
from brdfbench.plugins import registry

@dataclass(frozen=True)
class Failure:
    """A cell that failed and has not succeeded since: who, on what, and why."""

    label: str
    material: str
    message: str


#: Columns shown beside accuracy, with the aggregate that makes sense for each: costs, and a
#: model's own final fit loss (each family's own objective: not comparable across families,
#: so never ranked).
COST_METRICS = {
    "fit_loss": "mean",
    "fit_time": "mean",
    "fit_batch": "median",
    "fit_workers": "median",
    "train_time": "mean",
    "evals_per_s": "median",
    "model_bytes": "median",
    "shared_bytes": "median",
    "flops_per_eval": "median",
    "render_time": "mean",
    "render_samples_per_s": "median",
    "peak_rss_fit": "max",
    "peak_rss_eval": "max",
    "peak_rss_train": "max",
}
#: Properties of a cell's target, not figures of its model: never columns; the report groups
#: materials by them (the sharpest tenth by `target_lobe_half_width`, rad).
TARGET_PROPERTIES = (TARGET_HALF_WIDTH,)
#: Cost figures that depend on the machine's load (timings), flagged when measured under contention.
TIMED = ("fit_time", "train_time", "evals_per_s", "render_time", "render_samples_per_s")

_DEFAULTS = {"config_hash": None, "params": "null", "spp": 0, "sampler": "", "scene": "brdf_space", "harness": None,
             "concurrent_jobs": 1, "scope": "material", "distance": "", "device": "cpu", "device_detail": "cpu"}


def accelerator(detail: str) -> str:
    """The model of the accelerator a figure was computed on ("" for the CPU): the first part
    of the environment's `device_detail`, e.g. "NVIDIA H200"."""
    detail = str(detail or "cpu")
    return "" if detail == "cpu" else detail.split(",")[0].strip()


def normalise(df: pd.DataFrame) -> pd.DataFrame:
    """The frame with every column the report reads (older or hand-made frames lack some)."""
    df = df.copy()
    for col, default in _DEFAULTS.items():
        if col not in df.columns:
            df[col] = default
    df["config_hash"] = df["config_hash"].where(df["config_hash"].notna(), df["representation"])
    missing = df["harness"].isna() | (df["harness"] == "")
    inferred = df["sampler"].map(lambda s: "convergence" if s else None)
    inferred = inferred.where(inferred.notna(), df["scene"].map(lambda s: "accuracy" if s == "brdf_space" else "render"))
    df["harness"] = df["harness"].where(~missing, inferred)
    df["spp"] = pd.to_numeric(df["spp"]).fillna(0).astype(int)
    return df


def _params(text: Any) -> dict[str, Any] | None:
    try:
        value = json.loads(text) if isinstance(text, str) else None
    except ValueError:
        return None
    return value if isinstance(value, dict) and "migrated_from" not in value else None


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flatten(v, f"{key}."))
        else:
            out[key] = v
    return out


def _show(value: Any) -> str:
    return json.dumps(value, default=str).replace('"', "") if isinstance(value, (list, dict)) else str(value)


def display_labels(df: pd.DataFrame) -> dict[str, str]:
    """config hash → the label shown for it: unique within `df`."""
    configs = df.drop_duplicates("config_hash")[["config_hash", "representation", "params"]]
    out: dict[str, str] = {}
    for label, group in configs.groupby("representation", sort=False):
        if len(group) == 1:
            out[group.config_hash.iloc[0]] = label
            continue
        flat = {h: _flatten(p) if (p := _params(text)) is not None else None
                for h, text in zip(group.config_hash, group.params)}
        known = [f for f in flat.values() if f is not None]
        keys = sorted({k for f in known for k in f})
        differing = [k for k in keys if len({_show(f.get(k, "–")) for f in known}) > 1]
        for h, f in flat.items():
            if f is None:
                out[h] = f"{label} [{h[:8]}]"
                continue
            shown = [k for k in differing if not k.startswith("harness.")] or differing
            parts = ", ".join(f"{k.removeprefix('params.')}={_show(f.get(k, '–'))}" for k in shown)
            out[h] = f"{label} ({parts})" if parts else f"{label} [{h[:8]}]"
    # two configurations can still collide (identical shown parameters): keep them apart by hash
    seen: dict[str, int] = {}
    for h, name in out.items():
        seen[name] = seen.get(name, 0) + 1
    return {h: (f"{name} [{h[:8]}]" if seen[name] > 1 else name) for h, name in out.items()}


def with_labels(df: pd.DataFrame) -> pd.DataFrame:
    """`representation` replaced by each configuration's unique display label."""
    labels = display_labels(df)
    return df.assign(representation=df["config_hash"].map(labels))


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (configuration label, metric, spp): mean/median/max/worst over materials,
    with unit, direction and whether any of its cells ran beside other jobs."""
    cols = ["representation", "metric", "spp", "mean", "median", "max", "worst", "n", "unit", "higher_is_better",
            "contended"]
    ok = df[df.status == "ok"]
    if ok.empty:
        return pd.DataFrame(columns=cols)
    if "spp" not in ok.columns:
        ok = ok.assign(spp=0)
    if "concurrent_jobs" not in ok.columns:
        ok = ok.assign(concurrent_jobs=1)
    keys = ["representation", "metric", "spp"]
    groups = ok.groupby(keys)
    out = groups["value"].agg(["mean", "median", "min", "max", "count"]).reset_index()
    meta = groups[["unit", "higher_is_better"]].first().reset_index()
    contended = groups["concurrent_jobs"].max().reset_index(name="contended")
    out = out.merge(meta, on=keys).merge(contended, on=keys)
    out["contended"] = out["contended"] > 1
    out["worst"] = out["min"].where(out["higher_is_better"], out["max"])
    return out.rename(columns={"count": "n"}).drop(columns=["min"])[cols]


def failures(df: pd.DataFrame) -> pd.DataFrame:
    failed = df[df.status == "failed"].sort_values("timestamp").drop_duplicates(["representation", "material"], keep="last")
    done = df[df.status == "ok"][["representation", "material"]].drop_duplicates()
    merged = failed.merge(done, on=["representation", "material"], how="left", indicator=True)
    return merged[merged["_merge"] == "left_only"][["representation", "material", "message"]]


def metric_rank(name: str) -> int | None:
    """The metric plugin's ranking preference (`MetricSpec.rank`); None for an unranked or
    unregistered one (a store may hold figures of a plugin no longer installed)."""
    try:
        return registry.get("metrics", name).rank
    except Exception:  # an unknown name: the registry's lookup error
        return None


def is_reference(plugin: str, params: dict[str, Any] | None) -> bool:
    """Whether a stored configuration is its representation's reference (the target itself,
    `RepresentationSpec.reference`); False for a plugin no longer installed."""
    try:
        spec = registry.get("representations", plugin)
    except Exception:
        return False
    inner = (params or {}).get("params")
    return bool(getattr(spec, "is_reference", None)) and spec.is_reference(inner if isinstance(inner, dict) else {})


def dataset_caveat(name: str) -> str:
    """What the dataset plugin says its figures do not show (`DatasetSpec.caveat`), or ""."""
    try:
        return registry.get("datasets", name).caveat
    except Exception:
        return ""


def accuracy_metrics(summary: pd.DataFrame) -> list[str]:
    """The non-cost metrics present: ranked ones by rank, then the others by name."""
    present = set(summary["metric"]) - set(COST_METRICS) - set(TARGET_PROPERTIES)
    ranks = {m: metric_rank(m) for m in present}
    return sorted(present, key=lambda m: (ranks[m] is None, ranks[m] or 0, m))


def ranking(summary: pd.DataFrame, metric: str) -> pd.DataFrame:
    rows = summary[(summary.metric == metric) & (summary.spp == 0)]
    if rows.empty:
        return rows
    ascending = not bool(rows["higher_is_better"].iloc[0])
    return rows.sort_values("mean", ascending=ascending).reset_index(drop=True)


def sections(df: pd.DataFrame) -> list[tuple[tuple[str, str, str, str, str], pd.DataFrame]]:
    """((dataset, fingerprint, scene, harness, sampler), rows) of each report section; the
    sampler splits convergence sections only (a render section lists its configurations)."""
    df = normalise(df)
    df = df.assign(_section_sampler=df["sampler"].where(df["harness"] == "convergence", ""))
    out = []
    for key, group in df.groupby(["dataset", "dataset_fingerprint", "scene", "harness", "_section_sampler"], sort=True):
        out.append((key, with_labels(group.drop(columns="_section_sampler"))))
    return out


# --------------------------------------------------------------------------- convergence


def convergence_rungs(df: pd.DataFrame) -> pd.DataFrame:
    """Per-rung means over materials: representation, base (metric), spp, mean, n, unit."""
    summary = summarize(df)
    rungs = summary[summary.spp > 0].rename(columns={"metric": "base"})
    return rungs.sort_values(["representation", "base", "spp"]).reset_index(drop=True)
