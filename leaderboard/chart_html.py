"""The accuracy-against-cost section of a table section as HTML: legend, panels and notes.

The panels' data goes into the page as JSON (`<script type="application/json">`), and
`assets/chart.js` draws them from it, again whenever a legend box is toggled (the axes fit
the series shown, the front is recomputed among them) or the page's width changes. The SVG
of `pareto.figure` stands in where scripts do not run.
"""

from __future__ import annotations

import json

from . import pareto, svg_plot, units, view
from .html_parts import esc
from .view import TableSection


def legend(plot_id: str, c: pareto.Chart) -> str:
    """One box per series (`data-series` = its elements' id prefix, as `report.js` toggles);
    the references last, unticked."""
    items = []
    order = [k for k in range(len(c.series)) if k not in c.hidden] + sorted(c.hidden)
    for k in order:
        row = c.series[k]
        ref = k in c.hidden
        tag = ' <span class="ci">reference, the target itself</span>' if ref else ""
        attrs = ' class="reference" title="the target itself: off the axes unless ticked"' if ref else ""
        items.append(f'<label{attrs}><input type="checkbox"'
                     f'{"" if ref else " checked"} data-series="{plot_id}-s{k}-">'
                     f'<span class="swatch" style="background:{svg_plot.colour(k)}"></span>{esc(row.label)}{tag}</label>')
    return f'<div class="legend" data-chart="{plot_id}">{"".join(items)}</div>'


def payload(c: pareto.Chart, plot_id: str) -> dict:
    """What `chart.js` draws a chart from: per panel its points (series, x, y, interval, GPU
    flag, tooltip), candidate log ticks with their labels, titles and size curves."""
    primary = c.primary
    panels = []
    for panel in c.panels:
        cost = panel.cost
        pts = [dict(s=p.k, x=p.x, y=p.y, lo=p.lo, hi=p.hi, gpu=p.gpu, ref=p.k in c.hidden,
                    label=p.row.label + (" ‡" if p.gpu else ""), tip=pareto.tooltip(p, cost, primary))
               for p in panel.points]
        xs = [p.x for p in panel.points]
        ys = [v for p in panel.points for v in (p.y, p.lo, p.hi) if v is not None]
        curves = []
        if cost.name == pareto.BYTES:
            place = {id(p): i for i, p in enumerate(panel.points)}
            curves = [dict(name=plugin, points=[place[id(p)] for p in pts])
                      for plugin, pts in pareto.size_curves(panel).items()]
        panels.append(dict(
            cost=cost.name, xUp=cost.higher_is_better, title=f"{primary.name} against {cost.label}",
            xTitle=pareto.x_title(panel), points=pts, curves=curves,
            # the widest the axes can get (every series shown, padded); the script keeps the ticks inside its limits
            xTicks=svg_plot.log_ticks(*_wide(svg_plot.log_range(xs)), pareto.x_tick(cost)),
            yTicks=svg_plot.log_ticks(*_wide(svg_plot.log_range(ys)), svg_plot.plain) if c.y_log else []))
    return dict(id=plot_id, yLog=c.y_log, yUp=primary.higher_is_better, yTitle=pareto.y_title(primary),
                colours=[svg_plot.colour(k) for k in range(len(c.series))], panels=panels)


def _wide(limits: tuple[float, float]) -> tuple[float, float]:
    """A decade beyond each end, for the padding a subset of the points may need."""
    return limits[0] / 10, limits[1] * 10


def data_script(c: pareto.Chart, plot_id: str) -> str:
    """The payload as a JSON script element; `<` is escaped so no label can end the element."""
    text = json.dumps(payload(c, plot_id), ensure_ascii=False, allow_nan=False, separators=(",", ":"))
    text = text.replace("<", "\\u003c")
    return f'<script type="application/json" id="{plot_id}-data" data-cost-chart>{text}</script>'


def _shared_note(c: pareto.Chart) -> str:
    bytes_panel = next((p for p in c.panels if p.cost.name == pareto.BYTES), None)
    sharing = [p for p in bytes_panel.points if p.shared] if bytes_panel else []
    if not sharing:
        return ""
    each = "; ".join(f"<code>{esc(p.row.label)}</code> {esc(units.human(p.x - p.shared, 'B'))} + "
                     f"{esc(units.human(p.shared * c.materials, 'B'))} / {c.materials} = {esc(units.human(p.x, 'B'))}"
                     for p in sharing)
    return (f'<p class="note">Bytes per material: a configuration\'s own bytes per material plus what it stores once '
            f"for all (<code>shared_bytes</code>, e.g. a PCA basis) divided by N = {c.materials}, the materials of "
            f"this section: {each}.</p>")


def chart(s: TableSection, sid: str) -> list[str]:
    c = pareto.chart(s)
    if c is None:
        return []
    plot_id = f"{sid}-pareto"
    omitted = sorted({label for p in c.panels for label in p.omitted})
    refs = [c.series[k].label for k in sorted(c.hidden)]
    ref_note = (f" The reference ({esc(', '.join(refs))}: the target itself) is off the axes until its box is "
                "ticked." if refs else "")
    y_axis = "log" if c.y_log else "linear"
    return ["<h3>Accuracy against cost</h3>",
            f'<p class="note">Mean <code>{esc(c.primary.name)}</code> against each cost: cost axes logarithmic, the '
            f"accuracy axis {y_axis}; error bars are the {view.CONFIDENCE:.0%} intervals; the dashed line is the "
            "Pareto front of the series shown (no shown configuration beats a point on it on both axes; GPU timings "
            "‡ are left off a front of CPU ones); a thin line joins one plugin's configurations in order of size. "
            f"Untick a series to hide it: the axes and the front follow.{ref_note} A label that would collide with "
            "another is left out: hover a point for its name and figures.</p>",
            legend(plot_id, c),
            f'<div class="plot cost-plots" id="{plot_id}">{pareto.figure(c, plot_id)}</div>',
            data_script(c, plot_id),
            *([_shared_note(c)] if _shared_note(c) else []),
            *([f'<p class="note">Not plotted (a figure missing, or not positive on a log axis): '
               f'{esc(", ".join(omitted))}.</p>'] if omitted else [])]
