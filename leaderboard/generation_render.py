"""The generation section (`generation_view.GenerationSection`) as Markdown and as HTML."""

from __future__ import annotations

import html
import json
from pathlib import Path

from . import svg_plot
from .generation_view import DrawCell, GenerationSection, GenRow
from .units import fmt
from brdfbench import artifacts

INTRO = ("Each generator is trained on the dataset's training split; each of its {draws} independent sample draws "
         "is scored against the held-out test split ({ref} materials) as a set. A figure is the mean over the draws "
         "with a {conf} Student-t interval over them; in parentheses, the published figure of the same generator "
         "(Hu 2026, Table 4.5), in its printed display scale (ours converted to it). ↓ lower is better, ↑ higher "
         "is better, 1-NNA is best at 50 %; the best generator's figure is marked. The training set's row is the "
         "ceiling: the training split scored as if it were a generator (never marked best).")


def _intro(s: GenerationSection) -> str:
    return INTRO.format(draws=s.draws, ref=s.reference_size if s.reference_size is not None else "?", conf="95 %")


def _arrow(row: GenRow) -> str:
    if row.ideal is not None:
        return f"→{row.ideal:g}"
    if row.higher_is_better is None:
        return ""
    return "↑" if row.higher_is_better else "↓"


def _text(cell: DrawCell | None, scale: float, interval: bool = True) -> str:
    if cell is None:
        return "–"
    out = fmt(cell.value * scale)
    if interval and cell.lo is not None and cell.n > 1 and cell.lo != cell.hi:
        out += f" [{fmt(cell.lo * scale)}, {fmt(cell.hi * scale)}]"
    return out


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return (["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
            + ["| " + " | ".join(r) + " |" for r in rows])


def markdown(s: GenerationSection) -> list[str]:
    lines = [f"## Dataset `{s.dataset}`: generators", "", f"Fingerprint `{s.fingerprint}`.", ""]
    if s.caveat:
        lines += [f"> {s.caveat}", ""]
    if not s.rows:
        return lines + ["No successful results yet.", ""] + _md_failures(s)
    names = [f"`{c.label}`" for c in s.columns]
    lines += ["### Unconditional synthesis (Zhou et al., Table 1)", "", _intro(s), "", f"> {s.paper_caveat}", ""]
    body = []
    for row in s.rows:
        best = row.best(s.ceilings)
        cells = []
        for c in s.columns:
            text = _text(row.cells.get(c.config_hash), row.scale)
            if best == c.config_hash:
                text = f"**{text}**"
            if c.config_hash in row.published:
                text += f" ({fmt(row.published[c.config_hash])})"
            cells.append(text)
        body.append([f"{row.label} {_arrow(row)}".rstrip(), *cells])
    lines += _table(["metric", *names], body) + [""]
    if s.costs:
        lines += ["### Cost", ""]
        lines += _table(["", *names], [[f"{r.label} {_arrow(r)}".rstrip(),
                                         *[_text(r.cells.get(c.config_hash), 1.0, False) for c in s.columns]]
                                        for r in s.costs]) + [""]
    if s.categories:
        lines += ["### Constrained synthesis: samples per draw in each category (Zhou et al., C.3)", ""]
        lines += _table(["category", *names], [[r.label, *[_text(r.cells.get(c.config_hash), 1.0, False) for c in s.columns]]
                                               for r in s.categories]) + [""]
    return lines + _md_failures(s)


def _md_failures(s: GenerationSection) -> list[str]:
    if not s.failures:
        return []
    lines = ["### Failures", ""]
    lines += _table(["generator", "set", "error"], [[f"`{f.label}`", f.material, f.message.replace("|", "\\|")[:200]]
                                                    for f in s.failures])
    return lines + [""]


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _td(cell: DrawCell | None, scale: float, best: bool = False, published: float | None = None,
        interval: bool = True) -> str:
    if cell is None:
        return '<td class="missing" data-sort="">–</td>'
    ci = ""
    if interval and cell.lo is not None and cell.n > 1 and cell.lo != cell.hi:
        ci = f'<span class="ci">[{_e(fmt(cell.lo * scale))}, {_e(fmt(cell.hi * scale))}]</span>'
    paper = "" if published is None else f'<span class="ci">paper {_e(fmt(published))}</span>'
    cls = ' class="best"' if best else ""
    title = f"mean over {cell.n} draw(s)"
    return (f'<td{cls} data-sort="{cell.value * scale!r}" title="{_e(title)}">{_e(fmt(cell.value * scale))}'
            f"{ci}{paper}</td>")


def _html_table(tid: str, first: str, s: GenerationSection, rows: list[GenRow], with_paper: bool,
                interval: bool = True) -> str:
    head = f'<th class="label">{_e(first)}</th>' + "".join(f"<th><code>{_e(c.label)}</code></th>" for c in s.columns)
    body = []
    for row in rows:
        best = row.best(s.ceilings)
        cells = "".join(_td(row.cells.get(c.config_hash), row.scale, best == c.config_hash,
                            row.published.get(c.config_hash) if with_paper else None, interval) for c in s.columns)
        label = f"{row.label} {_arrow(row)}".rstrip()
        body.append(f'<tr><td class="label" title="{_e(row.unit)}">{_e(label)}</td>{cells}</tr>')
    return (f'<div class="scroll"><table id="{tid}"><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(body)}</tbody></table></div>")


def training_curves(s: GenerationSection, results_dir: Path) -> list[tuple[str, str, list[float]]]:
    """(generator label, curve name, values per epoch) of every configuration that left a
    training-curve artifact (`GenerationHarness` writes them)."""
    out = []
    for c in s.columns:
        entry = artifacts.lookup(results_dir, c.config_hash, "training").get("curve")
        if not entry:
            continue
        try:
            data = json.loads((results_dir / entry["path"]).read_text(encoding="utf-8"))
        except (OSError, ValueError, KeyError, TypeError):
            continue
        for name, values in (data.get("curves") or {}).items():
            if isinstance(values, list) and values:
                out.append((c.label, str(name), [float(v) for v in values]))
    return out


def curve_svg(curves: list[tuple[str, str, list[float]]]) -> str:
    """Training curves against the epoch, log-log, one series per (generator, curve)."""
    points = [(i + 1, v) for _, _, values in curves for i, v in enumerate(values) if v > 0]
    if not points:
        return ""
    axes = svg_plot.LogAxes(svg_plot.log_range([p[0] for p in points]), svg_plot.log_range([p[1] for p in points]),
                            60, 24, 420, 220)
    parts = [axes.frame("epoch", "training objective", "Training curves")]
    legend = []
    for k, (label, name, values) in enumerate(curves):
        kept = [(i + 1, v) for i, v in enumerate(values) if v > 0]
        if not kept:
            continue
        colour = svg_plot.colour(k)
        dash = ' stroke-dasharray="4 3"' if name != "loss" else ""
        parts.append(f'<path d="{axes.path([x for x, _ in kept], [y for _, y in kept])}" fill="none" '
                     f'stroke="{colour}" stroke-width="1.2"{dash}/>')
        y = 30 + 13 * len(legend)
        legend.append(f'<line x1="495" y1="{y - 3}" x2="515" y2="{y - 3}" stroke="{colour}" stroke-width="1.5"{dash}/>'
                      f'<text x="520" y="{y}" font-size="9">{svg_plot.escape(f"{label}: {name}")}</text>')
    return ('<svg xmlns="http://www.w3.org/2000/svg" width="700" height="280" viewBox="0 0 700 280" '
            f'role="img" aria-label="training curves">{"".join(parts + legend)}</svg>')


def html_section(s: GenerationSection, sid: str, results_dir: Path | None = None) -> list[str]:
    out = [f'<h2 id="{sid}">Dataset <code>{_e(s.dataset)}</code>: generators</h2>',
           f'<p class="meta">Fingerprint <code>{_e(s.fingerprint)}</code>, harness <code>generation</code>.</p>']
    if s.caveat:
        out.append(f"<blockquote>{_e(s.caveat)}</blockquote>")
    if not s.rows:
        return out + ["<p>No successful results yet.</p>", *_html_failures(s)]
    out += ["<h3>Unconditional synthesis (Zhou et al., Table 1)</h3>", f'<p class="note">{_e(_intro(s))}</p>',
            f"<blockquote>{_e(s.paper_caveat)}</blockquote>", _html_table(f"{sid}-table1", "metric", s, s.rows, True)]
    if s.costs:
        out += ["<h3>Cost</h3>", _html_table(f"{sid}-cost", "", s, s.costs, False, interval=False)]
    curves = training_curves(s, results_dir) if results_dir is not None else []
    if curves:
        out += ["<h3>Training curves</h3>", '<p class="note">Each generator\'s own training objective per epoch '
                "(not comparable across generators); dashed: held-out.</p>", f'<div class="plot">{curve_svg(curves)}</div>']
    if s.categories:
        out += ["<h3>Constrained synthesis: samples per draw in each category (Zhou et al., C.3)</h3>",
                _html_table(f"{sid}-categories", "category", s, s.categories, False, interval=False)]
    return out + _html_failures(s)


def _html_failures(s: GenerationSection) -> list[str]:
    if not s.failures:
        return []
    rows = "".join(f'<tr><td class="label"><code>{_e(f.label)}</code></td><td class="label">{_e(f.material)}</td>'
                   f'<td class="label">{_e(f.message[:300])}</td></tr>' for f in s.failures)
    return ["<h3>Failures</h3>", '<table><thead><tr><th class="label">generator</th><th class="label">set</th>'
            f'<th class="label">error</th></tr></thead><tbody>{rows}</tbody></table>']
