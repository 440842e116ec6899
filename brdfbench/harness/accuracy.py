"""BRDF-space accuracy: grid metrics over valid MERL cells, HDR metrics over random pairs.

The reference is the target's table: its valid cells for grid metrics, its nearest-cell
lookup (as the reference reader) for random pairs; invalid reference values are excluded.

Every material is scored at the same directions, so what depends on them alone lives in
an `AccuracyGeometry`, one per process and settings, reused for every material: the
pairs, the reference cells of the random pairs, and, for models that are MERL table
lookups, the cell data of the pairs they are evaluated at (see `merl.reuse_directions`).
Models still see the same subsets, chunks, dtypes and reference values as without it,
and a table lookup gets its cells from the same per-pair arithmetic, run once over all
pairs (tests/unit/test_accuracy_geometry.py checks the scores equal), so scores are unchanged
bit for bit. A geometry holds about 110 MB at the default settings, besides the
process-wide caches of the grid and random directions it reads.
"""

from __future__ import annotations

from functools import cached_property, lru_cache, partial

import torch

from .. import merl
from ..protocol import Material, Representation
from ..specs import MetricSpec
from . import Measurement, directions


def _chunks(n: int, size: int):
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


class _Pairs:
    """One domain's direction pairs (fp64) and, made on first use, their copies in the
    evaluation dtype and the table-lookup data of those copies."""

    def __init__(self, wi: torch.Tensor, wo: torch.Tensor, dtype: torch.dtype, chunk: int):
        self.wi, self.wo, self.dtype, self.chunk = wi, wo, dtype, chunk
        self._data: dict[str, tuple[torch.Tensor, ...]] = {}

    @cached_property
    def typed(self) -> tuple[torch.Tensor, torch.Tensor]:
        return self.wi.to(self.dtype), self.wo.to(self.dtype)

    @cached_property
    def cos(self) -> torch.Tensor:
        return self.wi[:, 2].contiguous()

    def data(self, kind: str) -> tuple[torch.Tensor, ...]:
        """`merl.direction_data` of all pairs in the evaluation dtype (cell indices as int16)."""
        if kind not in self._data:
            wi, wo = self.typed
            parts = [merl.direction_data(wi[s], wo[s], kind) for s in _chunks(wi.shape[0], self.chunk)]
            whole = tuple(torch.cat(p) for p in zip(*parts))
            self._data[kind] = tuple(t.to(torch.int16) for t in whole) if kind == "cells" else whole
        return self._data[kind]

    def _provide(self, index: torch.Tensor, kind: str) -> tuple[torch.Tensor, ...]:
        part = tuple(t[index] for t in self.data(kind))
        return tuple(t.long() for t in part) if kind == "cells" else part

    def select(self, index: torch.Tensor):
        """(fp64 cos θi of the pairs at `index`, generator of (slice, wi, wo) chunks of them in
        the dtype): what the model is evaluated at; each chunk is registered for table lookups."""
        wi, wo = (t.index_select(0, index) for t in self.typed)

        def batches():
            for s in _chunks(wi.shape[0], self.chunk):
                a, b = wi[s], wo[s]
                merl.reuse_directions(a, b, partial(self._provide, index[s]))
                yield s, a, b

        return self.cos.index_select(0, index), batches()


class AccuracyGeometry:
    """What `evaluate_accuracy` computes from the directions alone, for one setting; each
    part is made on first use and then shared by every material."""

    def __init__(self, n_random: int = 2**20, seed: int = 0, dtype: torch.dtype = torch.float32, chunk: int = 2**18):
        self.key = (n_random, seed, dtype, chunk)

    @cached_property
    def grid(self) -> _Pairs:
        return _Pairs(*merl.grid_directions(torch.float64), self.key[2], self.key[3])

    @cached_property
    def random(self) -> _Pairs:
        n_random, seed, dtype, chunk = self.key
        return _Pairs(*directions.random_pairs(n_random, seed, torch.float64), dtype, chunk)

    @cached_property
    def random_cells(self) -> torch.Tensor:
        """Flat reference cells of the random pairs, computed as the table's nearest lookup does."""
        return merl.flat_index(*merl.direction_data(self.random.wi, self.random.wo, "cells"))


@lru_cache(maxsize=2)
def accuracy_geometry(n_random: int, seed: int, dtype: torch.dtype, chunk: int) -> AccuracyGeometry:
    """The process's shared geometry for these settings (the last two used are kept)."""
    return AccuracyGeometry(n_random, seed, dtype, chunk)


def _rows(channels: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Rows at `index` of a channel-major (3, N) tensor, as a contiguous (len(index), 3) one
    (what boolean indexing of its transpose gives, in a third of the time)."""
    out = torch.empty(index.shape[0], 3, dtype=channels.dtype)
    for c in range(3):
        out[:, c] = channels[c].index_select(0, index)
    return out


def _score(model: Representation, pairs: _Pairs, mask: torch.Tensor, ref: torch.Tensor, metrics: list) -> None:
    """Update `metrics` with the model against the reference at the pairs where `mask`
    holds; `ref` is channel-major (3, N)."""
    index = mask.nonzero().squeeze(1)
    ref = _rows(ref, index)
    cos, batches = pairs.select(index)
    for s, a, b in batches:
        pred = model.eval(a, b)
        for m in metrics:
            m.update(pred, ref[s], cos[s])


def evaluate_accuracy(
    model: Representation,
    target: Material,
    metric_specs: list[MetricSpec],
    *,
    n_random: int = 2**20,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    chunk: int = 2**18,
    geometry: AccuracyGeometry | None = None,
) -> list[Measurement]:
    """Score `model` against `target`'s table; `geometry` (by default the process's shared
    one for these settings) must have been made for the same settings."""
    if geometry is None:
        geometry = accuracy_geometry(n_random, seed, dtype, chunk)
    elif geometry.key != (n_random, seed, dtype, chunk):
        raise ValueError(f"geometry made for (n_random, seed, dtype, chunk) = {geometry.key}, "
                         f"called with {(n_random, seed, dtype, chunk)}")
    metrics = {spec.name: (spec, spec.load()()) for spec in metric_specs}
    by_domain: dict[str, list] = {}
    for spec, metric in metrics.values():
        by_domain.setdefault(metric.domain, []).append(metric)
    unknown = set(by_domain) - {"merl_grid", "random_pairs"}
    if unknown:
        raise ValueError(f"metrics with unknown domain(s): {', '.join(sorted(unknown))}")

    table = target.table
    if "merl_grid" in by_domain:
        valid = torch.from_numpy(table.valid.reshape(-1)) & merl.grid_above_horizon()
        _score(model, geometry.grid, valid, torch.from_numpy(table.values.reshape(3, -1)), by_domain["merl_grid"])

    if "random_pairs" in by_domain:
        ref = merl.gather_cells(table.values, geometry.random_cells)
        _score(model, geometry.random, (ref >= 0).all(dim=1), ref.T, by_domain["random_pairs"])

    return [Measurement(name, m.compute(), spec.unit, spec.higher_is_better) for name, (spec, m) in metrics.items()]
