"""The run-control keys `workers` and `threads` (brdfbench.parallelism)."""

from __future__ import annotations

import pytest

from brdfbench import parallelism
from brdfbench.errors import ConfigError


@pytest.mark.parametrize("cores, jobs, expected", [
    (2, 13, (1, None)),   # two cores: one job at a time on every core, as before
    (3, 13, (1, None)),
    (4, 13, (2, 2)),
    (16, 13, (8, 2)),
    (16, 3, (3, 5)),      # fewer jobs than workers: the cores shared among the jobs there are
    (16, 1, (1, None)),   # a lone job keeps torch's default
])
def test_auto(cores, jobs, expected):
    assert parallelism.resolve("auto", "auto", jobs, cores) == expected


def test_explicit_counts_win():
    assert parallelism.resolve(1, "auto", 13, 16) == (1, None)  # workers=1: exclusive timings
    assert parallelism.resolve("auto", 4, 13, 16) == (4, 4)
    assert parallelism.resolve(2, 1, 13, 2) == (2, 1)
    assert parallelism.resolve("3", "2", 13, 16) == (3, 2)  # as a command line spells them


@pytest.mark.parametrize("key, value", [("workers", 0), ("workers", -1), ("workers", 17), ("threads", 0),
                                        ("threads", 99), ("threads", "abc"), ("workers", 1.5), ("workers", True)])
def test_out_of_range_names_the_key_and_the_range(key, value):
    with pytest.raises(ConfigError) as err:
        parallelism.count(key, value, cores=16)
    assert str(err.value).startswith(f"{key}={value!r}: expected auto or a whole number from 1 to 16")
