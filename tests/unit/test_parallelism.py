"""The run-control keys `workers`, `threads` and `fit_workers` (brdfbench.parallelism)."""

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


def test_fit_workers_auto_follows_the_threads_and_workers_1_makes_it_one():
    assert parallelism.fit_workers("auto", "auto", cores=16) is None  # auto: the job's threads
    assert parallelism.fit_processes(None, 4) == 4
    assert parallelism.fit_workers(1, "auto", cores=16) == 1  # exclusive timings stay exclusive
    assert parallelism.fit_workers(1, 3, cores=16) == 3  # unless fit_workers is given
    assert parallelism.fit_workers("auto", "2", cores=16) == 2
    assert parallelism.fit_processes(2, 8) == 2


@pytest.mark.parametrize("value", [0, -2, 17, "x", 2.5])
def test_fit_workers_out_of_range_names_the_key(value):
    with pytest.raises(ConfigError, match=r"^fit_workers=.*: expected auto or a whole number from 1 to 16"):
        parallelism.fit_workers("auto", value, cores=16)
