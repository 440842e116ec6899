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


def convergence_figures(df: pd.DataFrame) -> dict:
    """{file name: matplotlib Figure}: per (dataset, base scene), mean RMSE of HDR radiance
    against spp (left) and against mean render time (right), log-log, one curve per
    (representation, sampler), with a −½ slope guide."""
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
        fig = Figure(figsize=(10, 4.2), layout="constrained")
        FigureCanvasAgg(fig)
        by_spp, by_time = fig.subplots(1, 2)
        for name, c in curves.items():
            line, = by_spp.loglog(c["spp"], c["rmse"], marker="o", ms=3, label=name)
            if c["time"] is not None:
                by_time.loglog(c["time"], c["rmse"], marker="o", ms=3, color=line.get_color(), label=name)
        _guide(by_spp, curves)
        by_spp.set(xlabel="samples per pixel", ylabel="RMSE of HDR radiance (mean over materials)",
                   title=f"{dataset}: {base}, error vs spp")
        by_time.set(xlabel="render time (s, mean over materials)", title="error vs render time")
        for ax in (by_spp, by_time):
            ax.grid(True, which="both", alpha=0.3)
            ax.xaxis.set_minor_formatter(NullFormatter())  # decades only: minor labels overlap on a log axis
        by_spp.legend(fontsize="small")
        out[convergence_plot_name(dataset, fingerprint, base)] = fig
    return out


def _curves(group: pd.DataFrame) -> dict[str, dict]:
    """{"representation / sampler": {spp, rmse, time}} of one base scene's convergence rows."""
    curves = {}
    for sampler, rows in group.groupby("sampler", sort=True):
        rungs = tables.convergence_rungs(tables.with_labels(rows))
        for rep, r in rungs.groupby("representation", sort=True):
            err = r[r.base == "rmse_hdr"].set_index("spp")["mean"]
            if err.empty:
                continue
            time = r[r.base == "render_time"].set_index("spp")["mean"].reindex(err.index)
            curves[f"{rep} / {sampler}"] = {"spp": err.index.to_numpy(), "rmse": err.to_numpy(),
                                            "time": None if time.isna().any() else time.to_numpy()}
    return curves


def _guide(ax, curves: dict[str, dict]) -> None:
    """A dashed spp^(−½) line through the first curve's first rung: the unbiased-estimator rate."""
    first = next(iter(curves.values()))
    spp = first["spp"]
    ax.loglog(spp, first["rmse"][0] * (spp / spp[0]) ** -0.5, "k--", lw=0.8, label="∝ spp^−½")
