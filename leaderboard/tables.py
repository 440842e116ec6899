"""Aggregate store rows into per-representation summaries, one per dataset."""

from __future__ import annotations

import pandas as pd

#: Accuracy metric used to rank, first one present wins.
PRIMARY_METRICS = ("l1_log_cos", "l1_log", "l1", "hdr_rmse")
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
