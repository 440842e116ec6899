"""BRDF-space accuracy: grid metrics over valid MERL cells, HDR metrics over random pairs.

The reference is the target's table: its valid cells for grid metrics, its nearest-cell
lookup (as the reference reader) for random pairs; invalid reference values are excluded.

Every material is scored at the same directions, so what depends on them alone lives in
an `AccuracyGeometry`, one per process and settings, reused for every material: the
pairs, the reference cells of the random pairs, and what models derive from the pairs
they are evaluated at (see `brdfbench.reused`: a table lookup's cells, an analytic lobe's
geometry, an NBRDF's input encoding). Models still see the same subsets, chunks, dtypes and
reference values as without it, and derived data comes from the same per-pair arithmetic,
run once over all pairs (tests/unit/test_accuracy_geometry.py checks the scores equal), so
scores are unchanged bit for bit. A geometry holds about 110 MB at the default settings
for table lookups (more where analytic or neural models ask for their data), besides the
process-wide caches of the grid and random directions it reads.
"""

from __future__ import annotations

import weakref
from functools import cached_property, lru_cache, partial
from typing import Any, Callable

import torch

from .. import merl, reused
from ..protocols.representation import Material, Representation
from ..plugins.specs import MetricSpec
from . import Measurement, directions


def _chunks(n: int, size: int):
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


def _joined(parts: list) -> Any:
    """Chunks of a derived value (a tensor, or a tuple / named tuple of tensors) joined."""
    first = parts[0]
    if isinstance(first, torch.Tensor):
        return _stored(torch.cat(parts))
    joined = [_joined(list(p)) for p in zip(*parts)]
    return type(first)(*joined) if hasattr(first, "_fields") else tuple(joined)


def _stored(t: torch.Tensor) -> torch.Tensor:
    """int64 data (cell indices) kept as int16 where it fits: a quarter of the memory."""
    if t.dtype == torch.int64 and t.numel() and int(t.min()) >= -2**15 and int(t.max()) < 2**15:
        return t.to(torch.int16)
    return t


def _rows_of(value: Any, index: torch.Tensor) -> Any:
    """The rows at `index` of a joined value, in the types `fn` returns (int16 back to int64)."""
    if isinstance(value, torch.Tensor):
        part = value[index]
        return part.long() if part.dtype == torch.int16 else part
    rows = [_rows_of(v, index) for v in value]
    return type(value)(*rows) if hasattr(value, "_fields") else tuple(rows)


class _Pairs:
    """One domain's direction pairs (fp64) and, made on first use, their copies in the
    evaluation dtype and what models derive from those copies (see `brdfbench.reused`)."""

    def __init__(self, wi: torch.Tensor, wo: torch.Tensor, dtype: torch.dtype, chunk: int):
        self.wi, self.wo, self.dtype, self.chunk = wi, wo, dtype, chunk
        self._data: dict[tuple, Any] = {}

    @cached_property
    def typed(self) -> tuple[torch.Tensor, torch.Tensor]:
        return self.wi.to(self.dtype), self.wo.to(self.dtype)

    @cached_property
    def cos(self) -> torch.Tensor:
        return self.wi[:, 2].contiguous()

    def typed_on(self, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
        """The pairs in the evaluation dtype on `device`, moved there once and kept."""
        key = ("typed", str(device))
        if key not in self._data:
            self._data[key] = tuple(t.to(device) for t in self.typed)
        return self._data[key]

    def data(self, fn: Callable[..., Any], args: tuple = ()) -> Any:
        """fn(wi, wo, *args) of all pairs in the evaluation dtype, computed chunk by chunk."""
        key = (fn, args)
        if key not in self._data:
            wi, wo = self.typed
            self._data[key] = _joined([fn(wi[s], wo[s], *args) for s in _chunks(wi.shape[0], self.chunk)])
        return self._data[key]

    def _provide(self, index: torch.Tensor, fn: Callable[..., Any], args: tuple) -> Any:
        return _rows_of(self.data(fn, args), index)

    def select(self, index: torch.Tensor):
        """(fp64 cos θi of the pairs at `index`, generator of (slice, wi, wo) chunks of them in
        the dtype): what the model is evaluated at; each chunk is registered for `reused`."""
        wi, wo = (t.index_select(0, index) for t in self.typed)

        def batches():
            for s in _chunks(wi.shape[0], self.chunk):
                a, b = wi[s], wo[s]
                reused.register(a, b, partial(self._provide, index[s]))
                yield s, a, b

        return self.cos.index_select(0, index), batches()


class AccuracyGeometry:
    """What `evaluate_accuracy` computes from the directions alone, for one setting; each
    part is made on first use and then shared by every material."""

    def __init__(self, n_random: int = 2**20, seed: int = 0, dtype: torch.dtype = torch.float32, chunk: int = 2**18):
        self.key = (n_random, seed, dtype, chunk)
        _built.add(self)

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


def forget_derived() -> None:
    """Drop what models derived from the shared geometries' pairs (a new job's models ask for
    their own; memory measured in a job then holds none of another job's data)."""
    for geometry in _built:
        for pairs in ("grid", "random"):
            if pairs in geometry.__dict__:
                geometry.__dict__[pairs]._data.clear()


_built: "weakref.WeakSet[AccuracyGeometry]" = weakref.WeakSet()


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
    device = model.device
    if device.type != "cpu":  # a model on a GPU evaluates there, at pairs moved once per job
        _score_on(device, model, pairs, index, ref, metrics)
        return
    cos, batches = pairs.select(index)
    for s, a, b in batches:
        pred = model.eval(a, b)
        for m in metrics:
            m.update(pred, ref[s], cos[s])


def _score_on(device: torch.device, model: Representation, pairs: _Pairs, index: torch.Tensor, ref: torch.Tensor,
              metrics: list) -> None:
    """`_score` for a model on `device`: the same chunks evaluated there (what models derive
    from the pairs is made there too), the scores accumulated on the host in the same order."""
    wi, wo = pairs.typed_on(device)
    cos = pairs.cos.index_select(0, index)
    on_device = index.to(device)
    for s in _chunks(index.shape[0], pairs.chunk):
        rows = on_device[s]
        pred = model.eval(wi.index_select(0, rows), wo.index_select(0, rows)).cpu()
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
