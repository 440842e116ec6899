"""The HTML report: the report's view (`view.build`) as one self-contained page.

`leaderboard.html` opens from a file with no server and no network: styles, the sorting
script and every plot (inline SVG) are inside it; rendered images are linked by relative
path beside it. Tables sort by a click on their header; a plot's legend toggles its series.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from . import (chart_html, drilldown, drilldown_html, figures_html, generation_render, machines, main_table,
               published_fits_render, published_fits_view, published_render, view)
from . import plots as plots_module
from .html_parts import anchor, assets, cell as _cell, CONTENDED, esc, number, ON_GPU, svg, th
from .markdown import fmt, sharpness_caption
from .view import ConvergenceSection, Metric, TableSection
from brdfbench.atomic import replacing


#: Where a table section's heat map goes: filled in once the whole page, and so every
#: figure a heat-map cell may link to, is known.
DRILLDOWN_MARK = "<!--drilldown:{sid}-->"


def _best(section: TableSection, metric: Metric) -> str | None:
    """The config hash with the best complete figure of a directed metric, where at least
    two configurations (references aside) have one: a lone figure is not "best"."""
    if not metric.directed:
        return None
    peers = [r for r in section.timing_peers(metric.name)
             if r.cell(metric.name) is not None and r.cell(metric.name).complete]
    return peers[0].config_hash if len(peers) >= 2 else None


def table_section(s: TableSection, sid: str, results_dir: Path | None = None) -> list[str]:
    where = "" if s.scene == "brdf_space" else f", rendered scene <code>{esc(s.scene)}</code>"
    out = [f'<h2 id="{sid}">Dataset <code>{esc(s.dataset)}</code>{where}</h2>',
           f'<p class="meta">{len(s.materials)} materials, fingerprint <code>{esc(s.fingerprint)}</code>, '
           f"harness <code>{esc(s.harness)}</code>.</p>"]
    if s.scene != "brdf_space":
        out.append("<blockquote>Image metrics compare each representation's render with the render of the "
                   "material's own table (nearest-cell lookup) through the same simulator and random numbers."
                   "</blockquote>")
    if s.caveat:
        out.append(f"<blockquote>{esc(s.caveat)}</blockquote>")
    if s.primary is None:
        return out + ["<p>No successful results yet.</p>", *_failures(s.failures)]
    best = {m.name: _best(s, m) for m in [*s.accuracy, *s.costs]}
    hidden = main_table.columns(s)[1]
    out += ["<h3>Accuracy and its cost</h3>", *main_table.table(s, sid, best),
            f'<p class="note">Ranked by mean <code>{esc(s.primary.name)}</code> over materials; below each mean its '
            f"{view.CONFIDENCE:.0%} bootstrap interval over materials ({view.BOOTSTRAP_RESAMPLES} resamples; none with "
            f"fewer than {view.MIN_INTERVAL_N} materials). Fit time is the mean per material (amortised over the "
            "materials fitted together, for batched fitters, and over the fits run side by side, one per process, "
            "for single-threaded ones); evals/s and bytes the median; bytes per material "
            "leave out a part shared by every material, shown below them. A configuration without a figure for "
            "every material has no mean (its partial one is in the cell's tooltip) and is not ranked"
            + ("; the reference row, the target scored against itself, is shown above the ranking and never "
               "ranked" if s.references else "")
            + ". Click a header to sort (▲ / ▼ mark the sorted column); hover a cell for the exact figure, median "
            "and worst case"
            + ("; tick the box to show every column" if hidden else "") + ".</p>"]
    if s.contended:
        out.append(f'<p class="note">{CONTENDED} measured while other brdfbench jobs ran on the same host: timings '
                   "are not comparable with unmarked ones.</p>")
    if s.brief:
        note = view.BRIEF_NOTE.replace("`brdfbench`", "<code>brdfbench</code>").replace(
            "`brdfbench profile=full`", "<code>brdfbench profile=full</code>")
        out.append(f'<p class="note">{", ".join(f"<code>{esc(b)}</code>" for b in s.brief)}: {note}.</p>')
    if s.accelerators:
        out.append(f'<p class="note">{ON_GPU} computed on a GPU ({esc(", ".join(s.accelerators))}): these timings are '
                   "not comparable with CPU ones, and a column that holds both marks its best among the CPU "
                   "figures.</p>")
    out += chart_html.chart(s, sid)
    if results_dir is not None and s.harness == "accuracy":
        out += figures_html.lobes(s, sid, results_dir)
    if results_dir is not None and s.scene != "brdf_space":
        out += figures_html.images(s, sid, results_dir)
    out.append(DRILLDOWN_MARK.format(sid=sid))
    out += _per_metric(s, sid)
    out += _categories(s, sid)
    out += _sharpness(s, sid)
    return out + _failures(s.failures)


def _per_metric(s: TableSection, sid: str) -> list[str]:
    out = ["<details><summary>Per metric: mean, interval, median, worst case</summary>"]
    for m in s.accuracy:
        rows: dict[bool, list[str]] = {True: [], False: []}  # the reference's apart: sorting never moves it
        rank = 0
        for row in s.ranking(m.name):
            c = row.cell(m.name)
            if c is None:
                continue
            rank += 1 if c.complete and not row.reference else 0
            shown = "ref." if row.reference else (rank if c.complete else "–")
            rows[row.reference].append(
                f'<tr><td>{shown}</td><td class="label"><code>{esc(row.label)}</code></td>'
                f'{_cell(c, m)}<td data-sort="{number(c.median)}">{fmt(c.median)}</td>'
                f'<td data-sort="{number(c.worst)}">{fmt(c.worst)}</td><td>{c.n}</td></tr>')
        bodies = (f'<tbody class="reference">{"".join(rows[True])}</tbody>' if rows[True] else "") + \
            f'<tbody>{"".join(rows[False])}</tbody>'
        out += [f"<h3><code>{esc(m.name)}</code> ({esc(m.unit or 'unitless')}, "
                f"{'higher' if m.higher_is_better else 'lower'} is better)</h3>",
                f'<table class="sortable" id="{sid}-{esc(m.name)}"><thead><tr>{th("rank")}'
                f'{th("representation", cls="label")}{th("mean")}{th("median")}{th("worst")}{th("materials")}'
                f"</tr></thead>{bodies}</table>"]
    return out + ["</details>"]


def _categories(s: TableSection, sid: str) -> list[str]:
    if not s.categories:
        return []
    head = [th("representation", cls="label"), *[th(f"{c.name} ({c.materials})") for c in s.categories]]
    body = []
    for row in s.rows:
        cells = [f'<td class="label"><code>{esc(row.label)}</code></td>']
        cells += [_cell(c.cells.get(row.config_hash), s.primary) for c in s.categories]
        body.append(f"<tr>{''.join(cells)}</tr>")
    return [f"<h3>Mean <code>{esc(s.primary.name)}</code> per category</h3>",
            f'<div class="scroll"><table class="sortable" id="{sid}-categories"><thead><tr>{"".join(head)}</tr>'
            f"</thead><tbody>{''.join(body)}</tbody></table></div>"]


def _sharpness(s: TableSection, sid: str) -> list[str]:
    split = s.sharpness
    if split is None:
        return []
    head = [th("representation", cls="label")]
    for m in split.metrics:
        head += [th(f"{m.name} {m.arrow}, sharpest ({len(split.sharpest)})"), th(f"{m.name} {m.arrow}, rest ({split.rest})")]
    body = []
    for row in s.rows:
        cells = [f'<td class="label"><code>{esc(row.label)}</code></td>']
        for m in split.metrics:
            cells += [_cell(split.cells.get((row.config_hash, m.name, part)), m) for part in (True, False)]
        body.append(f"<tr>{''.join(cells)}</tr>")
    return ["<h3>The sharpest tenth of the targets</h3>", f'<p class="note">{esc(sharpness_caption(split))}</p>',
            f'<div class="scroll"><table class="sortable" id="{sid}-sharpest"><thead><tr>{"".join(head)}</tr>'
            f"</thead><tbody>{''.join(body)}</tbody></table></div>"]


def convergence_section(s: ConvergenceSection, sid: str, figure_svg: str | None) -> list[str]:
    out = [f'<h2 id="{sid}">Dataset <code>{esc(s.dataset)}</code>, convergence on <code>{esc(s.scene)}</code>, '
           f"sampler <code>{esc(s.sampler)}</code></h2>",
           f'<p class="meta">{len(s.materials)} materials, fingerprint <code>{esc(s.fingerprint)}</code>.</p>',
           "<blockquote>Monte Carlo noise only: each representation's render at n spp against its own high-spp "
           "render (same model, independent random numbers). Slope: of log RMSE on log spp (−0.5 for an unbiased "
           "estimator); RMSE at 1 spp: implied by the 1/√spp law over all rungs.</blockquote>"]
    if not s.rows:
        out.append("<p>No successful results yet.</p>")
    else:
        top = s.ladder[-1]
        err = Metric("rmse_hdr", "", False, "accuracy")
        cost = Metric("convergence", "", False, "cost")
        head = [th("representation", cls="label"), *[th(f"{n} spp") for n in s.ladder], th("slope"),
                th("RMSE at 1 spp (fit) ↓"), th(f"render time at {top} spp (s) ↓")]
        body = []
        for r in s.rows:
            cells = [f'<td class="label"><code>{esc(r.label)}</code></td>']
            cells += [_cell(r.rmse.get(n), err) for n in s.ladder]
            cells += [_cell(r.slope, cost), _cell(r.rmse_1spp, cost), _cell(r.render_time.get(top), cost)]
            body.append(f"<tr>{''.join(cells)}</tr>")
        out.append(f'<div class="scroll"><table class="sortable" id="{sid}-table"><thead><tr>{"".join(head)}'
                   f"</tr></thead><tbody>{''.join(body)}</tbody></table></div>")
    if figure_svg:
        out += ["<h3>Error against spp and against render time</h3>",
                f'<div class="plot" id="{sid}-convergence">{figure_svg}</div>']
    return out + _failures(s.failures)


def _failures(failures: list[view.Failure]) -> list[str]:
    if not failures:
        return []
    rows = "".join(f'<tr><td class="label"><code>{esc(f.label)}</code></td><td class="label">{esc(f.material)}</td>'
                   f'<td class="label">{esc(f.message[:300])}</td></tr>' for f in failures)
    return ["<h3>Failures</h3>", f'<table><thead><tr>{th("representation", cls="label")}'
            f'{th("material", cls="label")}{th("error", cls="label")}</tr></thead><tbody>{rows}</tbody></table>']


def _section_title(s) -> str:
    if isinstance(s, ConvergenceSection):
        return f"{s.dataset}: convergence on {s.scene}, sampler {s.sampler}"
    if getattr(s, "kind", "") == "generation":
        return f"{s.dataset}: generators"
    return f"{s.dataset}" + ("" if s.scene == "brdf_space" else f", scene {s.scene}")


def render_view(report: view.Report, convergence_svgs: dict[str, str] | None = None,
                extra: list[str] | None = None, results_dir: Path | None = None) -> str:
    """The page; `convergence_svgs` maps a convergence figure's name to its SVG; `extra` is
    markup appended after the sections (e.g. the published figures)."""
    convergence_svgs = dict(convergence_svgs or {})
    body = ["<h1>brdfbench leaderboard</h1>"]
    if report.empty:
        body += [f'<p class="meta">Generated {esc(report.generated)} from <code>{esc(report.source)}</code>.</p>',
                 "<p>The results store is empty: run the benchmark first.</p>"]
    else:
        body += provenance(report)
        toc = "".join(f'<li><a href="#s{i}">{esc(_section_title(s))}</a></li>' for i, s in enumerate(report.sections))
        body.append(f"<nav><ul>{toc}</ul></nav>")
        drills: dict[str, drilldown.Drilldown] = {}
        for i, s in enumerate(report.sections):
            sid = f"s{i}"
            if isinstance(s, ConvergenceSection):
                name = plots_module.convergence_plot_name(s.dataset, s.fingerprint, s.scene)
                body += convergence_section(s, sid, convergence_svgs.pop(name, None))
            elif getattr(s, "kind", "") == "generation":
                body += generation_render.html_section(s, sid, results_dir)
            else:
                body += table_section(s, sid, results_dir)
                d = drilldown.build(s) if s.primary is not None else None
                if d is not None:
                    drills[sid] = d
        body = _fill_drilldowns(body, report, drills)
        body += machine_section(report.machines)
    body += extra or []
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>brdfbench leaderboard</title><style>{assets('.css')}</style></head>"
            f"<body>{''.join(body)}<script>{assets('.js')}</script></body></html>\n")


def provenance(report: view.Report) -> list[str]:
    """Where the figures come from: the store, the code, and every machine that measured them."""
    code = f"brdfbench {esc(', '.join(report.versions))} (git {esc(', '.join(report.git_shas))})"
    items = [f"<dt>Store</dt><dd><code>{esc(report.source)}</code>, read {esc(report.generated)}</dd>",
             f"<dt>Code</dt><dd>{code}</dd>"]
    for h in report.hosts:
        gpu = f"GPU {h.gpu}" if h.gpu else "no GPU"
        soft = h.platform or "platform not recorded"
        if h.platform and not h.torch:
            soft += "; torch version not recorded"
        items.append(f"<dt>Machine</dt><dd><b>{esc(h.host)}</b>: {esc(h.cpu_model or 'CPU model not recorded')}, "
                     f"{h.cores} cores, {h.threads} threads, {esc(gpu)}; {esc(soft)} "
                     f'<span class="meta">({h.cells} rows)</span></dd>')
    speed = ' (<a href="#machine-speed">machine speed</a>)' if report.machines else ""
    items.append("<dt>Timings</dt><dd>from the machine that ran each cell: compare them between cells of one "
                 f"machine{speed}</dd>")
    return [f'<dl class="provenance">{"".join(items)}</dl>']


def _fill_drilldowns(body: list[str], report: view.Report, drills: dict) -> list[str]:
    """Put each section's heat map at its mark, linking to the figures the page holds."""
    import re

    ids = set(re.findall(r'\bid="([^"]+)"', "".join(body)))
    sections = {f"s{i}": s for i, s in enumerate(report.sections)}

    def links_for(sid: str):
        me = sections[sid]
        kin = [k for k, s in sections.items() if getattr(s, "kind", "") == "table" and s.dataset == me.dataset
               and s.fingerprint == me.fingerprint]

        def links(material: str) -> dict[str, str]:
            out = {}
            for kind in ("lobe", "render"):
                for k in [sid, *kin]:
                    target = anchor(k, kind, material)
                    if target in ids:
                        out[kind] = f"#{target}"
                        break
            return out
        return links

    out = []
    for part in body:
        for sid, d in drills.items():
            mark = DRILLDOWN_MARK.format(sid=sid)
            if mark in part:
                part = part.replace(mark, "".join(drilldown_html.heatmap(d, sid, links_for(sid))))
        out.append(part)
    return out


def machine_section(speeds: list) -> list[str]:
    """The machine-speed table (see `machines.MachineSpeed`), or nothing for a store without one."""
    if not speeds:
        return []
    head = "".join(th(t, cls="label") for t in ("host", "CPU", "device")) + "".join(
        th(t) for t in ("threads", "runs", "GFLOP/s ↑ (median)", "slowest run", "fastest run"))
    rows = "".join(f'<tr><td class="label">{esc(m.host)}</td><td class="label">{esc(m.cpu_model)}</td>'
                   f'<td class="label">{esc(m.device)}</td><td>{m.threads}</td><td>{m.runs}</td>'
                   f'<td>{number(m.median)}</td><td>{number(m.low)}</td><td>{number(m.high)}</td></tr>'
                   for m in speeds)
    return ['<h2 id="machine-speed">Machine speed</h2>', f'<p class="note">{esc(machines.MACHINE_NOTE)}</p>',
            f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table></div>']


def render(df: pd.DataFrame, source: str, results_dir: Path | None = None) -> str:
    """The page of a store's rows (`Store.frame()`); with `results_dir`, the figures of
    the files its cells left there (lobes, renders and their error maps)."""
    report = view.build(df, source)
    svgs = {name: svg(fig, name) for name, fig in plots_module.convergence_figures(df).items()}
    extra = [] if report.empty else [*published_fits_render.html_section(published_fits_view.build(df)),
                                     *published_render.published_section(report)]
    return render_view(report, svgs, extra, results_dir)


def html_report(df: pd.DataFrame, results_dir: Path, source: str) -> list[Path]:
    """The `html` report plugin: write `leaderboard.html` into `results_dir`, atomically."""
    page = results_dir / "leaderboard.html"
    text = render(df, source, results_dir)
    with replacing(page) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return [page]
