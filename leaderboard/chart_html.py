"""The accuracy-against-cost section of a table section as HTML: legend and plot."""

from __future__ import annotations

from . import pareto, svg_plot, view
from .html_parts import esc
from .view import TableSection


def legend(plot_id: str, series) -> str:
    items = []
    for k, row in enumerate(series):
        items.append(f'<label><input type="checkbox" checked data-series="{plot_id}-s{k}-">'
                     f'<span class="swatch" style="background:{svg_plot.colour(k)}"></span>{esc(row.label)}</label>')
    return f'<div class="legend">{"".join(items)}</div>'


def chart(s: TableSection, sid: str) -> list[str]:
    c = pareto.chart(s)
    if c is None:
        return []
    plot_id = f"{sid}-pareto"
    omitted = sorted({label for p in c.panels for label in p.omitted})
    return ["<h3>Accuracy against cost</h3>",
            f'<p class="note">Mean <code>{esc(c.primary.name)}</code> against each cost, log axes; error bars are the '
            f"{view.CONFIDENCE:.0%} intervals; the dashed line is the Pareto front (no configuration beats a point on "
            "it on both axes); a thin line joins one plugin's configurations in order of size. Untick a series to "
            "hide it.</p>",
            legend(plot_id, c.series),
            f'<div class="plot" id="{plot_id}">{pareto.figure(c, plot_id)}</div>',
            *([f'<p class="note">Not plotted (a figure missing or not positive): '
               f'{esc(", ".join(omitted))}.</p>'] if omitted else [])]
