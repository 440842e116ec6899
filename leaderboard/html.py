"""The HTML report: the report's view (`view.build`) as one self-contained page.

`leaderboard.html` opens from a file with no server and no network: styles, the sorting
script and every plot (inline SVG) are inside it; rendered images are linked by relative
path beside it. Tables sort by a click on their header; a plot's legend toggles its series.
"""

from __future__ import annotations

import html
import io
from importlib import resources
from pathlib import Path

import pandas as pd

from . import cell_figures, generation_render, pareto, published, svg_plot, view
from . import plots as plots_module
from .markdown import fmt, sharpness_caption
from .view import Cell, ConvergenceSection, Metric, TableSection

CONTENDED = "†"
ON_GPU = "‡"


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _asset(name: str) -> str:
    return resources.files("brdfbench_leaderboard").joinpath("assets", name).read_text(encoding="utf-8")


def svg(fig, salt: str) -> str:
    """A figure as inline SVG markup; `salt` keeps its internal ids apart from other figures'."""
    import matplotlib

    buf = io.StringIO()
    with matplotlib.rc_context({"svg.hashsalt": salt, "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _number(value: float | None) -> str:
    return "" if value is None else repr(float(value))


def _cell(c: Cell | None, metric: Metric, best: bool = False) -> str:
    if c is None:
        return '<td class="missing" data-sort="" title="no figure">–</td>'
    mark = (CONTENDED if metric.timed and c.contended else "") + (ON_GPU if metric.timed and c.accelerator else "")
    detail = f"median {fmt(c.median)}, worst {fmt(c.worst)}, {c.n}/{c.expected} materials"
    if metric.timed and c.accelerator:
        detail += f"; measured on a GPU ({c.accelerator})"
    if not c.complete:
        partial = f"partial {metric.aggregate} {fmt(c.partial)} over {c.n}/{c.expected} materials"
        return (f'<td class="missing" data-sort="" title="{_e(partial)}">–'
                f'<span class="ci">{c.missing} missing</span></td>')
    ci = f'<span class="ci">[{fmt(c.lo)}, {fmt(c.hi)}]</span>' if c.lo is not None else ""
    cls = ' class="best"' if best else ""
    return f'<td{cls} data-sort="{_number(c.value)}" title="{_e(detail)}">{_e(fmt(c.value) + mark)}{ci}</td>'


def _best(section: TableSection, metric: Metric) -> str | None:
    """The config hash with the best complete figure of a directed metric."""
    if not metric.directed:
        return None
    ranked = section.timing_peers(metric.name)
    if ranked and ranked[0].cell(metric.name) is not None and ranked[0].cell(metric.name).complete:
        return ranked[0].config_hash
    return None


def _span(text: str) -> str:
    return f'<span class="ci">{_e(text)}</span>' if text else ""


def _th(text: str, title: str = "", cls: str = "") -> str:
    attrs = (f' class="{cls}"' if cls else "") + (f' title="{_e(title)}"' if title else "")
    return f"<th{attrs}>{_e(text)}</th>"


def _header(metric: Metric) -> str:
    title = f"{metric.name}: {metric.unit or 'unitless'}"
    if metric.directed:
        title += f", {'higher' if metric.higher_is_better else 'lower'} is better"
    if metric.kind == "accuracy":
        title += f"; mean over materials, {view.CONFIDENCE:.0%} bootstrap interval below"
    else:
        title += f"; {metric.aggregate} over materials"
    unit = "" if metric.kind == "cost" and "(" in metric.label else (metric.unit or "unitless")
    attrs = f' title="{_e(title)}"'
    return f"<th{attrs}>{_e(f'{metric.label} {metric.arrow}'.rstrip())}{_span(unit)}</th>"


def _legend(plot_id: str, series) -> str:
    items = []
    for k, row in enumerate(series):
        items.append(f'<label><input type="checkbox" checked data-series="{plot_id}-s{k}-">'
                     f'<span class="swatch" style="background:{svg_plot.colour(k)}"></span>{_e(row.label)}</label>')
    return f'<div class="legend">{"".join(items)}</div>'


def table_section(s: TableSection, sid: str, results_dir: Path | None = None) -> list[str]:
    where = "" if s.scene == "brdf_space" else f", rendered scene <code>{_e(s.scene)}</code>"
    out = [f'<h2 id="{sid}">Dataset <code>{_e(s.dataset)}</code>{where}</h2>',
           f'<p class="meta">{len(s.materials)} materials, fingerprint <code>{_e(s.fingerprint)}</code>, '
           f"harness <code>{_e(s.harness)}</code>.</p>"]
    if s.scene != "brdf_space":
        out.append("<blockquote>Image metrics compare each representation's render with the render of the "
                   "material's own table (nearest-cell lookup) through the same simulator and random numbers."
                   "</blockquote>")
    if s.caveat:
        out.append(f"<blockquote>{_e(s.caveat)}</blockquote>")
    if s.primary is None:
        return out + ["<p>No successful results yet.</p>", *_failures(s.failures)]
    metrics = [*s.accuracy, *s.costs]
    best = {m.name: _best(s, m) for m in metrics}
    head = [_th("rank"), _th("representation", cls="label"), *[_header(m) for m in metrics],
            _th("materials", f"materials with a {s.primary.name} figure")]
    body = []
    for row in s.rows:
        primary = row.cell(s.primary.name)
        cells = [f'<td data-sort="{row.rank if row.rank is not None else ""}">'
                 f'{row.rank if row.rank is not None else "–"}</td>',
                 f'<td class="label"><code>{_e(row.label)}</code></td>']
        cells += [_cell(row.cell(m.name), m, best[m.name] == row.config_hash) for m in metrics]
        cells.append(f"<td>{primary.n if primary else 0}/{len(s.materials)}</td>")
        body.append(f"<tr>{''.join(cells)}</tr>")
    out += ["<h3>Accuracy and its cost</h3>",
            f'<p class="note">Ranked by mean <code>{_e(s.primary.name)}</code> over materials; below each mean its '
            f"{view.CONFIDENCE:.0%} bootstrap interval over materials ({view.BOOTSTRAP_RESAMPLES} resamples). Fit time "
            "is the mean per material (amortised over the materials fitted together, for batched fitters); evals/s "
            "and bytes the median. A configuration without a figure for every material has no mean (its partial "
            "one is in the cell's tooltip) and is not ranked. Click a header to sort; hover a cell for median and "
            "worst case.</p>",
            f'<div class="scroll"><table class="sortable" id="{sid}-table"><thead><tr>{"".join(head)}</tr></thead>'
            f"<tbody>{''.join(body)}</tbody></table></div>"]
    if s.contended:
        out.append(f'<p class="note">{CONTENDED} measured while other brdfbench jobs ran on the same host: timings '
                   "are not comparable with unmarked ones.</p>")
    if s.brief:
        note = view.BRIEF_NOTE.replace("`brdfbench`", "<code>brdfbench</code>").replace(
            "`brdfbench profile=full`", "<code>brdfbench profile=full</code>")
        out.append(f'<p class="note">{", ".join(f"<code>{_e(b)}</code>" for b in s.brief)}: {note}.</p>')
    if s.accelerators:
        out.append(f'<p class="note">{ON_GPU} computed on a GPU ({_e(", ".join(s.accelerators))}): these timings are '
                   "not comparable with CPU ones, and a column that holds both marks its best among the CPU "
                   "figures.</p>")
    out += _chart(s, sid)
    if results_dir is not None and s.harness == "accuracy":
        out += _lobes(s, sid, results_dir)
    if results_dir is not None and s.scene != "brdf_space":
        out += _images(s, sid, results_dir)
    out += _per_metric(s, sid)
    out += _categories(s, sid)
    out += _sharpness(s, sid)
    return out + _failures(s.failures)


def _lobes(s: TableSection, sid: str, results_dir: Path) -> list[str]:
    figures = cell_figures.lobe_figures(s, results_dir, s.material_categories, f"{sid}-lobe")
    if not figures:
        return []
    out = ["<h3>Lobes: in-plane slices</h3>",
           '<p class="note">Luminance of the BRDF in the plane of incidence at fixed incident inclinations θi, '
           "against the outgoing angle (positive: the mirror side), log radial scale from "
           f"{cell_figures.LOBE_FLOOR:g} 1/sr; black: the material's table (nearest cell, as the reference "
           "reader), colours: each configuration. Untick a series to hide it.</p>"]
    for i, f in enumerate(figures):
        plot_id = f"{sid}-lobe-{i}"
        series = [s.rows[k] for k in f.series]
        legend = "".join(f'<label><input type="checkbox" checked data-series="{plot_id}-s{k}-">'
                         f'<span class="swatch" style="background:{svg_plot.colour(k)}"></span>{_e(r.label)}</label>'
                         for k, r in zip(f.series, series))
        out += [f"<h3><code>{_e(f.material)}</code></h3>", f'<div class="legend">{legend}</div>',
                f'<div class="plot" id="{plot_id}">{f.svg}</div>']
        if f.missing:
            out.append(f'<p class="note">No slices saved for: {_e(", ".join(f.missing))}.</p>')
    return out


def _img(path: str | None, alt: str) -> str:
    if path is None:
        return f'<span class="missing">{_e(alt)}: –</span>'
    return f'<img src="{_e(Path(path).as_posix())}" alt="{_e(alt)}" width="160">'


def _images(s: TableSection, sid: str, results_dir: Path) -> list[str]:
    rows = cell_figures.image_rows(s, results_dir, s.material_categories)
    if not rows:
        return []
    out = ["<h3>Renders and error maps</h3>",
           '<p class="note">Per material: the render of its table (reference), then each configuration\'s render, '
           "its FLIP map (LDR-FLIP, 0 black to 1 bright) and its relative error in luminance (0 black to "
           f"{cell_figures.REL_ERROR_MAX:.0%} or more bright). Monte Carlo renders keep their noise: a low spp or a "
           "sampler that does not suit the material shows grain in both images and in the maps; for converged "
           "images run with a higher <code>harness.spp</code> or <code>harness.sampler</code> suited to the "
           "material.</p>"]
    for r in rows:
        cells = [f'<td class="label"><figure>{_img(r.reference, "reference")}<figcaption>reference</figcaption>'
                 "</figure></td>"]
        for c in r.cells:
            inner = "".join(_img(p, what) for p, what in ((c.image, c.label), (c.flip, "FLIP map"),
                                                           (c.relative, "relative error")))
            cells.append(f'<td class="label"><figure>{inner}<figcaption><code>{_e(c.label)}</code>'
                         f'{_span(c.note)}</figcaption></figure></td>')
        out.append(f'<div class="scroll"><table class="images"><caption><code>{_e(r.material)}</code>: '
                   f"{_e(r.caption)}</caption><tr>{''.join(cells)}</tr></table></div>")
    return out


def _chart(s: TableSection, sid: str) -> list[str]:
    c = pareto.chart(s)
    if c is None:
        return []
    plot_id = f"{sid}-pareto"
    omitted = sorted({label for p in c.panels for label in p.omitted})
    return ["<h3>Accuracy against cost</h3>",
            f'<p class="note">Mean <code>{_e(c.primary.name)}</code> against each cost, log axes; error bars are the '
            f"{view.CONFIDENCE:.0%} intervals; the dashed line is the Pareto front (no configuration beats a point on "
            "it on both axes); a thin line joins one plugin's configurations in order of size. Untick a series to "
            "hide it.</p>",
            _legend(plot_id, c.series),
            f'<div class="plot" id="{plot_id}">{pareto.figure(c, plot_id)}</div>',
            *([f'<p class="note">Not plotted (a figure missing or not positive): '
               f'{_e(", ".join(omitted))}.</p>'] if omitted else [])]


def _per_metric(s: TableSection, sid: str) -> list[str]:
    out = ["<details><summary>Per metric: mean, interval, median, worst case</summary>"]
    for m in s.accuracy:
        rows = []
        rank = 0
        for row in s.ranking(m.name):
            c = row.cell(m.name)
            if c is None:
                continue
            rank += 1 if c.complete else 0
            rows.append(f'<tr><td>{rank if c.complete else "–"}</td><td class="label"><code>{_e(row.label)}</code></td>'
                        f'{_cell(c, m)}<td data-sort="{_number(c.median)}">{fmt(c.median)}</td>'
                        f'<td data-sort="{_number(c.worst)}">{fmt(c.worst)}</td><td>{c.n}</td></tr>')
        out += [f"<h3><code>{_e(m.name)}</code> ({_e(m.unit or 'unitless')}, "
                f"{'higher' if m.higher_is_better else 'lower'} is better)</h3>",
                f'<table class="sortable" id="{sid}-{_e(m.name)}"><thead><tr>{_th("rank")}'
                f'{_th("representation", cls="label")}{_th("mean")}{_th("median")}{_th("worst")}{_th("materials")}'
                f"</tr></thead><tbody>{''.join(rows)}</tbody></table>"]
    return out + ["</details>"]


def _categories(s: TableSection, sid: str) -> list[str]:
    if not s.categories:
        return []
    head = [_th("representation", cls="label"), *[_th(f"{c.name} ({c.materials})") for c in s.categories]]
    body = []
    for row in s.rows:
        cells = [f'<td class="label"><code>{_e(row.label)}</code></td>']
        cells += [_cell(c.cells.get(row.config_hash), s.primary) for c in s.categories]
        body.append(f"<tr>{''.join(cells)}</tr>")
    return [f"<h3>Mean <code>{_e(s.primary.name)}</code> per category</h3>",
            f'<div class="scroll"><table class="sortable" id="{sid}-categories"><thead><tr>{"".join(head)}</tr>'
            f"</thead><tbody>{''.join(body)}</tbody></table></div>"]


def _sharpness(s: TableSection, sid: str) -> list[str]:
    split = s.sharpness
    if split is None:
        return []
    head = [_th("representation", cls="label")]
    for m in split.metrics:
        head += [_th(f"{m.name} {m.arrow}, sharpest ({len(split.sharpest)})"), _th(f"{m.name} {m.arrow}, rest ({split.rest})")]
    body = []
    for row in s.rows:
        cells = [f'<td class="label"><code>{_e(row.label)}</code></td>']
        for m in split.metrics:
            cells += [_cell(split.cells.get((row.config_hash, m.name, part)), m) for part in (True, False)]
        body.append(f"<tr>{''.join(cells)}</tr>")
    return ["<h3>The sharpest tenth of the targets</h3>", f'<p class="note">{_e(sharpness_caption(split))}</p>',
            f'<div class="scroll"><table class="sortable" id="{sid}-sharpest"><thead><tr>{"".join(head)}</tr>'
            f"</thead><tbody>{''.join(body)}</tbody></table></div>"]


def convergence_section(s: ConvergenceSection, sid: str, figure_svg: str | None) -> list[str]:
    out = [f'<h2 id="{sid}">Dataset <code>{_e(s.dataset)}</code>, convergence on <code>{_e(s.scene)}</code>, '
           f"sampler <code>{_e(s.sampler)}</code></h2>",
           f'<p class="meta">{len(s.materials)} materials, fingerprint <code>{_e(s.fingerprint)}</code>.</p>',
           "<blockquote>Monte Carlo noise only: each representation's render at n spp against its own high-spp "
           "render (same model, independent random numbers). Slope: of log RMSE on log spp (−0.5 for an unbiased "
           "estimator); RMSE at 1 spp: implied by the 1/√spp law over all rungs.</blockquote>"]
    if not s.rows:
        out.append("<p>No successful results yet.</p>")
    else:
        top = s.ladder[-1]
        err = Metric("rmse_hdr", "", False, "accuracy")
        cost = Metric("convergence", "", False, "cost")
        head = [_th("representation", cls="label"), *[_th(f"{n} spp") for n in s.ladder], _th("slope"),
                _th("RMSE at 1 spp (fit) ↓"), _th(f"render time at {top} spp (s) ↓")]
        body = []
        for r in s.rows:
            cells = [f'<td class="label"><code>{_e(r.label)}</code></td>']
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
    rows = "".join(f'<tr><td class="label"><code>{_e(f.label)}</code></td><td class="label">{_e(f.material)}</td>'
                   f'<td class="label">{_e(f.message[:300])}</td></tr>' for f in failures)
    return ["<h3>Failures</h3>", f'<table><thead><tr>{_th("representation", cls="label")}'
            f'{_th("material", cls="label")}{_th("error", cls="label")}</tr></thead><tbody>{rows}</tbody></table>']


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
    body = ["<h1>brdfbench leaderboard</h1>",
            f'<p class="meta">Generated {_e(report.generated)} from <code>{_e(report.source)}</code>.']
    if report.empty:
        body += ["</p>", "<p>The results store is empty: run the benchmark first.</p>"]
    else:
        body[-1] += (f" brdfbench {_e(', '.join(report.versions))}; git {_e(', '.join(report.git_shas))}. "
                     "Timings are from the machine that ran each cell.</p>")
        toc = "".join(f'<li><a href="#s{i}">{_e(_section_title(s))}</a></li>' for i, s in enumerate(report.sections))
        body.append(f"<nav><ul>{toc}</ul></nav>")
        for i, s in enumerate(report.sections):
            sid = f"s{i}"
            if isinstance(s, ConvergenceSection):
                name = plots_module.convergence_plot_name(s.dataset, s.fingerprint, s.scene)
                body += convergence_section(s, sid, convergence_svgs.pop(name, None))
            elif getattr(s, "kind", "") == "generation":
                body += generation_render.html_section(s, sid, results_dir)
            else:
                body += table_section(s, sid, results_dir)
        body += machine_section(report.machines)
    body += extra or []
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>brdfbench leaderboard</title><style>{_asset('report.css')}</style></head>"
            f"<body>{''.join(body)}<script>{_asset('report.js')}</script></body></html>\n")


def machine_section(machines: list) -> list[str]:
    """The machine-speed table (see `view.MachineSpeed`), or nothing for a store without one."""
    if not machines:
        return []
    head = "".join(_th(t, cls="label") for t in ("host", "CPU", "device")) + "".join(
        _th(t) for t in ("threads", "runs", "GFLOP/s ↑ (median)", "slowest run", "fastest run"))
    rows = "".join(f'<tr><td class="label">{_e(m.host)}</td><td class="label">{_e(m.cpu_model)}</td>'
                   f'<td class="label">{_e(m.device)}</td><td>{m.threads}</td><td>{m.runs}</td>'
                   f'<td>{_number(m.median)}</td><td>{_number(m.low)}</td><td>{_number(m.high)}</td></tr>'
                   for m in machines)
    return ['<h2 id="machine-speed">Machine speed</h2>', f'<p class="note">{_e(view.MACHINE_NOTE)}</p>',
            f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table></div>']


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
        return out + [f'<p class="missing">The published figures could not be read ({_e(exc)}); '
                      "this section is empty.</p>"]
    head = "".join(_th(t, cls="label" if i in (0, 1, 2, 7, 8) else "") for i, t in enumerate(
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
            f'<tr><td class="label">{_e(where)}<span class="ci">{_e(what)}'
            f'</span></td><td class="label">{_e(m.model)}</td><td class="label">{_e(m.metric)} → '
            f'<code>{_e(m.our_metric)}</code></td><td data-sort="{_number(p.value if p else None)}">{_e(theirs)}</td>'
            f'<td data-sort="{_number(c.theirs)}">{fmt(c.theirs)}</td>'
            f'<td data-sort="{_number(c.ours.value if c.ours is not None and c.ours.complete else None)}">{ours}'
            f"{_span(label)}</td>"
            f'<td class="{cls}">{_e(c.verdict)}<span class="ci">{_e(c.detail)}</span></td>'
            f'<td class="label">{_e(data)}</td><td class="label">{_e(m.setup)}</td></tr>')
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


def render(df: pd.DataFrame, source: str, results_dir: Path | None = None) -> str:
    """The page of a store's rows (`Store.frame()`); with `results_dir`, the figures of
    the files its cells left there (lobes, renders and their error maps)."""
    report = view.build(df, source)
    svgs = {name: svg(fig, name) for name, fig in plots_module.convergence_figures(df).items()}
    return render_view(report, svgs, [] if report.empty else published_section(report), results_dir)


def html_report(df: pd.DataFrame, results_dir: Path, source: str) -> list[Path]:
    """The `html` report plugin: write `leaderboard.html` into `results_dir`, atomically."""
    from brdfbench.atomic import replacing

    page = results_dir / "leaderboard.html"
    text = render(df, source, results_dir)
    with replacing(page) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return [page]
