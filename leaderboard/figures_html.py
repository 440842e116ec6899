"""The figures of a table section's cells as HTML: lobe slices as small multiples (a panel
per configuration against the table), and render grids (labelled rows, colour bars, each
render's stored figures, click to enlarge: `assets/figures.js`)."""

from __future__ import annotations

from pathlib import Path

from . import cell_figures, svg_plot
from .html_parts import anchor, esc, span
from .units import fmt
from .view import TableSection


def _primary_figure(s: TableSection, config_hash: str, material: str) -> str:
    """The section's ranking metric for one configuration and material, for a panel's title."""
    if s.primary is None:
        return ""
    value = s.per_material.get(s.primary.name, {}).get((config_hash, material))
    return "" if value is None else f"{s.primary.name} {fmt(value)}"


def _lobe_controls(fid: str, theta_i: list[float]) -> str:
    scale = "".join(f'<label><input type="radio" name="{fid}-scale" value="{v}" data-lobe-scale="{v}"'
                    f'{" checked" if v == "log" else ""}>{v}</label>' for v in ("log", "linear"))
    angles = "".join(f'<label><input type="checkbox" checked data-lobe-ti="{j}">θi = {t:g}°</label>'
                     for j, t in enumerate(theta_i))
    return (f'<div class="lobe-controls"><span>radial scale (1/sr):</span>{scale}'
            f'<span>incident inclinations:</span>{angles}</div>')


def lobes(s: TableSection, sid: str, results_dir: Path) -> list[str]:
    figures = cell_figures.lobe_figures(s, results_dir, s.material_categories, f"{sid}-lp")
    if not figures:
        return []
    refs = ", ".join(f"<code>{esc(r.label)}</code>" for r in s.references)
    ref_note = f" The reference ({refs}: the target itself) is that dashed line and has no panel." if refs else ""
    out = ["<h3>Lobes: in-plane slices</h3>",
           '<p class="note">Luminance of the BRDF in the plane of incidence at fixed incident inclinations θi '
           "(dotted rays: the incident directions), against the outgoing angle θo (positive: the mirror side). One "
           "panel per configuration, its slices in its colour; the dashed dark line on top is the material's table "
           f"(nearest cell, as the reference reader).{ref_note} The radius is in 1/sr, logarithmic from "
           f"{cell_figures.LOBE_FLOOR:g} or linear from 0, on one scale for all of a material's panels; the panel's "
           "title gives the section's ranking figure for that material.</p>"]
    for i, f in enumerate(figures):
        fid = f"{sid}-lobes{i}"
        panels = []
        for p in f.panels:
            row = s.rows[p.row]
            figure = _primary_figure(s, row.config_hash, f.material)
            panels.append(f'<figure class="plot lobe-panel"><figcaption><span class="swatch" '
                          f'style="background:{svg_plot.colour(p.row)}"></span><code>{esc(row.label)}</code>'
                          f"{span(figure)}</figcaption>{p.svg}</figure>")
        out += [f'<div class="lobes" id="{esc(anchor(sid, "lobe", f.material))}" data-lobes>',
                f"<h4><code>{esc(f.material)}</code></h4>", _lobe_controls(fid, f.theta_i_deg),
                f'<div class="lobe-grid">{"".join(panels)}</div>']
        if f.missing:
            out.append(f'<p class="note">No slices saved for: {esc(", ".join(f.missing))}.</p>')
        out.append("</div>")
    return out


def img(path: str | None, alt: str) -> str:
    if path is None:
        return f'<span class="missing">{esc(alt)}: –</span>'
    return (f'<img src="{esc(Path(path).as_posix())}" alt="{esc(alt)}" title="{esc(alt)}: click to enlarge" '
            'width="192" tabindex="0" data-enlarge>')


def colour_bar(cmap: str, ticks: list[str], title: str) -> str:
    """A horizontal colour bar of `cmap` (the colours of its maps) with `ticks` spread evenly under it."""
    stops = cell_figures.colour_stops(cmap)
    gradient = ", ".join(f"{c} {100 * i / (len(stops) - 1):.0f}%" for i, c in enumerate(stops))
    labels = "".join(f"<span>{esc(t)}</span>" for t in ticks)
    return (f'<div class="colour-bar" data-cmap="{esc(cmap)}" title="{esc(title)}">'
            f'<div class="ramp" style="background: linear-gradient(to right, {gradient})"></div>'
            f'<div class="ticks">{labels}</div></div>')


def _figures_text(s: TableSection, figures: dict[str, float]) -> str:
    parts = []
    for name in cell_figures.IMAGE_FIGURES:
        if name in figures:
            unit = s.metrics[name].unit if name in s.metrics else ""
            label = {"psnr_ldr": "PSNR", "flip_ldr": "FLIP"}.get(name, name)
            parts.append(f"{label} {fmt(figures[name])}{' ' + unit if unit and unit != '1' else ''}")
    return " · ".join(parts)


def images(s: TableSection, sid: str, results_dir: Path) -> list[str]:
    rows = cell_figures.image_rows(s, results_dir, s.material_categories)
    if not rows:
        return []
    top = cell_figures.REL_ERROR_MAX
    out = ["<h3>Renders and error maps</h3>",
           '<p class="note">Per material, one column per configuration: its render, its FLIP map (LDR-FLIP) and its '
           "relative error in luminance against the render of the material's own table (the reference column; "
           "the target itself has no column of its own). Under each render: its PSNR and FLIP as stored, for "
           "that material. The images shown are display renders (more samples per pixel, a sampler fitted to "
           "the material) wherever the caption says so; the stored metrics keep their own spp and sampler. "
           "Click an image to enlarge it (Escape or a click closes it).</p>"]
    flip_bar = colour_bar(cell_figures.FLIP_CMAP, ["0", "0.5", "1"], "LDR-FLIP, 0 (identical) to 1")
    rel_bar = colour_bar(cell_figures.RELATIVE_CMAP, ["0", f"{top / 2:.0%}", f"≥ {top:.0%}"],
                         f"|model − reference| / reference luminance, saturating at {top:.0%}")
    for r in rows:
        head = '<th></th><th class="label">reference<span class="ci">the table</span></th>' + "".join(
            f'<th class="label"><code>{esc(c.label)}</code></th>' for c in r.cells)
        renders = [f'<td>{img(r.reference, f"reference (the table), {r.material}")}</td>']
        flips, rels = ['<td class="empty"></td>'], ['<td class="empty"></td>']
        for c in r.cells:
            caption = _figures_text(s, c.figures)
            renders.append(f'<td><figure>{img(c.image, f"{c.label} render, {r.material}")}'
                           f'<figcaption>{esc(caption)}{span(c.note)}</figcaption></figure></td>')
            flips.append(f"<td>{img(c.flip, f'{c.label} FLIP map, {r.material}')}</td>")
            rels.append(f"<td>{img(c.relative, f'{c.label} relative error, {r.material}')}</td>")
        body = (f'<tr><th scope="row" class="label">render</th>{"".join(renders)}</tr>'
                f'<tr><th scope="row" class="label">FLIP map{flip_bar}</th>{"".join(flips)}</tr>'
                f'<tr><th scope="row" class="label">relative error{rel_bar}</th>{"".join(rels)}</tr>')
        out.append(f'<div class="scroll"><table class="images" id="{esc(anchor(sid, "render", r.material))}">'
                   f"<caption><code>{esc(r.material)}</code>: {esc(r.caption)}</caption>"
                   f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>")
    return out
