"""Accuracy against cost: per table section, the ranking metric against each cost axis.

One panel per cost the section has (fit time, evaluations per second, render samples per
second, bytes per material), log-log, every configuration a point with its bootstrap
interval, the Pareto front (configurations no other beats on both axes) drawn through
them, and a size curve joining a plugin's configurations where a sweep varied its size.
Each configuration's artists carry an SVG id `<plot>-s<k>-…` so the page can toggle it.
Pure matplotlib on the Agg canvas, like `plots`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .view import Metric, Row, TableSection

#: Cost axes, in panel order.
AXES = ("fit_time", "evals_per_s", "render_samples_per_s", "model_bytes")


@dataclass(frozen=True)
class Point:
    row: Row
    x: float
    y: float
    lo: float | None
    hi: float | None


@dataclass(frozen=True)
class Panel:
    cost: Metric
    points: list[Point]
    front: list[Point]
    omitted: list[str]  # labels of configurations without a complete, positive figure on both axes


@dataclass(frozen=True)
class Chart:
    """The panels of one section, with the series (configurations) in legend order."""

    panels: list[Panel]
    series: list[Row]
    primary: Metric


def pareto_front(points: list[Point], x_higher_is_better: bool, y_higher_is_better: bool) -> list[Point]:
    """The points no other point beats on both axes (ties kept once), ordered from the best x."""
    ordered = sorted(points, key=lambda p: (-p.x if x_higher_is_better else p.x, -p.y if y_higher_is_better else p.y))
    front: list[Point] = []
    for p in ordered:
        if not front:
            front.append(p)
            continue
        best = front[-1].y
        if (p.y > best) if y_higher_is_better else (p.y < best):
            front.append(p)
    return front


def chart(section: TableSection) -> Chart | None:
    """The section's accuracy-against-cost panels, or None where there is nothing to plot."""
    primary = section.primary
    if primary is None:
        return None
    metrics = section.metrics
    panels = []
    for name in AXES:
        if name not in metrics:
            continue
        cost = metrics[name]
        points, omitted = [], []
        for row in section.rows:
            y, x = row.cell(primary.name), row.cell(name)
            if y is None or x is None or not (y.complete and x.complete) or y.value <= 0 or x.value <= 0:
                omitted.append(row.label)
                continue
            points.append(Point(row, x.value, y.value, y.lo, y.hi))
        if points:
            panels.append(Panel(cost, points, pareto_front(points, cost.higher_is_better, primary.higher_is_better),
                                omitted))
    if not panels:
        return None
    return Chart(panels, list(section.rows), primary)  # series k is the section's row k (one colour per row)


def figure(c: Chart, plot_id: str):
    """A matplotlib Figure of the chart; artists of series k have SVG ids `{plot_id}-s{k}-…`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, NullLocator

    n = len(c.panels)
    fig = Figure(figsize=(4.2 * n, 3.9), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, n, squeeze=False)[0]
    colours = [f"C{i % 10}" for i in range(len(c.series))]
    index = {id(r): k for k, r in enumerate(c.series)}
    for ax, panel in zip(axes, c.panels):
        front = panel.front
        xs, ys = _staircase(front)
        ax.plot(xs, ys, color="0.35", lw=1.0, ls="--", zorder=1,
                label="Pareto front")[0].set_gid(f"{plot_id}-front-{panel.cost.name}")
        if panel.cost.name == "model_bytes":
            _size_curves(ax, panel, index, colours, plot_id)
        for p in panel.points:
            k = index[id(p.row)]
            gid = f"{plot_id}-s{k}-{panel.cost.name}"
            yerr = None
            if p.lo is not None and p.hi is not None:
                yerr = [[max(p.y - p.lo, 0.0)], [max(p.hi - p.y, 0.0)]]
            container = ax.errorbar([p.x], [p.y], yerr=yerr, fmt="o", ms=5, color=colours[k], capsize=2, zorder=3,
                                    mec="white" if p in front else colours[k], mew=0.8)
            for i, artist in enumerate(container.get_children()):
                artist.set_gid(f"{gid}-{i}")
            ax.annotate(p.row.label, (p.x, p.y), xytext=(4, 3), textcoords="offset points", fontsize=7,
                        color=colours[k]).set_gid(f"{gid}-label")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _decade_at_least(ax, [p.x for p in panel.points], "x")
        _decade_at_least(ax, [v for p in panel.points for v in (p.y, p.lo, p.hi) if v is not None and v > 0], "y")
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_formatter(FuncFormatter(decade_label))
            axis.set_minor_locator(NullLocator())  # decades only: minor ticks cost a text layout each
        ax.grid(True, which="major", alpha=0.3)
        ax.set_xlabel(f"{panel.cost.label} ({'higher' if panel.cost.higher_is_better else 'lower'} is better)")
        ax.set_ylabel(f"mean {c.primary.name} ({'higher' if c.primary.higher_is_better else 'lower'} is better)")
        ax.set_title(f"{c.primary.name} against {panel.cost.label}", fontsize=9)
    return fig


def decade_label(value: float, _pos=None) -> str:
    """A log axis's tick as plain text ("1e-4"): mathtext labels cost a parser run each."""
    if value <= 0:
        return ""
    exponent = math.log10(value)
    if abs(exponent - round(exponent)) > 1e-9:
        return ""
    return f"1e{int(round(exponent))}"


def _staircase(front: list[Point]) -> tuple[list[float], list[float]]:
    """The front as a staircase: from each point along the cost axis to the next one's
    cost, then to its accuracy (what the front attains between two configurations)."""
    xs, ys = [front[0].x], [front[0].y]
    for p in front[1:]:
        xs += [p.x, p.x]
        ys += [ys[-1], p.y]
    return xs, ys


def _decade_at_least(ax, values: list[float], which: str) -> None:
    """Widen a log axis to a decade around its data (a narrower one shows no labelled tick)."""
    lo, hi = min(values), max(values)
    if hi / lo >= 10:
        return
    mid = (lo * hi) ** 0.5
    lo, hi = min(lo, mid / 10**0.5) / 1.3, max(hi, mid * 10**0.5) * 1.3
    (ax.set_xlim if which == "x" else ax.set_ylim)(lo, hi)


def _size_curves(ax, panel: Panel, index: dict, colours: list[str], plot_id: str) -> None:
    """Join the configurations of one plugin (a size sweep) in order of size."""
    by_plugin: dict[str, list[Point]] = {}
    for p in panel.points:
        by_plugin.setdefault(p.row.plugin or p.row.label, []).append(p)
    for plugin, pts in by_plugin.items():
        if len(pts) < 2:
            continue
        pts = sorted(pts, key=lambda p: p.x)
        k = index[id(pts[0].row)]
        ax.plot([p.x for p in pts], [p.y for p in pts], color=colours[k], lw=0.8, alpha=0.6,
                zorder=2)[0].set_gid(f"{plot_id}-size-{plugin}")
