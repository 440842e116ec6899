"""What a representation costs: evaluation throughput and model size.

Throughput is the median over timed batches after one warm-up batch, measured where the
model lives (this machine's CPU with torch's current thread count, or its GPU, waiting for
the device to finish each batch): at least three batches, then more until
`min_time_s` has passed or `max_repeats` were timed. Every cell pays that time, so
`min_time_s` is kept short; the median of three or more is robust to a stray slow batch.
"""

from __future__ import annotations

import statistics
import time

import torch

from ..device import synchronize
from ..protocols.representation import FIT_LOSS_KEY, Representation
from . import Measurement, directions


def evaluation_throughput(
    model: Representation, *, batch: int = 2**16, min_time_s: float = 0.03, max_repeats: int = 20,
    seed: int = 0, dtype: torch.dtype = torch.float32,
) -> Measurement:
    device = model.device
    wi, wo = (t.to(device=device, dtype=dtype) for t in directions.random_pairs(batch, seed + 1, torch.float64))
    model.eval(wi, wo)  # warm-up
    synchronize(device)
    times: list[float] = []
    start = time.perf_counter()
    while len(times) < max_repeats and (len(times) < 3 or time.perf_counter() - start < min_time_s):
        t0 = time.perf_counter()
        model.eval(wi, wo)
        synchronize(device)
        times.append(time.perf_counter() - t0)
    return Measurement("evals_per_s", batch / statistics.median(times), "evals/s", True)


def model_size(model: Representation) -> list[Measurement]:
    out = [Measurement("model_bytes", float(model.nbytes), "B", False)]
    if model.shared_nbytes:
        out.append(Measurement("shared_bytes", float(model.shared_nbytes), "B", False))
    flops = model.flops_per_eval
    if flops is not None:
        out.append(Measurement("flops_per_eval", float(flops), "FLOP", False))
    return out


def fit_loss(model: Representation) -> list[Measurement]:
    """The model's own final fit objective (its metadata's `fit_loss`), where it reports a
    real number (a bool is not one)."""
    value = model.metadata().get(FIT_LOSS_KEY)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [Measurement("fit_loss", float(value), "objective", False)]
    return []
