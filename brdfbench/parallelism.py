"""How many jobs of a sweep run at once, on how many threads each, and how many materials a
job fits at once (the run-control keys `workers`, `threads` and `fit_workers`).

`threads: auto` leaves a lone job torch's default (every core); `workers: auto` runs one
job at a time below `PARALLEL_FROM_CORES` cores (two cores are better spent on one job's
threads than split: its timings stay uncontended), else `cores // THREADS_PER_WORKER` jobs
at once, each on `cores // workers` threads. `workers=1` gives exclusive timings on any
machine. A value outside 1 … cores is a ConfigError naming the key and the range.

`fit_workers: auto` fits the materials of a job whose representation fits on one thread
(`Representation.fits_in_parallel`) in as many single-threaded processes as the job has
threads, one material each at a time; `workers=1` (exclusive timings) makes that one too,
unless `fit_workers` is given.
"""

from __future__ import annotations

from .errors import ConfigError
from .pipeline.environment import usable_cores

AUTO = "auto"
#: auto: parallel jobs only from this many usable cores
PARALLEL_FROM_CORES = 4
#: auto: the threads each parallel job gets (the NBRDF and triplane fitters use two well)
THREADS_PER_WORKER = 2
#: Set by the sweeper for the jobs it runs in parallel: recorded as their launcher.
LAUNCHER_ENV = "BRDFBENCH_AUTO_LAUNCHER"


def count(key: str, value, cores: int | None = None) -> int | None:
    """A `workers` / `threads` value as a count (None for auto), checked against the cores."""
    cores = cores or usable_cores()
    if value is None or value == AUTO:
        return None
    if isinstance(value, str) and value.strip().lstrip("+-").isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= cores:
        raise ConfigError(f"{key}={value!r}: expected auto or a whole number from 1 to {cores} "
                          f"(the cores this process may use)")
    return value


def resolve(workers, threads, jobs: int, cores: int | None = None) -> tuple[int, int | None]:
    """(jobs at once, threads per job or None for torch's default) for a sweep of `jobs` jobs."""
    cores = cores or usable_cores()
    t = count("threads", threads, cores)
    w = count("workers", workers, cores)
    if w is None:
        w = 1 if cores < PARALLEL_FROM_CORES else max(1, cores // (t or THREADS_PER_WORKER))
    w = max(1, min(w, jobs))
    if t is None and w > 1:
        t = max(1, cores // w)
    return w, t


def fit_workers(workers, value, cores: int | None = None) -> int | None:
    """The `fit_workers` count of a job (None: auto, the job's threads), checked against the
    cores; `workers=1` with `fit_workers: auto` is 1, so that exclusive timings stay exclusive."""
    n = count("fit_workers", value, cores)
    if n is None and count("workers", workers, cores) == 1:
        return 1
    return n


def fit_processes(fit_workers: int | None, threads: int) -> int:
    """How many single-threaded fits a job on `threads` torch threads runs at once."""
    return max(1, fit_workers if fit_workers is not None else threads)
