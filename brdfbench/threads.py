"""Torch's intra-op thread count for one block of work, restored afterwards.

Work on tensors of ~10⁵–10⁶ values (an analytic fit's objective, the χ² engine, small MLPs,
image-distance loops, Inception batches) gains little from a second thread and, on a
machine whose cores are busy, loses much more to thread hand-offs; one thread also fixes
the order of every reduction, whatever the machine's core count.
"""

from __future__ import annotations

from contextlib import contextmanager

import torch


@contextmanager
def torch_threads(n: int | None = 1):
    """Run the block with `n` torch intra-op threads (None: as set), then restore the caller's count."""
    before = torch.get_num_threads()
    if n is not None and n != before:
        torch.set_num_threads(n)
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)
