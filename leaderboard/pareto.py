"""Accuracy against cost: per table section, the ranking metric against each cost axis.

One panel per cost the section has (fit time, evaluations per second, render samples per
second, bytes per material, FLOPs per evaluation), every configuration a point with its
bootstrap interval, the Pareto front (configurations no other beats on both axes) through
them, and a size curve joining a plugin's configurations where a sweep varied its size.

Cost axes are logarithmic; the accuracy axis too, except for a metric in dB (already a
logarithm) or one with figures at or below zero, which gets a linear one. A reference (the
target itself, `view.Row.reference`) starts hidden: off the axes and off the front, so that
an error of 1e-9 does not squeeze the real models into a corner. Bytes per material carry
the configuration's shared bytes (e.g. a PCA basis) amortised over the section's materials.

The page draws these panels in its script from `chart_html`'s data (so that hiding a series
rescales the axes and recomputes the front); `figure` is the SVG a page without scripts shows.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import svg_plot, units
from .view import Metric, Row, TableSection

#: Cost axes, in panel order.
AXES = ("fit_time", "evals_per_s", "render_samples_per_s", "model_bytes", "flops_per_eval")
#: The bytes axis, and the cost whose figure it amortises into each material's.
BYTES, SHARED = "model_bytes", "shared_bytes"


@dataclass(frozen=True)
class Point:
    row: Row
    x: float
    y: float
    lo: float | None
    hi: float | None
    gpu: bool = False  # its cost is a timing computed on a GPU (never on the same front as CPU timings)
    shared: float = 0.0  # of x, the shared bytes amortised into this material's (bytes axis only)
    k: int = -1  # its series: the index of its row in the section


@dataclass(frozen=True)
class Panel:
    cost: Metric
    points: list[Point]
    front: list[Point]  # among the series shown at first (references hidden)
    omitted: list[str]  # labels of configurations without a complete figure that fits both axes


@dataclass(frozen=True)
class Chart:
    """The panels of one section, with the series (configurations) in the section's row
    order; `hidden`: the series that start hidden (the references)."""

    panels: list[Panel]
    series: list[Row]
    primary: Metric
    y_log: bool = True
    hidden: frozenset[int] = frozenset()
    materials: int = 0  # N, over which shared bytes are amortised


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


def front(points: list[Point], x_higher_is_better: bool, y_higher_is_better: bool,
          hidden: frozenset[int] | set[int] = frozenset()) -> list[Point]:
    """The front among the points of the series shown (`hidden` left out); where CPU and GPU
    timings mix, it runs through the CPU ones (like with like). The page's script computes
    the same when a series is toggled."""
    shown = [p for p in points if p.k not in hidden]
    peers = [p for p in shown if not p.gpu] or shown
    return pareto_front(peers, x_higher_is_better, y_higher_is_better)


def y_log(section: TableSection) -> bool:
    """Whether the ranking metric gets a log axis: not for dB, nor where a configuration other
    than a reference has a figure (mean or interval end) at or below zero."""
    primary = section.primary
    if primary is None or primary.unit == "dB":
        return False
    for row in section.rows:
        c = row.cell(primary.name)
        if row.reference or c is None or not c.complete:
            continue
        if any(v is not None and v <= 0 for v in (c.value, c.lo, c.hi)):
            return False
    return True


def _x(row: Row, name: str, materials: int) -> tuple[float | None, float]:
    """A row's figure on cost axis `name` and, on the bytes axis, the shared bytes amortised into it."""
    c = row.cell(name)
    if c is None or not c.complete:
        return None, 0.0
    if name != BYTES or row.cell(SHARED) is None:
        return c.value, 0.0
    shared = row.cell(SHARED)
    if not shared.complete:
        return None, 0.0
    part = shared.value / max(1, materials)
    return c.value + part, part


def chart(section: TableSection) -> Chart | None:
    """The section's accuracy-against-cost panels, or None where there is nothing to plot."""
    primary = section.primary
    if primary is None:
        return None
    log = y_log(section)
    n = len(section.materials)
    others = any(not r.reference and r.cell(primary.name) is not None and r.cell(primary.name).complete
                 for r in section.rows)
    # the references start hidden, unless there is nothing else to plot
    hidden = frozenset(k for k, r in enumerate(section.rows) if r.reference) if others else frozenset()
    metrics = section.metrics
    panels = []
    for name in AXES:
        if name not in metrics:
            continue
        cost = metrics[name]
        points, omitted = [], []
        for k, row in enumerate(section.rows):
            y = row.cell(primary.name)
            x, shared = _x(row, name, n)
            if y is None or not y.complete or x is None or x <= 0 or (log and y.value <= 0):
                omitted.append(row.label)
                continue
            lo, hi = y.lo, y.hi
            if log and (lo is None or hi is None or lo <= 0 or hi <= 0):
                lo = hi = None
            gpu = bool(cost.timed and row.cell(name).accelerator)
            points.append(Point(row, x, y.value, lo, hi, gpu, shared, k))
        if points:
            panels.append(Panel(cost, points, front(points, cost.higher_is_better, primary.higher_is_better, hidden),
                                omitted))
    if not panels:
        return None
    return Chart(panels, list(section.rows), primary, log, hidden, n)  # series k is the section's row k


def size_curves(panel: Panel) -> dict[str, list[Point]]:
    """The configurations of one plugin (a size sweep) in order of size, per plugin with two or more."""
    by_plugin: dict[str, list[Point]] = {}
    for p in panel.points:
        by_plugin.setdefault(p.row.plugin or p.row.label, []).append(p)
    return {plugin: sorted(pts, key=lambda p: p.x) for plugin, pts in by_plugin.items() if len(pts) >= 2}


def direction(metric: Metric) -> str:
    return "higher is better" if metric.higher_is_better else "lower is better"


def x_title(panel: Panel) -> str:
    """The cost axis's title (its tick labels carry the unit)."""
    cost = panel.cost
    words = {"fit_time": "fit time per material", "evals_per_s": "BRDF evaluations per second",
             "render_samples_per_s": "render samples per second", BYTES: "bytes per material",
             "flops_per_eval": "FLOPs per evaluation"}
    shared = " (shared bytes amortised)" if any(p.shared for p in panel.points) else ""
    return f"{words.get(cost.name, cost.label)}{shared}, {direction(cost)}"


def y_title(primary: Metric) -> str:
    unit = f" ({primary.unit})" if primary.unit else ""
    return f"mean {primary.name}{unit}, {direction(primary)}"


def x_tick(cost: Metric):
    """How the cost axis prints a tick: in readable units ("12.3 ms", "1.27 kB")."""
    return lambda v: units.human(v, cost.unit)


# --------------------------------------------------------------------------- the page without scripts

PANEL_W, PANEL_H, COLUMNS, FONT = 560.0, 350.0, 2, 12.0
MARGIN = dict(left=76.0, right=16.0, top=28.0, bottom=50.0)


def figure(c: Chart, plot_id: str) -> str:
    """The chart as one inline SVG, its panels in a grid of two columns, as it first shows
    (hidden series off the axes): what a page without scripts draws. Series k's elements have
    ids `{plot_id}-s{k}-<cost>`, the front `{plot_id}-front-<cost>`, a size curve
    `{plot_id}-size-<plugin>`; a point names itself in its tooltip."""
    columns = min(COLUMNS, len(c.panels))
    rows = -(-len(c.panels) // columns)
    width, height = PANEL_W * columns, PANEL_H * rows
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width:.0f} {height:.0f}" width="100%" '
           'font-family="sans-serif" role="img">']
    for j, panel in enumerate(c.panels):
        out.append(_panel(c, panel, plot_id, PANEL_W * (j % columns), PANEL_H * (j // columns)))
    out.append("</svg>")
    return "".join(out)


def _panel(c: Chart, panel: Panel, plot_id: str, left: float, top: float) -> str:
    shown = [p for p in panel.points if p.k not in c.hidden] or panel.points
    ys = [v for p in shown for v in (p.y, p.lo, p.hi) if v is not None]
    x_range = svg_plot.log_range([p.x for p in shown])
    y_range = svg_plot.log_range(ys) if c.y_log else svg_plot.linear_range(ys)
    ax = svg_plot.Axes(x_range, y_range, left + MARGIN["left"], top + MARGIN["top"],
                       PANEL_W - MARGIN["left"] - MARGIN["right"], PANEL_H - MARGIN["top"] - MARGIN["bottom"],
                       True, c.y_log)
    cost, primary = panel.cost, c.primary
    x_ticks = svg_plot.pick_log_ticks(svg_plot.log_ticks(*x_range, x_tick(cost)), 5)
    y_ticks = (svg_plot.pick_log_ticks(svg_plot.log_ticks(*y_range, svg_plot.plain), 6) if c.y_log
               else svg_plot.linear_ticks(*y_range, 6))
    out = [ax.frame(x_ticks, y_ticks, x_title(panel), y_title(primary), f"{primary.name} against {cost.label}", FONT)]
    if panel.front:
        xs, ys = _staircase(panel.front)
        out.append(f'<path id="{plot_id}-front-{cost.name}" d="{ax.path(xs, ys)}" fill="none" stroke="#595959" '
                   'stroke-width="1.2" stroke-dasharray="5,3"/>')
    if cost.name == BYTES:
        for plugin, pts in size_curves(Panel(cost, shown, [], [])).items():
            d = ax.path([p.x for p in pts], [p.y for p in pts])
            out.append(f'<path id="{plot_id}-size-{svg_plot.escape(plugin)}" d="{d}" fill="none" '
                       f'stroke="{svg_plot.colour(pts[0].k)}" stroke-width="1" opacity="0.6"/>')
    for p in shown:
        colour = svg_plot.colour(p.k)
        x, y = ax.px(p.x), ax.py(p.y)
        parts = [f'<g id="{plot_id}-s{p.k}-{cost.name}"><title>{svg_plot.escape(tooltip(p, cost, primary))}</title>']
        if p.lo is not None and p.hi is not None:
            lo, hi = ax.py(p.lo), ax.py(p.hi)
            parts.append(f'<path d="M{x:.1f},{lo:.1f} L{x:.1f},{hi:.1f} M{x - 3:.1f},{lo:.1f} L{x + 3:.1f},{lo:.1f} '
                         f'M{x - 3:.1f},{hi:.1f} L{x + 3:.1f},{hi:.1f}" stroke="{colour}" stroke-width="1.2"/>')
        edge = "#ffffff" if p in panel.front else colour
        parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4.5" fill="{colour}" stroke="{edge}" stroke-width="1"/></g>')
        out.append("".join(parts))
    return "".join(out)


def tooltip(p: Point, cost: Metric, primary: Metric) -> str:
    """What hovering a point says: its configuration, cost (how bytes were amortised) and accuracy."""
    where = f"{units.human(p.x, cost.unit)}"
    if p.shared:
        where += f" ({units.human(p.x - p.shared, cost.unit)} own + {units.human(p.shared, cost.unit)} shared)"
    interval = f" [{svg_plot.plain(p.lo)}, {svg_plot.plain(p.hi)}]" if p.lo is not None and p.hi is not None else ""
    gpu = ", timed on a GPU" if p.gpu else ""
    return f"{p.row.label}: {cost.label} {where}{gpu}; {primary.name} {svg_plot.plain(p.y)}{interval}"


def _staircase(front: list[Point]) -> tuple[list[float], list[float]]:
    """The front as a staircase: from each point along the cost axis to the next one's
    cost, then to its accuracy (what the front attains between two configurations)."""
    xs, ys = [front[0].x], [front[0].y]
    for p in front[1:]:
        xs += [p.x, p.x]
        ys += [ys[-1], p.y]
    return xs, ys
