"""Polar lobe plots drawn as SVG markup directly: half-disk panels (the outgoing angle θo
from −90° to 90°, 0 at the top, positive to the right) with a log radius in decades above
a floor. Written by hand rather than with matplotlib because a report draws one per
material and configuration section, and matplotlib's polar axes dominated the report's
cost; the markup is small and the series keep stable ids for the page's legend toggles.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import numpy as np

from .svg_plot import colour

PANEL_W, PANEL_H = 272.0, 168.0
RADIUS = 108.0  # pixels of the outermost decade
TITLE_H = 18.0


def _path(theta: np.ndarray, r: np.ndarray, rmax: float, cx: float, cy: float) -> str:
    """`d` of a polyline through finite points, broken where a value is missing."""
    scale = RADIUS / rmax
    x = cx + scale * r * np.sin(theta)
    y = cy - scale * r * np.cos(theta)
    parts, pen_down = [], False
    for xi, yi in zip(x.tolist(), y.tolist()):
        if not (math.isfinite(xi) and math.isfinite(yi)):
            pen_down = False
            continue
        parts.append(f"{'L' if pen_down else 'M'}{xi:.1f},{yi:.1f}")
        pen_down = True
    return " ".join(parts)


def _arc(radius: float, cx: float, cy: float) -> str:
    return f"M{cx - radius:.1f},{cy:.1f} A{radius:.1f},{radius:.1f} 0 0 1 {cx + radius:.1f},{cy:.1f}"


def lobe_panels(theta_i_deg: Sequence[float], theta_o: np.ndarray, table: Sequence[np.ndarray],
                models: dict[int, Sequence[np.ndarray]], plot_id: str, floor_exponent: int) -> str:
    """One SVG of len(theta_i_deg) panels. `table[j]` and `models[k][j]` are radial
    coordinates (decades above the floor, NaN for none) at the angles `theta_o` (rad) for
    incident inclination j; series k is drawn in colour k with the id `{plot_id}-s{k}-{j}`,
    the table in black as `{plot_id}-table-{j}`."""
    curves = [np.asarray(c, dtype=float) for c in table] + [np.asarray(c, dtype=float)
                                                              for s in models.values() for c in s]
    top = max([float(np.nanmax(c)) for c in curves if np.isfinite(c).any()] + [1.0])
    decades = int(math.ceil(top))
    rmax = float(decades)
    step = max(1, (decades + 1) // 3)  # three radial labels at most
    width = PANEL_W * len(theta_i_deg)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width:.0f} {PANEL_H:.0f}" '
           f'width="{width:.0f}" height="{PANEL_H:.0f}" font-family="sans-serif" role="img">']
    for j, ti in enumerate(theta_i_deg):
        cx, cy = PANEL_W * j + PANEL_W / 2, TITLE_H + RADIUS + 18.0
        out.append(f'<text x="{cx:.1f}" y="12" font-size="10" text-anchor="middle">'
                   f'{html.escape(f"θi = {ti:g}° (dotted: incident)")}</text>')
        grid = [_arc(RADIUS * d / rmax, cx, cy) for d in range(1, decades + 1)]
        for a in range(-90, 91, 30):
            t = math.radians(a)
            grid.append(f"M{cx:.1f},{cy:.1f} L{cx + RADIUS * math.sin(t):.1f},{cy - RADIUS * math.cos(t):.1f}")
        out.append(f'<path d="{" ".join(grid)}" fill="none" stroke="#cccccc" stroke-width="0.6"/>')
        for a in range(-90, 91, 30):
            t = math.radians(a)
            lx, ly = cx + (RADIUS + 10) * math.sin(t), cy - (RADIUS + 10) * math.cos(t) + 3
            anchor = "middle" if abs(a) < 90 else ("start" if a > 0 else "end")
            if abs(a) == 90:  # beside the baseline, clear of the radial labels below it
                lx, ly = cx + math.copysign(RADIUS + 3, a), cy + 3
            out.append(f'<text x="{lx:.1f}" y="{ly:.1f}" font-size="8" text-anchor="{anchor}">{a}°</text>')
        for d in range(0, decades + 1, step):
            out.append(f'<text x="{cx + 2 + RADIUS * d / rmax:.1f}" y="{cy + 10:.1f}" font-size="7">'
                       f"1e{floor_exponent + d}</text>")
        t_in = -math.radians(ti)
        out.append(f'<path d="M{cx:.1f},{cy:.1f} L{cx + RADIUS * math.sin(t_in):.1f},'
                   f'{cy - RADIUS * math.cos(t_in):.1f}" stroke="#808080" stroke-width="0.8" '
                   'stroke-dasharray="1.5,2" fill="none"/>')
        out.append(f'<g id="{plot_id}-table-{j}"><path d="{_path(theta_o, np.asarray(table[j], float), rmax, cx, cy)}" '
                   'fill="none" stroke="#000000" stroke-width="1.6"/></g>')
        for k, series in models.items():
            out.append(f'<g id="{plot_id}-s{k}-{j}"><path d="{_path(theta_o, np.asarray(series[j], float), rmax, cx, cy)}'
                       f'" fill="none" stroke="{colour(k)}" stroke-width="1.0"/></g>')
    out.append("</svg>")
    return "".join(out)
