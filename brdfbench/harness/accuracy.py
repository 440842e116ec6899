"""BRDF-space accuracy: grid metrics over valid MERL cells, HDR metrics over random pairs.

The reference is the target's table: its valid cells for grid metrics, its nearest-cell
lookup (as the reference reader) for random pairs; invalid reference values are excluded.
"""

from __future__ import annotations

import torch

from .. import merl
from ..protocol import Material, Representation
from ..specs import MetricSpec
from . import Measurement, directions


def _chunks(n: int, size: int):
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


def evaluate_accuracy(
    model: Representation,
    target: Material,
    metric_specs: list[MetricSpec],
    *,
    n_random: int = 2**20,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    chunk: int = 2**18,
) -> list[Measurement]:
    metrics = {spec.name: (spec, spec.load()()) for spec in metric_specs}
    by_domain: dict[str, list] = {}
    for spec, metric in metrics.values():
        by_domain.setdefault(metric.domain, []).append(metric)
    unknown = set(by_domain) - {"merl_grid", "random_pairs"}
    if unknown:
        raise ValueError(f"metrics with unknown domain(s): {', '.join(sorted(unknown))}")

    if "merl_grid" in by_domain:
        wi, wo = merl.grid_directions(torch.float64)
        valid = torch.from_numpy(target.table.valid.reshape(-1)) & merl.grid_above_horizon()
        wi, wo = wi[valid], wo[valid]
        ref = torch.from_numpy(target.table.values.reshape(3, -1)).T[valid]
        for s in _chunks(wi.shape[0], chunk):
            pred = model.eval(wi[s].to(dtype), wo[s].to(dtype))
            for m in by_domain["merl_grid"]:
                m.update(pred, ref[s], wi[s, 2])

    if "random_pairs" in by_domain:
        wi, wo = directions.random_pairs(n_random, seed, torch.float64)
        ref = target.table.lookup(wi, wo, "nearest")
        ok = (ref >= 0).all(dim=1)
        wi, wo, ref = wi[ok], wo[ok], ref[ok]
        for s in _chunks(wi.shape[0], chunk):
            pred = model.eval(wi[s].to(dtype), wo[s].to(dtype))
            for m in by_domain["random_pairs"]:
                m.update(pred, ref[s], wi[s, 2])

    return [Measurement(name, m.compute(), spec.unit, spec.higher_is_better) for name, (spec, m) in metrics.items()]
