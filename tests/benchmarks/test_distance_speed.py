"""Cost of a full-resolution BRDF distance matrix (pytest-benchmark): N × N members over
every valid cell of the 90×90×180 MERL grid, each distance of `brdf_distances`, members
read lazily as cell sources (a base synthetic table scaled per member and channel), so
the members' own memory does not count.

    python -m pytest tests/benchmarks/test_distance_speed.py --benchmark-enable
    BRDFBENCH_DISTANCE_N=240 python -m pytest tests/benchmarks/test_distance_speed.py --benchmark-enable

`extra_info` records N, the cells compared and the peak resident memory of the process
(ru_maxrss, so a high-water mark over the whole session). The GPU case (skipped without
CUDA) times the same matrix computed on cuda:0 (`device=`, the torch path), the device
synchronised before the clock is read, and records the peak device memory it allocated.
"""

from __future__ import annotations

import os
import resource

import numpy as np
import pytest
import torch

from brdfbench.data.synthetic import generate_material
from brdfbench.distances import brdf as brdf_distances

N = int(os.environ.get("BRDFBENCH_DISTANCE_N", "24"))


class _Scaled:
    """One base table, scaled by a per-member factor per channel: distinct members for free."""

    def __init__(self, base: np.ndarray, scale: np.ndarray):
        self.base, self.scale = base, scale

    def grid_cells(self, cells: np.ndarray) -> np.ndarray:
        v = self.base[:, cells]
        return np.where(v >= 0, v * self.scale[:, None], v)


@pytest.fixture(scope="module")
def members():
    base = generate_material(1, seed=0)[2].values.reshape(3, -1)
    rng = np.random.default_rng(0)
    return [_Scaled(base, rng.lognormal(0.0, 0.5, 3)) for _ in range(N)]


@pytest.fixture(scope="module")
def cells(members):
    return brdf_distances.common_valid_cells(members[:1])


@pytest.mark.parametrize("kind", brdf_distances.KINDS)
def test_distance_matrix(benchmark, members, cells, kind):
    if not benchmark.enabled:
        pytest.skip("times a full-grid distance matrix: run with --benchmark-enable")
    d = benchmark.pedantic(lambda: brdf_distances.distance_matrix(members, kind=kind, cells=cells), rounds=1,
                           iterations=1)
    assert d.shape == (N, N) and np.isfinite(d).all()
    benchmark.extra_info.update(n=N, cells=int(len(cells)),
                                peak_rss_gib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2))


@pytest.mark.gpu
@pytest.mark.parametrize("kind", brdf_distances.KINDS)
def test_distance_matrix_on_gpu(benchmark, members, cells, kind):
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device: the GPU distance matrix needs one")
    if not benchmark.enabled:
        pytest.skip("times a full-grid distance matrix on the GPU: run with --benchmark-enable")
    device = torch.device("cuda", 0)
    brdf_distances.distance_matrix(members[:2], kind=kind, cells=cells[:1000], device=device)  # CUDA's start-up
    torch.cuda.synchronize(device)
    torch.cuda.reset_peak_memory_stats(device)

    def on_gpu():
        d = brdf_distances.distance_matrix(members, kind=kind, cells=cells, device=device)
        torch.cuda.synchronize(device)  # every queued kernel inside the timing
        return d

    d = benchmark.pedantic(on_gpu, rounds=1, iterations=1)
    assert d.shape == (N, N) and np.isfinite(d).all()
    from brdfbench.device import describe

    # the limit: each member's values cross to the device once (N × 3 × cells fp64 reads are
    # memory, not arithmetic), and the N² / 2 pairs' sums over 3 × cells values are at least
    # one read of each operand from the card's fastest memory; the copy leg is the bound here
    bytes_in = N * 3 * len(cells) * 8
    benchmark.extra_info.update(n=N, cells=int(len(cells)), device=describe(device),
                                peak_gpu_gib=round(torch.cuda.max_memory_allocated(device) / 2**30, 2),
                                peak_rss_gib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2),
                                value=benchmark.stats.stats.mean, unit="s", higher_is_better=False,
                                target="<= 5 (N = 240)", limit=bytes_in / 25e9,
                                limit_what="the members' fp64 values over an assumed 25 GB/s host-to-device link")
