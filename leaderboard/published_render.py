"""The source papers' figures beside ours as an HTML section (`published.compare`).

One narrow table that fits the page: the paper's model and citation, the metric, theirs,
ours, the verdict with its reasons under it, and the setups' differences, long text
wrapping (`assets/published.css`)."""

from __future__ import annotations

import re

from . import published, units, view
from .html_parts import esc, number, th

#: Columns: (header, class of its <col>, whether its cells are text).
COLUMNS = (("model (theirs) and source", "p-source", True), ("metric", "p-metric", True), ("theirs", "p-theirs", False),
           ("ours", "p-ours", False), ("verdict", "p-verdict", True), ("setup", "p-setup", True))
_CODE = re.compile(r"`([^`]+)`")
VERDICT_CLASS = {published.AGREES: "verdict-yes", published.DIFFERS: "verdict-no"}


def code_html(text: str) -> str:
    """Plain text with `names` in backticks as HTML, the names as code."""
    return _CODE.sub(lambda m: f"<code>{m.group(1)}</code>", esc(text))


def verdict_class(c: published.Comparison) -> str:
    """The verdict cell's class: agrees, does not reproduce, not comparable (muted), or missing."""
    return VERDICT_CLASS.get(c.verdict, "verdict-na" if c.mismatch else "missing")


def _ci(lines) -> str:
    return "".join(f'<span class="ci">{esc(t)}</span>' for t in lines if t)


def our_data(c: published.Comparison) -> str:
    """Which of our sections the figure comes from: its dataset, materials and scene."""
    s = c.section
    if s is None:
        return ""
    return f"{s.dataset}, {len(s.materials)} materials" + ("" if s.scene == "brdf_space" else f", {s.scene}")


def theirs_text(c: published.Comparison) -> tuple[str, str]:
    """(as printed with the paper's unit, in our unit where that reads differently)."""
    p = c.published
    if p is None:
        return "–", ""
    printed = f"{p.printed or p.value} {p.unit}".strip()
    if c.metric is None or c.theirs is None:
        return printed, ""
    if c.match.scale == 1 and (c.metric.kind != "cost" or p.unit == c.metric.unit):
        return printed, ""
    number_, unit = units.scaled(c.theirs, c.metric.unit) if c.metric.kind == "cost" else (units.human(c.theirs, ""), "")
    try:
        same = unit == p.unit and float(number_) == p.value
    except ValueError:
        same = False
    return printed, "" if same else f"= {published.show(c.theirs, c.metric)}"


def _row(c: published.Comparison) -> str:
    p, m = c.published, c.match
    where, what = published.citation(p.source if p else m.seed, p.table if p else m.table)
    printed, converted = theirs_text(c)
    ours, ours_sort = "–", None
    if c.ours is not None:
        value = c.ours.value if c.ours.complete else c.ours.partial
        ours, ours_sort = published.show(value, c.metric), c.ours.value if c.ours.complete else None
    notes = c.notes or ((c.detail,) if c.detail else ())
    return (f'<tr><td class="label" title="{esc(what)}">{esc(m.model)}{_ci([where])}</td>'
            f'<td class="label">{esc(m.metric)} → <code>{esc(m.our_metric)}</code></td>'
            f'<td data-sort="{number(c.theirs)}">{esc(printed)}{_ci([converted])}</td>'
            f'<td data-sort="{number(ours_sort)}">{esc(ours)}{_ci([c.label, our_data(c)])}</td>'
            f'<td class="label verdict {verdict_class(c)}">{esc(c.verdict)}{_ci(notes)}</td>'
            f'<td class="label setup">{esc(m.setup)}</td></tr>')


def _table(tid: str, rows: list[published.Comparison]) -> str:
    cols = "".join(f'<col class="{cls}">' for _, cls, _ in COLUMNS)
    head = "".join(th(name, cls="label" if text else "") for name, _, text in COLUMNS)
    body = "".join(_row(c) for c in rows)
    return (f'<div class="scroll"><table class="sortable published" id="{tid}"><colgroup>{cols}</colgroup>'
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>")


def published_section(report: view.Report) -> list[str]:
    """The source papers' figures beside ours (`published.compare`); says so where they cannot be read."""
    out = ['<h2 id="published">Published figures beside ours</h2>']
    out += [f'<p class="note">{code_html(text)}</p>' for text in published.note()]
    try:
        rows = published.compare(report)
    except (OSError, ValueError, KeyError) as exc:
        return out + [f'<p class="missing">The published figures could not be read ({esc(exc)}); '
                      "this section is empty.</p>"]
    measured = [c for c in rows if c.section is not None]
    unmeasured = [c for c in rows if c.section is None]
    out.append(f'<p class="meta">{esc(published.counts(rows))}</p>')
    if measured:
        out.append(_table("published-table", measured))
    if unmeasured:
        out.append(f"<details><summary>{len(unmeasured)} published figures with no figure of ours in this store"
                   f"</summary>{_table('published-unmeasured', unmeasured)}</details>")
    return out
