"""Figures in units a reader takes in at a glance: 12.3 ms, 1.27 kB, 5.80 M evals/s.

One convention throughout the report: decimal SI prefixes (1 kB = 1000 B, 1 MB = 10⁶ B),
so a byte count reads the same in every table, plot and published comparison. The exact
value stays in the cell's sort key and tooltip; this is only how it is printed.
"""

from __future__ import annotations

import math

#: Decimal prefixes, smallest first (exponent of 1000, symbol).
_PREFIXES = ((-3, "n"), (-2, "µ"), (-1, "m"), (0, ""), (1, "k"), (2, "M"), (3, "G"), (4, "T"), (5, "P"))
#: Units printed with a prefix, and the smallest and largest exponent of 1000 they use.
_SCALED = {
    "s": (-3, 0),  # ns … s; a minute or more stays in seconds (fit times are compared in seconds)
    "B": (0, 5),  # B … PB
    "evals/s": (0, 4),
    "samples/s": (0, 4),
    "FLOP": (0, 5),
    "GFLOP/s": (0, 0),
}
#: Units that are words: the prefix stands apart ("5.8 M evals/s", not "5.8 Mevals/s").
_WORDS = ("evals/s", "samples/s")
#: Significant digits printed.
DIGITS = 3


def _sig(value: float, digits: int = DIGITS) -> str:
    """`value` to `digits` significant digits, no exponent (1.00 → "1", 12.30 → "12.3")."""
    if value == 0:
        return "0"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(value)))))
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text


def scaled(value: float, unit: str) -> tuple[str, str]:
    """(number, unit with prefix) of `value` in `unit`, e.g. (0.0123, "s") → ("12.3", "ms");
    a unit without a scale comes back unchanged, with the number to four significant digits."""
    if value is None or not math.isfinite(value):
        return ("–" if value is None or math.isnan(value) else ("∞" if value > 0 else "−∞")), unit
    span = _SCALED.get(unit)
    if span is None or value == 0:
        return (fmt(value), unit)
    lo, hi = span
    exponent = int(math.floor(math.log10(abs(value)) / 3))
    exponent = min(max(exponent, lo), hi)
    mantissa = value / 1000.0 ** exponent
    if round(abs(mantissa), DIGITS - len(str(int(abs(mantissa))))) >= 1000 and exponent < hi:
        exponent += 1
        mantissa = value / 1000.0 ** exponent
    prefix = dict(_PREFIXES)[exponent]
    return _sig(mantissa), (f"{prefix} {unit}" if prefix and unit in _WORDS else prefix + unit)


def scales(unit: str) -> bool:
    """Whether figures in `unit` are printed with a prefix (and so carry their unit)."""
    return unit in _SCALED


def human(value: float | None, unit: str) -> str:
    """`value` in `unit` as one string ("12.3 ms", "250 MB", "5.8 M evals/s")."""
    number, shown = scaled(value, unit)
    if number == "–":
        return number
    return f"{number} {shown}".rstrip()


def fmt(value: float | None) -> str:
    """A figure without a unit to scale: four significant digits, an exponent outside [1e-3, 1e5)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if value == 0:
        return "0"
    if abs(value) >= 1e5 or abs(value) < 1e-3:
        return f"{value:.3e}"
    return f"{value:.4g}"
