"""The source papers' figures beside ours as an HTML section (`published.compare`)."""

from __future__ import annotations

from . import published, view
from .html_parts import esc, number, span, th
from .markdown import fmt


def published_section(report: view.Report) -> list[str]:
    """The source papers' figures beside ours (`published.compare`); says so where they cannot be read."""
    out = ['<h2 id="published">Published figures beside ours</h2>',
           '<p class="note">Figures as printed in the source papers, converted to our unit, beside our figure for '
           "the same model and metric, with how the setups differ. A figure within a factor of "
           f"{published.AGREEMENT_FACTOR:g} of the published one (within 3 dB for PSNR; 1 − SSIM within a factor of "
           f"{published.AGREEMENT_FACTOR:g} for SSIM) is said to agree; any other does not reproduce. Timings and "
           "throughputs are from other hardware: their ratio is not a verdict on the method. Under each of our "
           "figures is the configuration that produced it, which names its recipe: <code>nbrdf</code>, "
           "<code>naive_mlp</code>, <code>tripleplane</code>, <code>triplane_gated</code> and "
           "<code>hyperdiffusion</code> train on this project's schedules, sized for a CPU; "
           f"{', '.join(f'<code>{n}</code>' for n in published.PUBLISHED_RECIPES)} on the papers' own recipes "
           "(see the README's GPUs section).</p>"]
    try:
        rows = published.compare(report)
    except (OSError, ValueError, KeyError) as exc:
        return out + [f'<p class="missing">The published figures could not be read ({esc(exc)}); '
                      "this section is empty.</p>"]
    head = "".join(th(t, cls="label" if i in (0, 1, 2, 7, 8) else "") for i, t in enumerate(
        ("source", "model (theirs)", "metric", "theirs", "theirs, our unit", "ours", "verdict", "our data", "setup")))
    body: dict[bool, list[str]] = {True: [], False: []}  # measured here, or not
    for c in rows:
        p, m = c.published, c.match
        theirs = "–" if p is None else f"{fmt(p.value)} {p.unit}".strip()
        ours = "–"
        if c.ours is not None:
            ours = fmt(c.ours.value if c.ours.complete else c.ours.partial)
        data = "–" if c.section is None else (f"{c.section.dataset} ({len(c.section.materials)} materials)"
                                              + ("" if c.section.scene == "brdf_space" else f", {c.section.scene}"))
        cls = {"agrees": "verdict-yes", "does not reproduce": "verdict-no"}.get(c.verdict, "missing")
        label = "" if c.section is None else next((r.label for r in c.section.rows if r.cell(m.our_metric) is c.ours), "")
        where, what = published.citation(p.source if p else m.seed, p.table if p else m.table)
        body[c.section is not None].append(
            f'<tr><td class="label">{esc(where)}<span class="ci">{esc(what)}'
            f'</span></td><td class="label">{esc(m.model)}</td><td class="label">{esc(m.metric)} → '
            f'<code>{esc(m.our_metric)}</code></td><td data-sort="{number(p.value if p else None)}">{esc(theirs)}</td>'
            f'<td data-sort="{number(c.theirs)}">{fmt(c.theirs)}</td>'
            f'<td data-sort="{number(c.ours.value if c.ours is not None and c.ours.complete else None)}">{ours}'
            f"{span(label)}</td>"
            f'<td class="{cls}">{esc(c.verdict)}<span class="ci">{esc(c.detail)}</span></td>'
            f'<td class="label">{esc(data)}</td><td class="label">{esc(m.setup)}</td></tr>')
    counts = {v: sum(c.verdict == v for c in rows) for v in ("agrees", "does not reproduce", "not measured")}
    out.append(f'<p class="meta">{counts["agrees"]} agree, {counts["does not reproduce"]} do not reproduce, '
               f'{counts["not measured"]} not measured in this store.</p>')
    def table(tid: str, rows_: list[str]) -> str:
        return (f'<div class="scroll"><table class="sortable" id="{tid}"><thead><tr>{head}</tr></thead>'
                f"<tbody>{''.join(rows_)}</tbody></table></div>")

    if body[True]:
        out.append(table("published-table", body[True]))
    if body[False]:
        out.append(f"<details><summary>{len(body[False])} published figures with no figure of ours in this store"
                   f"</summary>{table('published-unmeasured', body[False])}</details>")
    return out
