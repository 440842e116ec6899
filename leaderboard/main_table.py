"""A table section's main table as HTML: compact by default, every column one click away.

The compact view holds what a reader compares first (rank, configuration, the ranking
metric with its interval, fit time, evaluations per second, bytes per material and how
many materials have a figure); the other metrics and costs are in the same table, shown
by a checkbox that needs no script (CSS `:checked`). The rank and configuration columns
stay in view when the table scrolls sideways. The target itself (`Row.reference`) sits in
its own row group above the ranking, which sorting never moves.
"""

from __future__ import annotations

from . import units, view
from .html_parts import cell, esc
from .view import Metric, Row, TableSection

#: Costs the compact view shows beside the ranking metric (where the section has them).
COMPACT_COSTS = ("fit_time", "evals_per_s", "render_time", "render_samples_per_s", "model_bytes")


def direction(metric: Metric) -> str:
    return "" if not metric.directed else ("higher is better" if metric.higher_is_better else "lower is better")


def header(metric: Metric, extra: bool) -> str:
    title = f"{metric.name}: {metric.unit or 'unitless'}"
    if metric.directed:
        title += f", {direction(metric)}"
    if metric.kind == "accuracy":
        title += (f"; mean over materials, {view.CONFIDENCE:.0%} bootstrap interval below "
                  f"(with {view.MIN_INTERVAL_N} or more materials)")
    else:
        title += f"; {metric.aggregate} over materials"
    unit = "" if units.scales(metric.unit) else (metric.unit or "unitless")
    sub = " · ".join(x for x in (unit, direction(metric)) if x)
    cls = ' class="extra"' if extra else ""
    return (f'<th{cls} title="{esc(title)}" data-metric="{esc(metric.name)}">{esc(metric.short_label)}'
            f'<span class="ci">{esc(sub)}</span></th>')


def _shared_note(row: Row, s: TableSection) -> str:
    """Under a bytes-per-material figure: the part shared by all materials, where there is one."""
    shared = row.cell("shared_bytes")
    if shared is None or not shared.complete or not shared.value:
        return ""
    return f"+ {units.human(shared.value, 'B')} shared"


def columns(s: TableSection) -> tuple[list[Metric], set[str]]:
    """Every column in order, and the names of those the compact view hides."""
    metrics = [*s.accuracy, *s.costs]
    shown = {s.primary.name, *COMPACT_COSTS} if s.primary is not None else set(COMPACT_COSTS)
    return metrics, {m.name for m in metrics if m.name not in shown}


def table(s: TableSection, sid: str, best: dict[str, str | None]) -> list[str]:
    metrics, hidden = columns(s)
    compact = [m for m in metrics if m.name not in hidden]
    head = ['<th class="rank" title="rank by the ranking metric; ref.: the target itself, not ranked">rank</th>',
            '<th class="label name">representation</th>',
            *[header(m, m.name in hidden) for m in metrics],
            f'<th title="materials with a {esc(s.primary.name)} figure">materials</th>']
    groups: dict[bool, list[str]] = {True: [], False: []}
    for row in s.rows:
        primary = row.cell(s.primary.name)
        rank = "ref." if row.reference else (row.rank if row.rank is not None else "–")
        name = f"<code>{esc(row.label)}</code>"
        if row.reference:
            name += '<span class="ci">reference: the target itself</span>'
        cells = [f'<td class="rank" data-sort="{row.rank if row.rank is not None else ""}">{rank}</td>',
                 f'<td class="label name">{name}</td>']
        for m in metrics:
            note = _shared_note(row, s) if m.name == "model_bytes" else ""
            cells.append(cell(row.cell(m.name), m, best.get(m.name) == row.config_hash, m.name in hidden, note))
        cells.append(f"<td>{primary.n if primary else 0}/{len(s.materials)}</td>")
        groups[row.reference].append(f"<tr>{''.join(cells)}</tr>")
    bodies = ""
    if groups[True]:
        bodies += f'<tbody class="reference">{"".join(groups[True])}</tbody>'
    if not groups[False]:
        groups[False].append(f'<tr><td class="label" colspan="{len(metrics) + 3}">No configuration to rank beside '
                             "the reference yet.</td></tr>")
    bodies += f'<tbody class="ranked">{"".join(groups[False])}</tbody>'
    toggle = (f'<input type="checkbox" class="columns-toggle" id="{sid}-all-columns">'
              f'<label class="columns-toggle" for="{sid}-all-columns">show all {len(metrics) + 3} columns '
              f"({len(hidden)} more: {esc(', '.join(m.short_label for m in metrics if m.name in hidden))})</label>"
              if hidden else "")
    return [f'<div class="main-table">{toggle}<div class="scroll"><table class="sortable main" id="{sid}-table" '
            f'data-compact="{len(compact) + 3}"><thead><tr>{"".join(head)}</tr></thead>{bodies}</table></div></div>']
