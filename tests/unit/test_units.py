"""The report's unit formatting: decimal SI prefixes, three significant digits."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from brdfbench_leaderboard.units import human, scaled


@pytest.mark.parametrize("value, unit, text", [
    (4.5e-5, "s", "45 µs"), (0.1218, "s", "122 ms"), (12.5, "s", "12.5 s"), (0.9996, "s", "1 s"),
    (640.0, "s", "640 s"), (64, "B", "64 B"), (1272, "B", "1.27 kB"), (2.5e8, "B", "250 MB"),
    (9.536e8, "B", "954 MB"), (3.2e9, "B", "3.2 GB"), (5.8e6, "evals/s", "5.8 M evals/s"),
    (120.0, "evals/s", "120 evals/s"), (1200, "FLOP", "1.2 kFLOP"), (0, "B", "0 B"),
    (3.5e-9, "log(1+1/sr)", "3.500e-09 log(1+1/sr)"), (0.0163, "1/sr", "0.0163 1/sr"),
])
def test_human(value, unit, text):
    assert human(value, unit) == text


def test_missing_figures_are_a_dash():
    assert human(None, "s") == "–"
    assert human(float("nan"), "B") == "–"


@given(st.floats(min_value=1e-9, max_value=1e15, allow_nan=False))
def test_the_printed_figure_is_within_half_a_unit_of_its_third_digit(value):
    """Whatever the prefix, reading the text back gives the value to three significant digits."""
    for unit, factors in (("s", {"ns": 1e-9, "µs": 1e-6, "ms": 1e-3, "s": 1.0}),
                          ("B", {"B": 1.0, "kB": 1e3, "MB": 1e6, "GB": 1e9, "TB": 1e12, "PB": 1e15})):
        number, shown = scaled(value, unit)
        back = float(number) * factors[shown]
        assert math.isclose(back, value, rel_tol=5.01e-3), (value, number, shown)
        assert float(number) < 1000 or shown in ("s", "PB")
