"""Aggregate store rows into per-representation summaries, one per dataset."""

from __future__ import annotations

import pandas as pd

#: Accuracy metric used to rank, first one present wins.
PRIMARY_METRICS = ("l1_log_cos", "l1_log", "l1", "hdr_rmse",
                   # rendered scenes (each scene is its own section)
                   "psnr_ldr", "ssim_ldr", "flip_ldr", "psnr_hdr", "ssim_hdr", "flip_hdr", "rmse_hdr", "rmse_ldr")
#: Columns shown beside accuracy, with the aggregate that makes sense for each: costs, and a
#: model's own final fit loss (each family's own objective: not comparable across families,
#: so never ranked).
COST_METRICS = {
    "fit_loss": "mean",
    "fit_time": "mean",
    "fit_batch": "median",
    "train_time": "mean",
    "evals_per_s": "median",
    "model_bytes": "median",
    "shared_bytes": "median",
    "flops_per_eval": "median",
    "render_time": "mean",
    "render_samples_per_s": "median",
}


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (representation, metric): mean/median/worst over materials, with unit and direction."""
    ok = df[df.status == "ok"]
    if ok.empty:
        return pd.DataFrame(columns=["representation", "metric", "mean", "median", "worst", "n", "unit", "higher_is_better"])
    # Latest value per cell and metric (a re-run with a new config hash adds rows).
    ok = ok.sort_values("timestamp").drop_duplicates(["representation", "material", "metric"], keep="last")
    groups = ok.groupby(["representation", "metric"])
    out = groups["value"].agg(["mean", "median", "min", "max", "count"]).reset_index()
    meta = groups[["unit", "higher_is_better"]].first().reset_index()
    out = out.merge(meta, on=["representation", "metric"])
    out["worst"] = out["min"].where(out["higher_is_better"], out["max"])
    return out.rename(columns={"count": "n"}).drop(columns=["min", "max"])


def failures(df: pd.DataFrame) -> pd.DataFrame:
    failed = df[df.status == "failed"].sort_values("timestamp").drop_duplicates(["representation", "material"], keep="last")
    done = df[df.status == "ok"][["representation", "material"]].drop_duplicates()
    merged = failed.merge(done, on=["representation", "material"], how="left", indicator=True)
    return merged[merged["_merge"] == "left_only"][["representation", "material", "message"]]


def primary_metric(summary: pd.DataFrame) -> str | None:
    present = set(summary["metric"])
    return next((m for m in PRIMARY_METRICS if m in present), None)


def ranking(summary: pd.DataFrame, metric: str) -> pd.DataFrame:
    rows = summary[summary.metric == metric]
    if rows.empty:
        return rows
    ascending = not bool(rows["higher_is_better"].iloc[0])
    return rows.sort_values("mean", ascending=ascending).reset_index(drop=True)


# --------------------------------------------------------------------------- convergence

#: The store's scene column of convergence rows: "<scene>/convergence/<sampler>".
CONVERGENCE_INFIX = "/convergence/"
#: Per-rung metric names: "<metric>@spp=<n>".
_RUNG = r"^(?P<base>.+)@spp=(?P<spp>\d+)$"


def is_convergence(scene: str) -> bool:
    return CONVERGENCE_INFIX in scene


def split_convergence(scene: str) -> tuple[str, str]:
    """(scene, sampler label) of a convergence scene label."""
    base, _, sampler = scene.partition(CONVERGENCE_INFIX)
    return base, sampler


def convergence_rungs(df: pd.DataFrame) -> pd.DataFrame:
    """Per-rung means over materials: representation, base (metric), spp, mean, n, unit."""
    summary = summarize(df)
    parts = summary["metric"].str.extract(_RUNG)
    rungs = summary.assign(base=parts["base"], spp=pd.to_numeric(parts["spp"])).dropna(subset=["base"])
    return rungs.astype({"spp": int}).sort_values(["representation", "base", "spp"]).reset_index(drop=True)
