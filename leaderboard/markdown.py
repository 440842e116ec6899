"""The Markdown leaderboard: accuracy side by side with what it costs."""

from __future__ import annotations

import math
import time

import pandas as pd

from . import tables

COST_LABELS = {
    "fit_loss": "own fit loss",
    "fit_time": "fit time (s) ↓",
    "fit_batch": "materials per fit",
    "train_time": "train time (s) ↓",
    "evals_per_s": "evals/s ↑",
    "model_bytes": "bytes/material ↓",
    "shared_bytes": "shared bytes ↓",
    "flops_per_eval": "FLOP/eval ↓",
}


#: Caveats printed under a dataset's heading: what its numbers do and do not show.
DATASET_NOTES = {
    "nbrdf_release": (
        "Targets are the published NBRDF networks (Sztrajman et al. 2021) evaluated on the MERL grid, "
        "not the measurements: refitting an NBRDF-generated table favours `nbrdf` (it can represent "
        "its target exactly), so its lead here overstates its accuracy on measured data."
    ),
}


def fmt(value: float) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if value == 0:
        return "0"
    if abs(value) >= 1e5 or abs(value) < 1e-3:
        return f"{value:.3e}"
    return f"{value:.4g}"


def _arrow(higher_is_better: bool) -> str:
    return "↑" if higher_is_better else "↓"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return lines


def dataset_section(name: str, fingerprint: str, df: pd.DataFrame) -> list[str]:
    summary = tables.summarize(df)
    n_materials = df["material"].nunique()
    lines = [f"## Dataset `{name}`", "", f"{n_materials} materials, fingerprint `{fingerprint}`.", ""]
    if name in DATASET_NOTES:
        lines += [f"> {DATASET_NOTES[name]}", ""]
    primary = tables.primary_metric(summary)
    if primary is None:
        lines += ["No successful results yet.", ""]
    else:
        ranked = tables.ranking(summary, primary)
        accuracy_metrics = [m for m in tables.PRIMARY_METRICS + ("hdr_mae",) if m in set(summary.metric)]
        accuracy_metrics += sorted(set(summary.metric) - set(accuracy_metrics) - set(tables.COST_METRICS))
        costs = [c for c in tables.COST_METRICS if c in set(summary.metric)]
        lookup = {(r.representation, r.metric): r for r in summary.itertuples()}
        header = ["rank", "representation"]
        header += [f"{m} {_arrow(lookup_any(summary, m).higher_is_better)}" for m in accuracy_metrics]
        header += [COST_LABELS[c] for c in costs] + ["materials"]
        rows = []
        for rank, rep in enumerate(ranked["representation"], 1):
            cells = [str(rank), f"`{rep}`"]
            cells += [fmt(lookup[(rep, m)].mean) if (rep, m) in lookup else "–" for m in accuracy_metrics]
            cells += [fmt(getattr(lookup[(rep, c)], tables.COST_METRICS[c])) if (rep, c) in lookup else "–" for c in costs]
            cells.append(f"{lookup[(rep, primary)].n}/{n_materials}")
            rows.append(cells)
        lines += [
            "### Accuracy and its cost",
            "",
            f"Ranked by mean `{primary}` over materials. Accuracy columns are means over materials; fit time is the "
            "mean per material (amortised over the materials fitted together, for batched fitters), evals/s and "
            "bytes the median. Representations that train on a split (train time, "
            "shared bytes) are cross-validated: each material is scored by a model trained without it. "
            "↓ lower is better, ↑ higher is better.",
            "",
            *_table(header, rows),
            "",
            "### Per metric",
            "",
        ]
        for metric in accuracy_metrics:
            r = tables.ranking(summary, metric)
            first = r.iloc[0]
            lines += [f"#### `{metric}` ({first.unit or 'unitless'}, {'higher' if first.higher_is_better else 'lower'} is better)", ""]
            lines += _table(
                ["rank", "representation", "mean", "median", "worst", "materials"],
                [[str(i), f"`{x.representation}`", fmt(x.mean), fmt(x.median), fmt(x.worst), str(x.n)]
                 for i, x in enumerate(r.itertuples(), 1)],
            )
            lines.append("")
    failed = tables.failures(df)
    if not failed.empty:
        lines += ["### Failures", ""]
        lines += _table(["representation", "material", "error"],
                        [[f"`{f.representation}`", f.material, f.message.replace("|", "\\|")[:200]] for f in failed.itertuples()])
        lines.append("")
    return lines


def lookup_any(summary: pd.DataFrame, metric: str):
    return summary[summary.metric == metric].iloc[0]


def render(df: pd.DataFrame, source: str) -> str:
    lines = [
        "# brdfbench leaderboard",
        "",
        f"Generated {time.strftime('%Y-%m-%d %H:%M:%S %Z')} from `{source}`.",
        "",
    ]
    if df.empty:
        return "\n".join(lines + ["The results store is empty.", ""])
    versions = ", ".join(sorted(set(df.package_version)))
    shas = ", ".join(sorted({s[:10] for s in df.git_sha}))
    lines += [f"brdfbench {versions}; git {shas}. Timings are from the machine that ran each cell.", ""]
    for (name, fingerprint), group in df.groupby(["dataset", "dataset_fingerprint"], sort=True):
        lines += dataset_section(name, fingerprint, group)
    return "\n".join(lines)
