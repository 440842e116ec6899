"""Accuracy against cost: per table section, the ranking metric against each cost axis.

One panel per cost the section has (fit time, evaluations per second, render samples per
second, bytes per material), log-log, every configuration a point with its bootstrap
interval, the Pareto front (configurations no other beats on both axes) drawn through
them, and a size curve joining a plugin's configurations where a sweep varied its size.
Each configuration's artists carry an SVG id `<plot>-s<k>-…` so the page can toggle it.
Drawn as SVG markup (`svg_plot`).
"""

from __future__ import annotations

from dataclasses import dataclass

from . import svg_plot
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
    gpu: bool = False  # its cost is a timing computed on a GPU (never on the same front as CPU timings)


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
            points.append(Point(row, x.value, y.value, y.lo, y.hi, bool(cost.timed and x.accelerator)))
        if points:
            # a front compares like with like: where CPU and GPU timings mix, it runs through the CPU ones
            peers = [p for p in points if not p.gpu] or points
            panels.append(Panel(cost, points, pareto_front(peers, cost.higher_is_better, primary.higher_is_better),
                                omitted))
    if not panels:
        return None
    return Chart(panels, list(section.rows), primary)  # series k is the section's row k (one colour per row)


PANEL_W, PANEL_H = 340.0, 300.0
MARGIN = dict(left=64.0, right=16.0, top=26.0, bottom=44.0)


def figure(c: Chart, plot_id: str) -> str:
    """The chart as inline SVG markup, one log-log panel per cost; the elements of series k
    have ids `{plot_id}-s{k}-<cost>` (its point, interval and label), the front
    `{plot_id}-front-<cost>` and a size curve `{plot_id}-size-<plugin>`."""
    width = PANEL_W * len(c.panels)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width:.0f} {PANEL_H:.0f}" width="{width:.0f}" '
           f'height="{PANEL_H:.0f}" font-family="sans-serif" role="img">']
    index = {id(r): k for k, r in enumerate(c.series)}
    for j, panel in enumerate(c.panels):
        ys = [v for p in panel.points for v in (p.y, p.lo, p.hi) if v is not None and v > 0]
        ax = svg_plot.LogAxes(svg_plot.log_range([p.x for p in panel.points]), svg_plot.log_range(ys),
                              PANEL_W * j + MARGIN["left"], MARGIN["top"],
                              PANEL_W - MARGIN["left"] - MARGIN["right"], PANEL_H - MARGIN["top"] - MARGIN["bottom"])
        cost, primary = panel.cost, c.primary
        out.append(ax.frame(f"{cost.label} ({'higher' if cost.higher_is_better else 'lower'} is better)",
                            f"mean {primary.name} ({'higher' if primary.higher_is_better else 'lower'} is better)",
                            f"{primary.name} against {cost.label}"))
        xs, ys = _staircase(panel.front)
        out.append(f'<path id="{plot_id}-front-{cost.name}" d="{ax.path(xs, ys)}" fill="none" stroke="#595959" '
                   'stroke-width="1" stroke-dasharray="4,3"/>')
        if cost.name == "model_bytes":
            for plugin, pts in size_curves(panel).items():
                colour = svg_plot.colour(index[id(pts[0].row)])
                d = ax.path([p.x for p in pts], [p.y for p in pts])
                out.append(f'<path id="{plot_id}-size-{svg_plot.escape(plugin)}" d="{d}" fill="none" stroke="{colour}" '
                           'stroke-width="0.8" opacity="0.6"/>')
        for p in panel.points:
            k = index[id(p.row)]
            colour = svg_plot.colour(k)
            x, y = ax.px(p.x), ax.py(p.y)
            parts = [f'<g id="{plot_id}-s{k}-{cost.name}">']
            if p.lo is not None and p.hi is not None and p.lo > 0 and p.hi > 0:
                lo, hi = ax.py(p.lo), ax.py(p.hi)
                parts.append(f'<path d="M{x:.1f},{lo:.1f} L{x:.1f},{hi:.1f} M{x - 2:.1f},{lo:.1f} L{x + 2:.1f},{lo:.1f} '
                             f'M{x - 2:.1f},{hi:.1f} L{x + 2:.1f},{hi:.1f}" stroke="{colour}" stroke-width="1"/>')
            edge = "#ffffff" if p in panel.front else colour
            parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3.5" fill="{colour}" stroke="{edge}" '
                         'stroke-width="0.8"/>')
            parts.append(f'<text x="{x + 5:.1f}" y="{y - 4:.1f}" font-size="8" fill="{colour}">'
                         f"{svg_plot.escape(p.row.label + (' ‡ GPU' if p.gpu else ''))}</text></g>")
            out.append("".join(parts))
    out.append("</svg>")
    return "".join(out)


def _staircase(front: list[Point]) -> tuple[list[float], list[float]]:
    """The front as a staircase: from each point along the cost axis to the next one's
    cost, then to its accuracy (what the front attains between two configurations)."""
    xs, ys = [front[0].x], [front[0].y]
    for p in front[1:]:
        xs += [p.x, p.x]
        ys += [ys[-1], p.y]
    return xs, ys


def size_curves(panel: Panel) -> dict[str, list[Point]]:
    """The configurations of one plugin (a size sweep) in order of size, per plugin with two or more."""
    by_plugin: dict[str, list[Point]] = {}
    for p in panel.points:
        by_plugin.setdefault(p.row.plugin or p.row.label, []).append(p)
    return {plugin: sorted(pts, key=lambda p: p.x) for plugin, pts in by_plugin.items() if len(pts) >= 2}
