"""The Markdown leaderboard: accuracy side by side with what it costs."""

from __future__ import annotations

import math
import time
from collections.abc import Collection

import pandas as pd

from . import plots as plots_module
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
    "render_time": "render time (s) ↓",
    "render_samples_per_s": "render samples/s ↑",
    "peak_rss_fit": "peak memory, fit (B) ↓",
    "peak_rss_eval": "peak memory, eval (B) ↓",
    "peak_rss_train": "peak memory, train (B) ↓",
}
#: Marks a timing measured while other brdfbench jobs ran on the same host.
CONTENDED = "†"


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


def dataset_section(name: str, fingerprint: str, df: pd.DataFrame, scene: str = "brdf_space") -> list[str]:
    summary = tables.summarize(df)
    n_materials = df["material"].nunique()
    heading = f"## Dataset `{name}`" + ("" if scene == "brdf_space" else f", rendered scene `{scene}`")
    lines = [heading, "", f"{n_materials} materials, fingerprint `{fingerprint}`.", ""]
    if scene != "brdf_space":
        lines += ["> Image metrics compare each representation's render with the render of the material's own "
                  "table (nearest-cell lookup) through the same simulator and random numbers.", ""]
    caveat = tables.dataset_caveat(name)
    if caveat:
        lines += [f"> {caveat}", ""]
    primary = tables.primary_metric(summary)
    if primary is None:
        lines += ["No successful results yet.", ""]
    else:
        ranked = tables.ranking(summary, primary)
        accuracy_metrics = tables.accuracy_metrics(summary)
        costs = [c for c in tables.COST_METRICS if c in set(summary.metric)]
        lookup = {(r.representation, r.metric): r for r in summary.itertuples() if r.spp == 0}
        header = ["rank", "representation"]
        header += [f"{m} {_arrow(lookup_any(summary, m).higher_is_better)}" for m in accuracy_metrics]
        header += [COST_LABELS[c] for c in costs] + ["materials"]
        rows = []
        for rank, rep in enumerate(ranked["representation"], 1):
            cells = [str(rank), f"`{rep}`"]
            cells += [fmt(lookup[(rep, m)].mean) if (rep, m) in lookup else "–" for m in accuracy_metrics]
            cells += [_cost(lookup.get((rep, c)), c) for c in costs]
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
            *([f"{CONTENDED} measured while other brdfbench jobs ran on the same host: timings are not comparable "
               "with unmarked ones.", ""] if any(_contended(lookup.get((rep, c)), c) for rep in ranked["representation"]
                                                  for c in costs) else []),
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
    return lines + _failures(df)


def _contended(row, metric: str) -> bool:
    return row is not None and metric in tables.TIMED and bool(row.contended)


def _cost(row, metric: str) -> str:
    if row is None:
        return "–"
    return fmt(getattr(row, tables.COST_METRICS[metric])) + (CONTENDED if _contended(row, metric) else "")


def convergence_section(name: str, fingerprint: str, df: pd.DataFrame, base: str, sampler: str,
                        plots: Collection[str] = ()) -> list[str]:
    """Mean RMSE per spp rung per representation for one (dataset, scene, sampler)."""
    lines = [f"## Dataset `{name}`, convergence on `{base}`, sampler `{sampler}`", "",
             f"{df['material'].nunique()} materials, fingerprint `{fingerprint}`.", "",
             "> Monte Carlo noise only: each representation's render at n spp against its own high-spp render "
             "(same model, independent random numbers), so the error measures how well the sampler suits the "
             "representation. Columns: mean RMSE of HDR radiance over materials (↓); the slope of log RMSE on "
             "log spp (−0.5 for an unbiased estimator; flatter when rare fireflies dominate); the RMSE at 1 spp "
             "implied by the 1/√spp law over all rungs (↓); the mean render time at the top rung.", ""]
    rungs = tables.convergence_rungs(df)
    rmse = rungs[rungs.base == "rmse_hdr"]
    if rmse.empty:
        lines += ["No successful results yet.", ""]
    else:
        summary = tables.summarize(df)
        lookup = {(r.representation, r.metric, r.spp): r for r in summary.itertuples()}
        ladder = sorted(set(rmse.spp))
        top = ladder[-1]
        means = {(r.representation, r.spp): r for r in rmse.itertuples()}
        order = sorted(set(rmse.representation),
                       key=lambda rep: getattr(lookup.get((rep, "convergence_rmse_1spp", 0)), "mean", math.inf))
        header = ["representation", *[f"{n} spp" for n in ladder], "slope", "RMSE at 1 spp (fit) ↓",
                  f"render time at {top} spp (s) ↓", "materials"]
        rows = []
        for rep in order:
            cells = [f"`{rep}`", *[fmt(means[(rep, n)].mean) if (rep, n) in means else "–" for n in ladder]]
            for metric, spp in (("convergence_slope", 0), ("convergence_rmse_1spp", 0), ("render_time", top)):
                cells.append(fmt(lookup[(rep, metric, spp)].mean) if (rep, metric, spp) in lookup else "–")
            cells.append(str(max(r.n for (name, _), r in means.items() if name == rep)))
            rows.append(cells)
        lines += ["### Error against spp", "", *_table(header, rows), ""]
    plot = plots_module.convergence_plot_name(name, fingerprint, base)
    if plot in plots:
        lines += [f"![RMSE against spp and render time, every sampler on `{base}`]({plot})", ""]
    return lines + _failures(df)


def _failures(df: pd.DataFrame) -> list[str]:
    """The unresolved failures of a section, or nothing."""
    failed = tables.failures(df)
    if failed.empty:
        return []
    lines = ["### Failures", ""]
    lines += _table(["representation", "material", "error"],
                    [[f"`{f.representation}`", f.material, f.message.replace("|", "\\|")[:200]] for f in failed.itertuples()])
    return lines + [""]


def lookup_any(summary: pd.DataFrame, metric: str):
    return summary[summary.metric == metric].iloc[0]


def render(df: pd.DataFrame, source: str, plots: Collection[str] = ()) -> str:
    """The leaderboard text; `plots` names the figure files written beside it (linked from their sections)."""
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
    for (name, fingerprint, scene, harness, sampler), group in tables.sections(df):
        if harness == "convergence":
            lines += convergence_section(name, fingerprint, group, scene, sampler, plots)
        else:
            lines += dataset_section(name, fingerprint, group, scene)
    return "\n".join(lines)
