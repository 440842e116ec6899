"""The figures of a table section's cells as HTML: lobe slices and renders with error maps."""

from __future__ import annotations

from pathlib import Path

from . import cell_figures, svg_plot
from .html_parts import esc, span
from .view import TableSection


def lobes(s: TableSection, sid: str, results_dir: Path) -> list[str]:
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
                         f'<span class="swatch" style="background:{svg_plot.colour(k)}"></span>{esc(r.label)}</label>'
                         for k, r in zip(f.series, series))
        out += [f"<h3><code>{esc(f.material)}</code></h3>", f'<div class="legend">{legend}</div>',
                f'<div class="plot" id="{plot_id}">{f.svg}</div>']
        if f.missing:
            out.append(f'<p class="note">No slices saved for: {esc(", ".join(f.missing))}.</p>')
    return out


def img(path: str | None, alt: str) -> str:
    if path is None:
        return f'<span class="missing">{esc(alt)}: –</span>'
    return f'<img src="{esc(Path(path).as_posix())}" alt="{esc(alt)}" width="160">'


def images(s: TableSection, sid: str, results_dir: Path) -> list[str]:
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
        cells = [f'<td class="label"><figure>{img(r.reference, "reference")}<figcaption>reference</figcaption>'
                 "</figure></td>"]
        for c in r.cells:
            inner = "".join(img(p, what) for p, what in ((c.image, c.label), (c.flip, "FLIP map"),
                                                           (c.relative, "relative error")))
            cells.append(f'<td class="label"><figure>{inner}<figcaption><code>{esc(c.label)}</code>'
                         f'{span(c.note)}</figcaption></figure></td>')
        out.append(f'<div class="scroll"><table class="images"><caption><code>{esc(r.material)}</code>: '
                   f"{esc(r.caption)}</caption><tr>{''.join(cells)}</tr></table></div>")
    return out
