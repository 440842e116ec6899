"""Cost of a full-resolution BRDF distance matrix (pytest-benchmark): N × N members over
every valid cell of the 90×90×180 MERL grid, each distance of `brdf_distances`, members
read lazily as cell sources (a base synthetic table scaled per member and channel), so
the members' own memory does not count.

    python -m pytest tests/benchmarks/test_distance_speed.py --benchmark-enable
    BRDFBENCH_DISTANCE_N=240 python -m pytest tests/benchmarks/test_distance_speed.py --benchmark-enable

`extra_info` records N, the cells compared and the peak resident memory of the process
(ru_maxrss, so a high-water mark over the whole session).
"""

from __future__ import annotations

import os
import resource

import numpy as np
import pytest

from brdfbench.data.synthetic import generate_material
from brdfbench_metrics import brdf_distances

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
