"""The machine's speed when a task ran: a fixed fp32 matrix product timed on the task's
threads just before it, stored with each of its cells (`METRIC`, GFLOP/s), so that cost
figures of runs on a machine whose speed drifts (other load, clocks, another host of the
same name) can be compared: the report lists it per host and thread count."""

from __future__ import annotations

import statistics
import time

from ..harness import Measurement

METRIC = "calibration_gflops"
UNIT = "GFLOP/s"
SIZE = 512  # (SIZE × SIZE) @ (SIZE × SIZE): 2·SIZE³ FLOP, a few milliseconds on one core
REPEATS = 15


def measure() -> Measurement:
    """The median speed of `REPEATS` timed products after one warm-up, as a Measurement."""
    import torch

    g = torch.Generator().manual_seed(0)
    a = torch.rand(SIZE, SIZE, generator=g)
    b = torch.rand(SIZE, SIZE, generator=g)
    out = torch.mm(a, b)
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        torch.mm(a, b, out=out)
        times.append(time.perf_counter() - t0)
    return Measurement(METRIC, 2 * SIZE**3 / max(statistics.median(times), 1e-9) / 1e9, UNIT, True)
