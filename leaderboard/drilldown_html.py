"""The per-material heat map of a table section (`drilldown.build`) as HTML.

Rows are materials, hardest first; columns the configurations. A cell's colour is its
figure on one scale for the whole map (log for positive lower-is-better metrics, linear
otherwise), so a column shows a model's weak materials and a row the models a material
defeats. Each cell links to that material's lobe figure, or its render, where the page
has one (`links`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from . import drilldown
from .html_parts import esc, number, th
from .units import fmt

#: A perceptually ordered ramp (dark blue → teal → yellow), sampled at equal steps.
RAMP = ((68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37))


def colour(t: float) -> tuple[int, int, int]:
    """The ramp at t in [0, 1] (clamped), linearly interpolated."""
    t = min(max(t, 0.0), 1.0) * (len(RAMP) - 1)
    k = min(int(t), len(RAMP) - 2)
    f = t - k
    return tuple(round(a + (b - a) * f) for a, b in zip(RAMP[k], RAMP[k + 1]))


def _scale(d: drilldown.Drilldown) -> tuple[Callable[[float], float], float, float, bool]:
    """(position of a value in [0, 1] with 1 the worst, low, high, log?) over the ranked cells."""
    ranked = {r.config_hash for r in d.configs if not r.reference}
    vals = [v for (h, _m), v in d.values.items() if h in ranked and math.isfinite(v)]
    log = (not d.metric.higher_is_better) and bool(vals) and min(vals) > 0
    xs = [math.log10(v) for v in vals] if log else vals
    lo, hi = (min(xs), max(xs)) if xs else (0.0, 1.0)

    def position(v: float) -> float:
        x = math.log10(v) if log else v
        t = 0.5 if hi == lo else (x - lo) / (hi - lo)
        return 1 - t if d.metric.higher_is_better else t

    return position, (10 ** lo if log else lo), (10 ** hi if log else hi), log


def _bar(lo: float, hi: float, log: bool, worse_high: bool) -> str:
    """The colour scale: a CSS gradient from the better end to the worse, with its figures."""
    stops = ", ".join(f"rgb{c} {100 * k / (len(RAMP) - 1):.0f}%" for k, c in enumerate(RAMP))
    left, right = (fmt(lo), fmt(hi)) if worse_high else (fmt(hi), fmt(lo))
    return (f'<div class="heat-bar"><span>{esc(left)} (better)</span>'
            f'<span class="ramp" style="background:linear-gradient(to right, {stops})"></span>'
            f'<span>{esc(right)} (worse){"; log scale" if log else ""}</span></div>')


def heatmap(d: drilldown.Drilldown, sid: str, links: Callable[[str], dict[str, str]]) -> list[str]:
    """The heat map; `links(material)` maps "lobe" / "render" to an anchor ("#id") where the page has one."""
    position, lo, hi, log = _scale(d)
    head = [th("material", "category; the target's lobe half-width", cls="label name"),
            th("difficulty", "mean percentile rank over the ranked configurations: 0 easiest, 1 hardest")]
    head += [f'<th class="heat-col">{esc(r.label).replace("_", "_<wbr>")}'
             f'{" <span class=ci>reference</span>" if r.reference else ""}</th>' for r in d.configs]
    body = []
    for m in d.materials:
        found = links(m)
        where = " ".join(f'<a href="{esc(href)}">{esc(kind)}</a>' for kind, href in found.items())
        about = " · ".join(x for x in (d.categories.get(m, ""),
                                       f"lobe {d.widths[m]:.3g} rad" if m in d.widths else "") if x)
        about = esc(about) + (f" · {where}" if where else "")
        cells = [f'<td class="label name"><code>{esc(m)}</code><span class="ci">{about}</span></td>',
                 f'<td data-sort="{number(d.difficulty[m])}">{d.difficulty[m]:.2f}</td>']
        target = found.get("lobe") or found.get("render")
        for r in d.configs:
            v = d.values.get((r.config_hash, m))
            if v is None or not math.isfinite(v):
                cells.append('<td class="missing" data-sort="">–</td>')
                continue
            title = f"{r.label} on {m}: {d.metric.name} {fmt(v)}"
            if r.reference:
                cells.append(f'<td class="heat-ref" data-sort="{number(v)}" title="{esc(title)}">{esc(fmt(v))}</td>')
                continue
            rgb = colour(position(v))
            ink = "#111" if 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2] > 140 else "#fff"
            text = esc(fmt(v))
            if target:
                text = f'<a href="{esc(target)}" style="color:{ink}">{text}</a>'
            cells.append(f'<td class="heat" data-sort="{number(v)}" title="{esc(title)}" '
                         f'style="background:rgb{rgb};color:{ink}">{text}</td>')
        body.append(f"<tr>{''.join(cells)}</tr>")
    return [f'<h3 id="{sid}-materials">Per material: <code>{esc(d.metric.name)}</code></h3>',
            f'<p class="note">{esc(drilldown.summary(d))} Each cell links to the material\'s lobe figure (or its '
            "render) where the page has one; the reference column (the target scored against itself) is not "
            "coloured.</p>",
            _bar(lo, hi, log, not d.metric.higher_is_better),
            f'<div class="scroll"><table class="sortable heatmap" id="{sid}-heatmap"><thead><tr>{"".join(head)}'
            f"</tr></thead><tbody>{''.join(body)}</tbody></table></div>"]
