"""Plot panels as SVG markup: axes, grid, ticks and labels, written directly rather than
through matplotlib (whose import and layout were most of a report's cost). Coordinates are
data values; `LogAxes` (log-log, decade ticks) and `Axes` (each axis log or linear, ticks
given by the caller) map them into their pixel box. The tick helpers here are also what the
report's script draws its own panels from (`log_ticks` labels, the same padding rules).
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


def linear_range(values: list[float]) -> tuple[float, float]:
    """A linear axis's limits around `values`, padded by a tenth of their spread; a single
    value gets ±5 % of its size (±1 at zero) so that it is not drawn on the frame."""
    lo, hi = min(values), max(values)
    if hi - lo <= 1e-12 * max(1.0, abs(hi)):
        half = abs(hi) * 0.05 or 1.0
        lo, hi = lo - half, hi + half
    pad = (hi - lo) * 0.1
    return lo - pad, hi + pad


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def plain(value: float) -> str:
    """A tick's number without a unit: three significant digits in positional notation
    between 0.001 and 10⁴ ("0.0123", "45.1"), else as a power of ten ("10⁻⁹", "2×10⁻⁹")."""
    if value == 0:
        return "0"
    sign = "−" if value < 0 else ""
    size = abs(value)
    exponent = math.floor(math.log10(size))
    if 1e-3 <= size < 1e4:
        text = f"{size:.{max(0, 2 - exponent)}f}"
        return sign + (text.rstrip("0").rstrip(".") if "." in text else text)
    mantissa = float(f"{size / 10.0 ** exponent:.2g}")
    if mantissa >= 10:
        mantissa, exponent = mantissa / 10, exponent + 1
    power = f"10{str(exponent).translate(_SUPERSCRIPT)}"
    return sign + (power if mantissa == 1 else f"{mantissa:g}×{power}")


def log_ticks(lo: float, hi: float, label) -> list[tuple[float, str, int]]:
    """Candidate ticks of a log axis from `lo` to `hi`: (value, label(value), level), level 0
    for a decade and 1 for two and five times one; a plot keeps the decades where three or
    more fall inside its limits, else all of them."""
    out = []
    for e in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1):
        for m, level in ((1, 0), (2, 1), (5, 1)):
            v = float(f"{m}e{e}")
            if lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9):
                out.append((v, label(v), level))
    return out


def pick_log_ticks(candidates: list[tuple[float, str, int]], most: int) -> list[tuple[float, str]]:
    """The ticks a log axis shows: its decades where three or more fall inside, else the
    two and five too; every n-th one so that at most `most` remain."""
    decades = [c for c in candidates if c[2] == 0]
    chosen = decades if len(decades) >= 3 else candidates
    step = max(1, math.ceil(len(chosen) / most))
    return [(v, text) for v, text, _ in chosen[::step]]


def linear_ticks(lo: float, hi: float, most: int) -> list[tuple[float, str]]:
    """Round-numbered ticks of a linear axis (steps of 1, 2 or 5 times a power of ten), at most `most`."""
    raw = (hi - lo) / max(1, most)
    base = 10.0 ** math.floor(math.log10(raw))
    step = next(m * base for m in (1, 2, 5, 10) if m * base >= raw)
    first = math.ceil(lo / step - 1e-9)
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    out = []
    for i in range(first, math.floor(hi / step + 1e-9) + 1):
        v = i * step
        text = f"{abs(v):.{decimals}f}"
        out.append((v, ("−" if v < 0 and float(text) != 0 else "") + text))
    return out


@dataclass(frozen=True)
class Axes:
    """A panel whose axes are each logarithmic or linear: data ranges into the pixel box
    (left, top, width, height); ticks are the caller's (value, label) pairs."""

    x_range: tuple[float, float]
    y_range: tuple[float, float]
    left: float
    top: float
    width: float
    height: float
    x_log: bool = True
    y_log: bool = True

    @staticmethod
    def _frac(v: float, limits: tuple[float, float], log: bool) -> float:
        a, b = limits
        if log:
            return (math.log10(v) - math.log10(a)) / (math.log10(b) - math.log10(a))
        return (v - a) / (b - a)

    def px(self, x: float) -> float:
        return self.left + self._frac(x, self.x_range, self.x_log) * self.width

    def py(self, y: float) -> float:
        return self.top + self.height - self._frac(y, self.y_range, self.y_log) * self.height

    def path(self, xs: list[float], ys: list[float]) -> str:
        return " ".join(f"{'M' if i == 0 else 'L'}{self.px(x):.1f},{self.py(y):.1f}"
                        for i, (x, y) in enumerate(zip(xs, ys)))

    def frame(self, x_ticks: list[tuple[float, str]], y_ticks: list[tuple[float, str]], x_label: str,
              y_label: str, title: str, font: float = 12.0) -> str:
        """Box, grid at the ticks with their labels, axis labels and title."""
        bottom = self.top + self.height
        grid, out = [], []
        for v, text in x_ticks:
            x = self.px(v)
            grid.append(f"M{x:.1f},{self.top:.1f} L{x:.1f},{bottom:.1f}")
            out.append(f'<text x="{x:.1f}" y="{bottom + font + 3:.1f}" font-size="{font:g}" '
                       f'text-anchor="middle">{escape(text)}</text>')
        for v, text in y_ticks:
            y = self.py(v)
            grid.append(f"M{self.left:.1f},{y:.1f} L{self.left + self.width:.1f},{y:.1f}")
            out.append(f'<text x="{self.left - 5:.1f}" y="{y + font * 0.35:.1f}" font-size="{font:g}" '
                       f'text-anchor="end">{escape(text)}</text>')
        cx, cy = self.left + self.width / 2, self.top + self.height / 2
        side = self.left - 4.2 * font
        out += [f'<text x="{cx:.1f}" y="{bottom + 2.6 * font + 4:.1f}" font-size="{font:g}" '
                f'text-anchor="middle">{escape(x_label)}</text>',
                f'<text x="{side:.1f}" y="{cy:.1f}" font-size="{font:g}" text-anchor="middle" '
                f'transform="rotate(-90 {side:.1f} {cy:.1f})">{escape(y_label)}</text>',
                f'<text x="{cx:.1f}" y="{self.top - 8:.1f}" font-size="{font + 1:g}" font-weight="600" '
                f'text-anchor="middle">{escape(title)}</text>']
        return (f'<path d="{" ".join(grid)}" stroke="#e1e4ea" stroke-width="1" fill="none"/>'
                f'<rect x="{self.left:.1f}" y="{self.top:.1f}" width="{self.width:.1f}" height="{self.height:.1f}" '
                'fill="none" stroke="#333333" stroke-width="0.8"/>' + "".join(out))


def _decades(limits: tuple[float, float]) -> list[int]:
    """Integer decades inside the limits, thinned to at most six labels."""
    lo, hi = math.ceil(math.log10(limits[0]) - 1e-9), math.floor(math.log10(limits[1]) + 1e-9)
    step = max(1, math.ceil((hi - lo + 1) / 6))
    return list(range(lo, hi + 1, step))
