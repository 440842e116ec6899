"""Polar lobe plots drawn as SVG markup directly: one half-disk panel per representation
(the outgoing angle θo from −90° to 90°, 0 at the top, positive on the mirror side), every
incident inclination's slice in it, the material's table drawn last (dark, dashed) on top
of the representation's own line. Each panel carries a log radius (decades above a floor)
and a linear one (1/sr); the page shows one and swaps them (figures.js).

Written by hand rather than with matplotlib because a report draws one panel per material
and configuration, and matplotlib's polar axes dominated the report's cost; polylines are
thinned to what shows at the panel's size, so a page of many panels stays small.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import numpy as np

from .svg_plot import colour

PANEL_W, PANEL_H = 460.0, 262.0
RADIUS = 196.0  # pixels of the outermost ring
TITLE_H = 8.0  # above the rim's angle labels; the panel's title is the page's caption
FONT = 13  # tick and angle labels, px at the panel's own size
TABLE_COLOUR = "#111111"
TOLERANCE = 0.5  # px: a polyline point closer than this to the thinned line is dropped
SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def centre() -> tuple[float, float]:
    return PANEL_W / 2, TITLE_H + RADIUS + 18.0


def _degrees(a: int) -> str:
    return f"{a}°".replace("-", "−")


def decade(exponent: int) -> str:
    return "10" + str(exponent).translate(SUPERSCRIPT)


def nice_step(top: float) -> float:
    """A round ring spacing (1, 2, 2.5 or 5 times a power of ten) giving 3 to 6 rings up to `top`."""
    top = top if top > 0 and math.isfinite(top) else 1.0
    base = 10 ** math.floor(math.log10(top / 3))
    return next(m * base for m in (1, 2, 2.5, 5, 10) if top / (m * base) <= 6)


def _thin(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Ramer–Douglas–Peucker: the fewest points that stay within `TOLERANCE` of the polyline."""
    if len(points) < 3:
        return points
    keep = [False] * len(points)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        (xa, ya), (xb, yb) = points[a], points[b]
        dx, dy = xb - xa, yb - ya
        length = math.hypot(dx, dy)
        far, far_d = -1, TOLERANCE
        for i in range(a + 1, b):
            x, y = points[i]
            d = (abs(dy * (x - xa) - dx * (y - ya)) / length) if length > 0 else math.hypot(x - xa, y - ya)
            if d > far_d:
                far, far_d = i, d
        if far >= 0:
            keep[far] = True
            stack += [(a, far), (far, b)]
    return [p for p, k in zip(points, keep) if k]


def _path(theta: np.ndarray, r: np.ndarray, rmax: float, cx: float, cy: float) -> str:
    """`d` of a polyline through finite points (radius `r` of `rmax` at the rim), broken
    where a value is missing."""
    scale = RADIUS / rmax
    x = cx + scale * r * np.sin(theta)
    y = cy - scale * r * np.cos(theta)
    runs: list[list[tuple[float, float]]] = [[]]
    for xi, yi in zip(x.tolist(), y.tolist()):
        if math.isfinite(xi) and math.isfinite(yi):
            runs[-1].append((xi, yi))
        elif runs[-1]:
            runs.append([])
    parts = []
    for run in runs:
        for i, (xi, yi) in enumerate(_thin(run)):
            parts.append(f"{'L' if i else 'M'}{xi:.1f},{yi:.1f}")
    return " ".join(parts)


def _arc(radius: float, cx: float, cy: float) -> str:
    return f"M{cx - radius:.1f},{cy:.1f} A{radius:.1f},{radius:.1f} 0 0 1 {cx + radius:.1f},{cy:.1f}"


def _text(x: float, y: float, text: str, anchor: str = "middle", extra: str = "") -> str:
    return (f'<text x="{x:.1f}" y="{y:.1f}" font-size="{FONT}" text-anchor="{anchor}"{extra}>'
            f"{html.escape(text)}</text>")


def _rings(radii: list[float], labels: list[str], cls: str, cx: float, cy: float) -> list[str]:
    """Rings at `radii` (px) labelled along the baseline right of the centre (every other
    one from the centre where they would crowd); `cls` is the scale they belong to."""
    hidden = ' display="none"' if cls == "lobe-lin" else ""
    out = [f'<path class="{cls}"{hidden} d="{" ".join(_arc(r, cx, cy) for r in radii if r > 0)}" fill="none" '
           'stroke="#cfd3da" stroke-width="0.8"/>']
    gap = min((b - a for a, b in zip(radii, radii[1:])), default=RADIUS)
    every = 1 if gap >= 2.6 * FONT else 2
    shown = [(r, t) for i, (r, t) in enumerate(zip(radii, labels)) if i % every == 0]
    out += [_text(cx + r, cy + FONT + 3, t, extra=f' class="{cls}"{hidden}') for r, t in shown]
    return out


def lobe_panels(theta_i_deg: Sequence[float], theta_o: np.ndarray, table: Sequence[np.ndarray],
                models: dict[int, Sequence[np.ndarray]], plot_id: str, floor_exponent: int, *,
                decades: int | None = None, linear_max: float | None = None) -> str:
    """One SVG panel. `table[j]` and `models[k][j]` are radial coordinates (decades above
    the floor 10^floor_exponent 1/sr, NaN for none) at the angles `theta_o` (rad) for
    incident inclination j. Series k is drawn in colour k as `{plot_id}-s{k}-{j}`, then the
    table, dashed and dark, as `{plot_id}-table-{j}`, so it stays visible on top; every
    group holds the log path (class `lobe-log`) and the linear one (`lobe-lin`, hidden),
    and `data-ti` = j for the page's inclination toggles. `decades` (the rim, log) and
    `linear_max` (1/sr, the largest value) default to this panel's own curves: give them to
    share one scale across panels."""
    table = [np.asarray(c, dtype=float) for c in table]
    series = {k: [np.asarray(c, dtype=float) for c in s] for k, s in models.items()}
    curves = table + [c for s in series.values() for c in s]
    if decades is None:
        decades = int(math.ceil(max([float(np.nanmax(c)) for c in curves if np.isfinite(c).any()] + [1.0])))
    decades = max(int(decades), 1)
    floor = 10.0 ** floor_exponent

    def as_value(r: np.ndarray) -> np.ndarray:
        """1/sr of a log radius."""
        return floor * np.power(10.0, r)

    if linear_max is None:
        linear_max = max([float(np.nanmax(as_value(c))) for c in curves if np.isfinite(c).any()] + [floor])
    step = nice_step(linear_max)
    rings = max(1, math.ceil(linear_max / step - 1e-9))
    lin_top = rings * step
    cx, cy = centre()
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {PANEL_W:.0f} {PANEL_H:.0f}" '
           f'width="{PANEL_W:.0f}" height="{PANEL_H:.0f}" font-family="sans-serif" role="img">']
    out += _rings([RADIUS * d / decades for d in range(decades + 1)],
                  [decade(floor_exponent + d) for d in range(decades + 1)], "lobe-log", cx, cy)
    out += _rings([RADIUS * i / rings for i in range(rings + 1)], [f"{i * step:g}" for i in range(rings + 1)],
                  "lobe-lin", cx, cy)
    spokes = []
    for a in range(-90, 91, 30):
        t = math.radians(a)
        spokes.append(f"M{cx:.1f},{cy:.1f} L{cx + RADIUS * math.sin(t):.1f},{cy - RADIUS * math.cos(t):.1f}")
        if abs(a) == 90:  # beside the baseline, clear of the radial labels below it
            out.append(_text(cx + math.copysign(RADIUS + 4, a), cy + 4, _degrees(a), "start" if a > 0 else "end"))
        else:
            out.append(_text(cx + (RADIUS + 11) * math.sin(t), cy - (RADIUS + 11) * math.cos(t) + 4, _degrees(a)))
    out.append(f'<path d="{" ".join(spokes)}" fill="none" stroke="#cfd3da" stroke-width="0.8"/>')
    out.append(_text(cx + RADIUS / 2, cy + 2 * FONT + 8, "BRDF luminance, 1/sr"))
    for j, ti in enumerate(theta_i_deg):
        t = -math.radians(ti)
        out.append(f'<path data-ti="{j}" d="M{cx:.1f},{cy:.1f} L{cx + RADIUS * math.sin(t):.1f},'
                   f'{cy - RADIUS * math.cos(t):.1f}" stroke="#8a8f98" stroke-width="1" stroke-dasharray="1.5,2.5" '
                   'fill="none"/>')
        out.append(_text(cx + (RADIUS + 11) * math.sin(t), cy - (RADIUS + 11) * math.cos(t) + 4, f"θi {ti:g}°",
                         extra=f' data-ti="{j}" fill="#6b717c" font-style="italic"'))

    def group(gid: str, j: int, r: np.ndarray, stroke: str) -> str:
        log = _path(theta_o, r, decades, cx, cy)
        lin = _path(theta_o, np.where(np.isfinite(r), as_value(r), np.nan), lin_top, cx, cy)
        return (f'<g id="{gid}" data-ti="{j}" fill="none" {stroke}><path class="lobe-log" d="{log}"/>'
                f'<path class="lobe-lin" display="none" d="{lin}"/></g>')

    for k, s in series.items():
        out += [group(f"{plot_id}-s{k}-{j}", j, s[j], f'stroke="{colour(k)}" stroke-width="2.4"')
                for j in range(len(theta_i_deg))]
    out += [group(f"{plot_id}-table-{j}", j, table[j],
                  f'stroke="{TABLE_COLOUR}" stroke-width="1.5" stroke-dasharray="5,4"')
            for j in range(len(theta_i_deg))]
    out.append("</svg>")
    return "".join(out)
