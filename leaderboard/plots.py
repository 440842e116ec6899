"""Figures beside the leaderboard: convergence of Monte Carlo error with spp and with time.

Pure matplotlib on the Agg canvas (no pyplot, no global backend switch), so building a
figure works headless and leaves the caller's matplotlib state alone.
"""

from __future__ import annotations

import hashlib
import re

import pandas as pd

from . import tables


def convergence_plot_name(dataset: str, fingerprint: str, scene: str) -> str:
    """File name of the convergence figure of one (dataset, base scene)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{dataset}-{scene}")
    return f"convergence-{safe}-{hashlib.sha256(fingerprint.encode()).hexdigest()[:8]}.png"


#: The error panels against spp (Sztrajman et al.'s convergence figures: MAE, RMSE, MAPE,
#: PSNR), each (metric, axis label, log y): PSNR is already logarithmic.
PANELS = (
    ("rmse_hdr", "RMSE of HDR radiance", True),
    ("mae_hdr", "MAE of HDR radiance", True),
    ("mape_hdr", "MAPE of HDR radiance (%)", True),
    ("psnr_hdr", "PSNR of HDR radiance (dB)", False),
)


def convergence_figures(df: pd.DataFrame) -> dict:
    """{file name: matplotlib Figure}: per (dataset, base scene), the mean over materials of
    each error in PANELS against spp (log-log, RMSE with a −½ slope guide) and of RMSE
    against mean render time, one curve per (representation, sampler). A panel whose metric
    no row has (results stored before it was measured) says so."""
    df = tables.normalise(df)
    conv = df[df["harness"] == "convergence"]
    if conv.empty:
        return {}
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    out = {}
    for (dataset, fingerprint, base), group in conv.groupby(["dataset", "dataset_fingerprint", "scene"]):
        curves = _curves(group)
        if not curves:
            continue
        fig = Figure(figsize=(12, 7.6), layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(2, 3).ravel()
        lines = {}
        for ax, (metric, label, log_y) in zip(axes, PANELS):
            for name, c in curves.items():
                y = c["errors"].get(metric)
                if y is None:
                    continue
                plot = ax.loglog if log_y else ax.semilogx
                line, = plot(c["spp"], y, marker="o", ms=3, label=name, color=lines[name].get_color()
                             if name in lines else None)
                lines.setdefault(name, line)
            if metric == "rmse_hdr":
                _guide(ax, curves)
            if not ax.lines:
                ax.text(0.5, 0.5, f"no {metric} rows (stored before it was measured)", ha="center",
                        va="center", transform=ax.transAxes, fontsize="small")
            ax.set(xlabel="samples per pixel", ylabel=f"{label}, mean over materials")
        axes[0].set_title(f"{dataset}: {base}, error vs spp", loc="left")
        by_time = axes[len(PANELS)]
        for name, c in curves.items():
            if c["time"] is not None:
                by_time.loglog(c["time"], c["errors"]["rmse_hdr"], marker="o", ms=3, color=lines[name].get_color())
        by_time.set(xlabel="render time (s, mean over materials)", ylabel="RMSE of HDR radiance",
                    title="error vs render time")
        for ax in axes[: len(PANELS) + 1]:
            ax.grid(True, which="both", alpha=0.3)
            ax.xaxis.set_minor_formatter(NullFormatter())  # decades only: minor labels overlap on a log axis
        legend = axes[-1]
        legend.axis("off")
        legend.legend(handles=[*lines.values(), *[h for h in axes[0].lines if h.get_label().startswith("∝")]],
                      loc="center", fontsize="small", title="representation / sampler")
        out[convergence_plot_name(dataset, fingerprint, base)] = fig
    return out


def _curves(group: pd.DataFrame) -> dict[str, dict]:
    """{"representation / sampler": {spp, errors: {metric: means}, time}} of one base
    scene's convergence rows (curves without RMSE rungs are left out)."""
    curves = {}
    for sampler, rows in group.groupby("sampler", sort=True):
        rungs = tables.convergence_rungs(tables.with_labels(rows))
        for rep, r in rungs.groupby("representation", sort=True):
            err = r[r.base == "rmse_hdr"].set_index("spp")["mean"]
            if err.empty:
                continue
            errors = {}
            for metric, _, _ in PANELS:
                values = r[r.base == metric].set_index("spp")["mean"].reindex(err.index)
                if not values.isna().any():
                    errors[metric] = values.to_numpy()
            time = r[r.base == "render_time"].set_index("spp")["mean"].reindex(err.index)
            curves[f"{rep} / {sampler}"] = {"spp": err.index.to_numpy(), "errors": errors,
                                            "time": None if time.isna().any() else time.to_numpy()}
    return curves


def _guide(ax, curves: dict[str, dict]) -> None:
    """A dashed spp^(−½) line through the first curve's first rung: the unbiased-estimator rate."""
    first = next(iter(curves.values()))
    spp = first["spp"]
    ax.loglog(spp, first["errors"]["rmse_hdr"][0] * (spp / spp[0]) ** -0.5, "k--", lw=0.8, label="∝ spp^−½")
