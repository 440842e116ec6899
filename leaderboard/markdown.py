"""The Markdown leaderboard: the report's view (`view.build`) as text, accuracy beside its cost."""

from __future__ import annotations

from collections.abc import Collection

import pandas as pd

from . import drilldown, generation_render, machines, plots as plots_module, published_fits_render, view
from .published_markdown import published_markdown
from .units import fmt
from .view import Cell, ConvergenceSection, Metric, TableSection
from . import published_fits_view

#: Marks a timing measured while other brdfbench jobs ran on the same host.
CONTENDED = "†"
ON_GPU = "‡"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return lines


def cell_text(cell: Cell | None, metric: Metric | None = None) -> str:
    """The cell's figure; an incomplete one as "–" with its partial figure and what is missing."""
    if cell is None:
        return "–"
    timed = metric is not None and metric.timed
    mark = (CONTENDED if timed and cell.contended else "") + (ON_GPU if timed and cell.accelerator else "")
    show = metric.show if metric is not None else fmt
    if cell.complete:
        return show(cell.value) + mark
    if cell.partial is None:
        return "–"
    return f"– ({show(cell.partial)}{mark} over {cell.n}/{cell.expected})"


def _interval(cell: Cell | None) -> str:
    if cell is None or cell.lo is None:
        return "–"
    return f"[{fmt(cell.lo)}, {fmt(cell.hi)}]"


def _header(metric: Metric) -> str:
    return f"{metric.short_label} {metric.arrow}".rstrip()


def table_section(s: TableSection) -> list[str]:
    heading = f"## Dataset `{s.dataset}`" + ("" if s.scene == "brdf_space" else f", rendered scene `{s.scene}`")
    lines = [heading, "", f"{len(s.materials)} materials, fingerprint `{s.fingerprint}`.", ""]
    if s.scene != "brdf_space":
        lines += ["> Image metrics compare each representation's render with the render of the material's own "
                  "table (nearest-cell lookup) through the same simulator and random numbers.", ""]
    if s.caveat:
        lines += [f"> {s.caveat}", ""]
    if s.primary is None:
        return lines + ["No successful results yet.", ""] + _failures(s.failures)
    header = ["rank", "representation", *[_header(m) for m in s.accuracy], *[_header(m) for m in s.costs], "materials"]
    rows: dict[bool, list[list[str]]] = {True: [], False: []}
    for row in s.rows:
        cells = ["ref." if row.reference else (str(row.rank) if row.rank is not None else "–"), f"`{row.label}`"]
        cells += [cell_text(row.cell(m.name), m) for m in [*s.accuracy, *s.costs]]
        primary = row.cell(s.primary.name)
        cells.append(f"{primary.n if primary else 0}/{len(s.materials)}")
        rows[row.reference].append(cells)
    reference = []
    if rows[True]:
        reference = ["**Reference** (the target scored against itself: what a perfect model would score; never "
                     "ranked):", "", *_table(header, rows[True]), "", "**Ranking:**", ""]
    lines += [
        "### Accuracy and its cost",
        "",
        f"Ranked by mean `{s.primary.name}` over materials. Accuracy columns are means over materials; fit time is "
        "the mean per material (amortised over the materials fitted together, for batched fitters, and over the fits "
        "run side by side, one per process, for single-threaded ones), evals/s and "
        "bytes the median. Representations that train on a split (train time, "
        "shared bytes) are cross-validated: each material is scored by a model trained without it. "
        "↓ lower is better, ↑ higher is better. A configuration without a figure for every material has no mean "
        "(shown as – with the partial mean over the materials it has) and is not ranked. Byte counts use "
        "1 kB = 1000 B.",
        "",
        *reference,
        *(_table(header, rows[False]) if rows[False] else ["No configuration to rank beside the reference yet."]),
        "",
        *_hardest(s),
        *([f"{CONTENDED} measured while other brdfbench jobs ran on the same host: timings are not comparable "
           "with unmarked ones.", ""] if s.contended else []),
        *([f"{ON_GPU} computed on a GPU ({', '.join(s.accelerators)}): these timings are not comparable with CPU "
           "ones.", ""] if s.accelerators else []),
        *([f"{', '.join(f'`{b}`' for b in s.brief)}: {view.BRIEF_NOTE}.", ""] if s.brief else []),
        "### Per metric",
        "",
    ]
    for metric in s.accuracy:
        ranked = s.ranking(metric.name)
        lines += [f"#### `{metric.name}` ({metric.unit or 'unitless'}, "
                  f"{'higher' if metric.higher_is_better else 'lower'} is better)", ""]
        table_rows = []
        rank = 0
        for row in (r for r in ranked if r.cell(metric.name) is not None):
            c = row.cell(metric.name)
            rank += 1 if c.complete and not row.reference else 0
            shown_rank = "ref." if row.reference else (str(rank) if c.complete else "–")
            table_rows.append([shown_rank, f"`{row.label}`", cell_text(c), _interval(c),
                               fmt(c.median), fmt(c.worst), str(c.n)])
        lines += _table(["rank", "representation", "mean", f"{view.CONFIDENCE:.0%} interval", "median", "worst",
                         "materials"], table_rows)
        lines.append("")
    if s.categories:
        lines += [f"### `{s.primary.name}` per category", ""]
        header = ["representation", *[f"{c.name} ({c.materials})" for c in s.categories]]
        lines += _table(header, [[f"`{row.label}`", *[cell_text(c.cells.get(row.config_hash)) for c in s.categories]]
                                 for row in s.rows])
        lines.append("")
    if s.sharpness is not None:
        split = s.sharpness
        header = ["representation"]
        for m in split.metrics:
            header += [f"{m.name} {m.arrow} sharpest ({len(split.sharpest)})", f"{m.name} {m.arrow} rest ({split.rest})"]
        lines += ["### The sharpest tenth of the targets", "", sharpness_caption(split), ""]
        lines += _table(header, [[f"`{row.label}`", *[cell_text(split.cells.get((row.config_hash, m.name, part)))
                                                      for m in split.metrics for part in (True, False)]]
                                 for row in s.rows])
        lines.append("")
    return lines + _failures(s.failures)


def _hardest(s: TableSection) -> list[str]:
    """The per-material drill-down in one paragraph (the HTML page has its heat map)."""
    d = drilldown.build(s)
    return [] if d is None else [drilldown.summary(d), ""]


def sharpness_caption(split: view.Split) -> str:
    named = ", ".join(f"{m} ({split.widths[m]:.3g} rad)" for m in split.sharpest)
    return (f"Means over the {len(split.sharpest)} materials whose target has the narrowest specular lobe "
            f"and over the other {split.rest}. Width: the lobe half-width of Zhou et al. (C.3), the θh at which "
            f"max over channels of f(θh, θd = 0, φd = 0) first halves, on the target's table. "
            f"The sharpest: {named}.")


def convergence_section(s: ConvergenceSection, plots: Collection[str] = ()) -> list[str]:
    """Mean RMSE per spp rung per representation for one (dataset, scene, sampler)."""
    lines = [f"## Dataset `{s.dataset}`, convergence on `{s.scene}`, sampler `{s.sampler}`", "",
             f"{len(s.materials)} materials, fingerprint `{s.fingerprint}`.", "",
             "> Monte Carlo noise only: each representation's render at n spp against its own high-spp render "
             "(same model, independent random numbers), so the error measures how well the sampler suits the "
             "representation. Columns: mean RMSE of HDR radiance over materials (↓); the slope of log RMSE on "
             "log spp (−0.5 for an unbiased estimator; flatter when rare fireflies dominate); the RMSE at 1 spp "
             "implied by the 1/√spp law over all rungs (↓); the mean render time at the top rung.", ""]
    if not s.rows:
        lines += ["No successful results yet.", ""]
    else:
        top = s.ladder[-1]
        header = ["representation", *[f"{n} spp" for n in s.ladder], "slope", "RMSE at 1 spp (fit) ↓",
                  f"render time at {top} spp (s) ↓", "materials"]
        rows = []
        for r in s.rows:
            cells = [f"`{r.label}`", *[fmt(view.shown(r.rmse.get(n))) for n in s.ladder]]
            cells += [fmt(view.shown(r.slope)), fmt(view.shown(r.rmse_1spp)), fmt(view.shown(r.render_time.get(top)))]
            cells.append(str(max(c.n for c in r.rmse.values())))
            rows.append(cells)
        lines += ["### Error against spp", "", *_table(header, rows), ""]
    plot = plots_module.convergence_plot_name(s.dataset, s.fingerprint, s.scene)
    if plot in plots:
        lines += [f"![RMSE against spp and render time, every sampler on `{s.scene}`]({plot})", ""]
    return lines + _failures(s.failures)


def _failures(failures: list[view.Failure]) -> list[str]:
    """The unresolved failures of a section, or nothing."""
    if not failures:
        return []
    lines = ["### Failures", ""]
    lines += _table(["representation", "material", "error"],
                    [[f"`{f.label}`", f.material, f.message.replace("|", "\\|")[:200]] for f in failures])
    return lines + [""]


def render_view(report: view.Report, plots: Collection[str] = (), fits=None) -> str:
    """The text of `report`; `fits` (`published_fits_view.build`) adds "Published fits against our fits"."""
    lines = ["# brdfbench leaderboard", "", f"Generated {report.generated} from `{report.source}`.", ""]
    if report.empty:
        return "\n".join(lines + ["The results store is empty.", ""])
    lines += [f"brdfbench {', '.join(report.versions)}; git {', '.join(report.git_shas)}. "
              "Timings are from the machine that ran each cell:", ""]
    lines += [f"- {line}" for line in host_lines(report.hosts)] + [""]

    for s in report.sections:
        if isinstance(s, ConvergenceSection):
            lines += convergence_section(s, plots)
        elif getattr(s, "kind", "") == "generation":
            lines += generation_render.markdown(s)
        else:
            lines += table_section(s)
    lines += published_fits_render.markdown(fits)
    lines += published_markdown(report)
    lines += machine_section(report.machines)
    return "\n".join(lines)


def host_lines(hosts: list) -> list[str]:
    """One line per machine that produced figures (`machines.Host`)."""
    out = []
    for h in hosts:
        soft = h.platform or "platform not recorded"
        if h.platform and not h.torch:
            soft += "; torch version not recorded"
        out.append(f"{h.host}: {h.cpu_model or 'CPU model not recorded'}, {h.cores} cores, {h.threads} threads, "
                   f"{'GPU ' + h.gpu if h.gpu else 'no GPU'}; {soft} ({h.cells} rows)")
    return out


def machine_section(speeds: list) -> list[str]:
    """The machine-speed table (see `machines.MachineSpeed`), or nothing for a store without one."""
    if not speeds:
        return []
    lines = ["## Machine speed", "", machines.MACHINE_NOTE, ""]
    lines += _table(["host", "CPU", "device", "threads", "runs", "GFLOP/s ↑ (median)", "slowest run", "fastest run"],
                    [[m.host, m.cpu_model, m.device, str(m.threads), str(m.runs), fmt(m.median), fmt(m.low), fmt(m.high)]
                     for m in speeds])
    return lines + [""]


def render(df: pd.DataFrame, source: str, plots: Collection[str] = ()) -> str:
    """The leaderboard text; `plots` names the figure files written beside it (linked from their sections)."""
    return render_view(view.build(df, source), plots, published_fits_view.build(df))
