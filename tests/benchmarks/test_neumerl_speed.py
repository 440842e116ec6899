"""NeuMERL fitting throughput (pytest-benchmark): the default recipe's aligned NBRDF fits of
AugMERL materials, into a fresh cache each round (the anchor fitted first, then the rest
from it, `batch_materials` at a time), on the 24-material synthetic base.

    python -m pytest tests/benchmarks/test_neumerl_speed.py --benchmark-enable

`extra_info["materials_per_minute"]` is the figure the README and notes quote.
"""

from __future__ import annotations

import os
import statistics

N_MATERIALS = int(os.environ.get("BRDFBENCH_NEUMERL_N", "48"))


def test_neumerl_fit_throughput(enabled, tmp_path_factory, synthetic_cache):
    from brdfbench.data.neumerl import neumerl_dataset

    seconds = []

    def fresh():
        cache = tmp_path_factory.mktemp("neumerl-bench")
        ds = neumerl_dataset(base_params={"cache_dir": str(synthetic_cache)}, cache_dir=str(cache))
        names = tuple(ds.splits["train"][:N_MATERIALS])
        for name in names:  # tables first: the timing is the fits
            ds.load(name)
        return (ds, names), {}

    def fit(ds, names):
        import time

        t0 = time.perf_counter()
        ds.weights(names)
        seconds.append(time.perf_counter() - t0)

    enabled.pedantic(fit, setup=fresh, rounds=2, iterations=1)
    enabled.extra_info.update(materials=N_MATERIALS,
                              materials_per_minute=60 * N_MATERIALS / statistics.median(seconds))
