"""The source papers' figures beside ours as Markdown (`published.compare`): the same rows,
verdicts and reasons as the HTML section (`published_render`), as one table."""

from __future__ import annotations

from . import published, published_render, view


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return text.replace("|", "\\|").replace("\n", " ")


def _row(c: published.Comparison) -> list[str]:
    p, m = c.published, c.match
    where, _ = published.citation(p.source if p else m.seed, p.table if p else m.table)
    printed, converted = published_render.theirs_text(c)
    ours = "–"
    if c.ours is not None:
        ours = published.show(c.ours.value if c.ours.complete else c.ours.partial, c.metric)
        if c.label:
            ours += f" (`{c.label}`)"
    data = published_render.our_data(c)
    notes = c.notes or ((c.detail,) if c.detail else ())
    verdict = f"**{c.verdict}**" + "".join(f"; {n}" for n in notes)
    return [_cell(f"{m.model} ({where})"), _cell(f"{m.metric} → `{m.our_metric}`"),
            _cell(printed + (f" ({converted})" if converted else "")), _cell(ours + (f"; {data}" if data else "")),
            _cell(verdict), _cell(m.setup)]


def _table(rows: list[published.Comparison]) -> list[str]:
    header = ["model (theirs) and source", "metric", "theirs", "ours", "verdict", "setup"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return lines + ["| " + " | ".join(_row(c)) + " |" for c in rows]


def published_markdown(report: view.Report) -> list[str]:
    """The section "Published figures beside ours" as lines of Markdown (nothing for an empty
    store); says so where the published figures cannot be read."""
    if report.empty:
        return []
    lines = ["## Published figures beside ours", ""]
    for text in published.note():
        lines += [text, ""]
    try:
        rows = published.compare(report)
    except (OSError, ValueError, KeyError) as exc:
        return lines + [f"The published figures could not be read ({exc}); this section is empty.", ""]
    measured = [c for c in rows if c.section is not None]
    unmeasured = [c for c in rows if c.section is None]
    lines += [published.counts(rows), ""]
    if measured:
        lines += _table(measured) + [""]
    if unmeasured:
        lines += [f"### {len(unmeasured)} published figures with no figure of ours in this store", ""]
        lines += _table(unmeasured) + [""]
    return lines
