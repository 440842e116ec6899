"""Log-log panels as SVG markup: the axes, decade grid and labels the report's
accuracy-against-cost charts need, written directly rather than through matplotlib (whose
import and layout were most of a report's cost). Coordinates are data values; `LogAxes`
maps them into its pixel box.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass


#: Series colours: matplotlib's default cycle (tab10), shared by every plot and legend swatch.
COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
           "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")


def colour(k: int) -> str:
    return COLOURS[k % len(COLOURS)]


def escape(text) -> str:
    return html.escape(str(text), quote=True)


def decade_label(exponent: int) -> str:
    return f"1e{exponent}"


def log_range(values: list[float]) -> tuple[float, float]:
    """A log axis's limits around positive `values`: at least a decade wide (a narrower
    one shows no labelled tick), padded by a tenth of its width on each side."""
    lo, hi = min(values), max(values)
    if hi / lo < 10:
        mid = math.sqrt(lo * hi)
        lo, hi = min(lo, mid / math.sqrt(10)), max(hi, mid * math.sqrt(10))
    pad = (math.log10(hi) - math.log10(lo)) * 0.1
    return 10 ** (math.log10(lo) - pad), 10 ** (math.log10(hi) + pad)


@dataclass(frozen=True)
class LogAxes:
    """A log-log panel: data ranges (x0, x1) and (y0, y1) into the pixel box (left, top, width, height)."""

    x_range: tuple[float, float]
    y_range: tuple[float, float]
    left: float
    top: float
    width: float
    height: float

    def px(self, x: float) -> float:
        a, b = (math.log10(v) for v in self.x_range)
        return self.left + (math.log10(x) - a) / (b - a) * self.width

    def py(self, y: float) -> float:
        a, b = (math.log10(v) for v in self.y_range)
        return self.top + self.height - (math.log10(y) - a) / (b - a) * self.height

    def point(self, x: float, y: float) -> str:
        return f"{self.px(x):.1f},{self.py(y):.1f}"

    def path(self, xs: list[float], ys: list[float]) -> str:
        return " ".join(f"{'M' if i == 0 else 'L'}{self.point(x, y)}" for i, (x, y) in enumerate(zip(xs, ys)))

    def frame(self, x_label: str, y_label: str, title: str) -> str:
        """Box, decade grid with tick labels, axis labels and title."""
        out = [f'<rect x="{self.left:.1f}" y="{self.top:.1f}" width="{self.width:.1f}" height="{self.height:.1f}" '
               'fill="none" stroke="#333333" stroke-width="0.8"/>']
        grid = []
        for e in _decades(self.x_range):
            x = self.px(10.0**e)
            grid.append(f"M{x:.1f},{self.top:.1f} L{x:.1f},{self.top + self.height:.1f}")
            out.append(f'<text x="{x:.1f}" y="{self.top + self.height + 12:.1f}" font-size="9" '
                       f'text-anchor="middle">{decade_label(e)}</text>')
        for e in _decades(self.y_range):
            y = self.py(10.0**e)
            grid.append(f"M{self.left:.1f},{y:.1f} L{self.left + self.width:.1f},{y:.1f}")
            out.append(f'<text x="{self.left - 4:.1f}" y="{y + 3:.1f}" font-size="9" '
                       f'text-anchor="end">{decade_label(e)}</text>')
        out.insert(0, f'<path d="{" ".join(grid)}" stroke="#dddddd" stroke-width="0.7" fill="none"/>')
        cx = self.left + self.width / 2
        out.append(f'<text x="{cx:.1f}" y="{self.top + self.height + 28:.1f}" font-size="9" '
                   f'text-anchor="middle">{escape(x_label)}</text>')
        cy = self.top + self.height / 2
        out.append(f'<text x="{self.left - 40:.1f}" y="{cy:.1f}" font-size="9" text-anchor="middle" '
                   f'transform="rotate(-90 {self.left - 40:.1f} {cy:.1f})">{escape(y_label)}</text>')
        out.append(f'<text x="{cx:.1f}" y="{self.top - 8:.1f}" font-size="10" '
                   f'text-anchor="middle">{escape(title)}</text>')
        return "".join(out)


def _decades(limits: tuple[float, float]) -> list[int]:
    """Integer decades inside the limits, thinned to at most six labels."""
    lo, hi = math.ceil(math.log10(limits[0]) - 1e-9), math.floor(math.log10(limits[1]) + 1e-9)
    step = max(1, math.ceil((hi - lo + 1) / 6))
    return list(range(lo, hi + 1, step))
