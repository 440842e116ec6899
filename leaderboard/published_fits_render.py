"""The section "Published fits against our fits" (`published_fits_view`) as Markdown and as HTML.

One table per published source: a row per (our fit, metric), the published fit's mean and
ours over the same materials, and ours − published. The HTML table is as wide as the page
and no wider (`table.published`: fixed layout, text wraps)."""

from __future__ import annotations

from .html_parts import esc
from .published_fits_view import FitsSection, MetricPair, OurFit, PublishedFits, SourceFits
from .published_render import code_html
from .units import fmt

TITLE = "Published fits against our fits"
ANCHOR = "published-fits"
HEADER = ("our fit", "materials", "metric", "published", "ours", "ours − published")
#: Failed materials named before "and N more".
NAMED_FAILURES = 5


def _signed(value: float) -> str:
    return ("+" if value > 0 else "") + fmt(value)


def difference_text(p: MetricPair, materials: int) -> str:
    """"−0.0123 (−17 %; ours better)"; the metric's own count where it is not the pair's."""
    d = p.difference
    if d is None:
        return "–"
    parts = [f"{100 * d / abs(p.published):+.3g} %"] if p.published else []
    parts.append({"ours": "ours better", "published": "published better", "equal": "equal"}[p.better])
    if p.n != materials:
        parts.append(f"over {p.n} materials")
    return f"{_signed(d)} ({'; '.join(parts)})"


def _arrow(p: MetricPair) -> str:
    return "↑" if p.higher_is_better else "↓"


def heading(s: FitsSection) -> str:
    where = "BRDF space" if s.scene == "brdf_space" else f"rendered scene `{s.scene}`"
    return f"Dataset `{s.dataset}`, {where} (harness `{s.harness}`)"


def source_heading(f: SourceFits) -> str:
    paper = f": {f.paper}" if f.paper else ""
    model = f", evaluated with `{f.model}`" if f.model else ""
    return f"`{f.source}`{paper}{model}"


def source_line(f: SourceFits, s: FitsSection) -> str:
    """The published fit's materials: how many have a figure, which failed."""
    text = f"Published fit `{f.label}`: a figure for {f.ok} of {s.materials} materials"
    if f.failed:
        named = ", ".join(f.failed[:NAMED_FAILURES])
        more = f" and {len(f.failed) - NAMED_FAILURES} more" if len(f.failed) > NAMED_FAILURES else ""
        text += f"; failed on {len(f.failed)} ({named}{more}), left out"
    text += "."
    return text + (f" {f.note[0].upper()}{f.note[1:]}." if f.note else "")


def empty_line(f: SourceFits) -> str:
    """Our fits with no material where both are ok (no table row), or ""."""
    empty = [f"`{o.label}`" for o in f.ours if not o.materials]
    return f"No material where both the published fit and {', '.join(empty)} have a figure." if empty else ""


def fit_text(o: OurFit) -> tuple[str, str]:
    """(our configuration, its loss in words)."""
    loss = f"loss `{o.loss}`" + (" (default)" if o.loss == "l1_log_cos" else "")
    if o.authors_loss:
        loss += ", the authors' loss"
    return f"`{o.label}`", loss


def materials_text(o: OurFit) -> str:
    return f"{o.materials}" + (f" (ours failed on {o.failed})" if o.failed else "")


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(view: PublishedFits | None) -> list[str]:
    """The section as lines of Markdown; nothing without published fits."""
    if view is None:
        return []
    lines = [f"## {TITLE}", "", view.note, ""]
    for s in view.sections:
        lines += [f"### {heading(s)}", "", f"{s.materials} materials, fingerprint `{s.fingerprint}`.", "",
                  f"> {s.caveat}", ""]
        for f in s.sources:
            lines += [f"#### {source_heading(f)}", "", source_line(f, s), ""]
            lines += [empty_line(f), ""] if empty_line(f) else []
            if not any(o.materials for o in f.ours):
                continue
            lines += ["| " + " | ".join(HEADER) + " |", "|" + "|".join("---" for _ in HEADER) + "|"]
            for o in (o for o in f.ours if o.materials):
                label, loss = fit_text(o)
                for p in o.metrics:
                    cells = [f"{label}, {loss}", materials_text(o), f"`{p.metric}` {_arrow(p)}", fmt(p.published),
                             fmt(p.ours), difference_text(p, o.materials)]
                    lines.append("| " + " | ".join(_md_cell(c) for c in cells) + " |")
            lines.append("")
    return lines


def _td(text: str, cls: str = "", rowspan: int = 1) -> str:
    attrs = (f' class="{cls}"' if cls else "") + (f' rowspan="{rowspan}"' if rowspan > 1 else "")
    return f"<td{attrs}>{text}</td>"


def _rows(o: OurFit) -> str:
    label, loss = fit_text(o)
    out = []
    for k, p in enumerate(o.metrics):
        lead = ""
        if k == 0:
            lead = (_td(f'{code_html(label)}<span class="ci">{code_html(loss)}</span>', "label", len(o.metrics))
                    + _td(esc(materials_text(o)), "", len(o.metrics)))
        best_pub, best_ours = ("best" if p.better == "published" else ""), ("best" if p.better == "ours" else "")
        out.append(f"<tr>{lead}{_td(f'<code>{esc(p.metric)}</code> {_arrow(p)}', 'label')}"
                   f"{_td(esc(fmt(p.published)), best_pub)}{_td(esc(fmt(p.ours)), best_ours)}"
                   f"{_td(esc(difference_text(p, o.materials)))}</tr>")
    return "".join(out)


def _table(f: SourceFits, tid: str) -> str:
    head = "".join(f'<th class="label">{esc(h)}</th>' if i in (0, 2) else f"<th>{esc(h)}</th>"
                   for i, h in enumerate(HEADER))
    body = "".join(_rows(o) for o in f.ours if o.materials)
    return (f'<div class="scroll"><table class="published" id="{tid}"><thead><tr>{head}</tr></thead>'
            f"<tbody>{body}</tbody></table></div>")


def html_section(view: PublishedFits | None) -> list[str]:
    """The section as HTML; nothing without published fits. Ids: `published-fits`, then
    `published-fits-<section>`, `-<source>` and `-<source>-table`, unique on the page."""
    if view is None:
        return []
    out = [f'<h2 id="{ANCHOR}">{esc(TITLE)}</h2>', f'<p class="note">{code_html(view.note)}</p>']
    for i, s in enumerate(view.sections):
        sid = f"{ANCHOR}-{i}"
        out += [f'<h3 id="{sid}">{code_html(heading(s))}</h3>',
                f'<p class="meta">{s.materials} materials, fingerprint <code>{esc(s.fingerprint)}</code>.</p>',
                f"<blockquote>{code_html(s.caveat)}</blockquote>"]
        for j, f in enumerate(s.sources):
            fid = f"{sid}-{j}"
            out += [f'<h4 id="{fid}">{code_html(source_heading(f))}</h4>', f"<p>{code_html(source_line(f, s))}</p>"]
            if empty_line(f):
                out.append(f'<p class="note">{code_html(empty_line(f))}</p>')
            if any(o.materials for o in f.ours):
                out.append(_table(f, f"{fid}-table"))
    return out
