"""Datasets: named collections of target materials, loaded one at a time."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator, Mapping

from ..errors import DataError
from .material_types import describe, material_type

if TYPE_CHECKING:  # keep `import brdfbench.data.specs` light: listing plugins must not import torch
    from ..protocols.generator import WeightSet
    from ..protocols.representation import Material

#: Largest plausible BRDF value (1/sr). The brightest measured specular peaks reach a few
#: thousand; values far above (1e300 in a damaged file) are corruption, and overflow fp32 metrics.
MAX_VALUE = 1e7
_WHAT_TO_DO = "replace or remove the file, or pick other materials with materials=[...]"


def check_table(material: Material) -> None:
    """Refuse a table no metric can score: no valid cell, non-finite cells, absurd values."""
    import numpy as np

    from ..merl import CHANNEL_SCALES  # lazy: torch

    where = material.source or f"material {material.name!r}"
    raw = material.table.raw
    bad = ~np.isfinite(raw)
    if bad.any():
        c, i, j, k = (int(x) for x in np.argwhere(bad)[0])
        raise DataError(f"{where}: {int(bad.sum())} non-finite (NaN/Inf) cells, first at channel {c}, index ({i}, {j}, {k}); "
                        f"the table is corrupt: {_WHAT_TO_DO}")
    valid = material.table.valid
    if not valid.any():
        raise DataError(f"{where}: no valid (non-negative) cells: every cell is marked invalid; "
                        f"not a usable measurement: {_WHAT_TO_DO}")
    peak = max(float(channel.max()) * scale for channel, scale in zip(raw, CHANNEL_SCALES))  # invalid cells are < 0
    if peak > MAX_VALUE:
        raise DataError(f"{where}: BRDF value {peak:.3g} 1/sr, above the plausible maximum {MAX_VALUE:.0e}; "
                        f"the table is corrupt (or not in MERL units): {_WHAT_TO_DO}")


@dataclass(frozen=True)
class Dataset:
    """Material names plus a loader; materials load lazily (a full table is 35 MB).

    `fingerprint` identifies the content (e.g. generator version + seed, or the files'
    sha256) so the results store can tell a re-run of the same data from new data. `load`
    checks each table once (`check_table`), so unusable data stops the run naming the file.

    A dataset made for generation may declare its own `splits` ({"train": names, "test":
    names}) and provide aligned NBRDF weight vectors of its materials (`weights(names)`,
    e.g. NeuMERL's, fitted and cached on first use).
    """

    name: str
    materials: tuple[str, ...]
    loader: Callable[[str], Material]
    fingerprint: str
    categories: dict[str, str] | None = None
    splits: Mapping[str, tuple[str, ...]] | None = None
    weights: Callable[[tuple[str, ...]], WeightSet] | None = None
    #: Per material, its MERL material types (one, or two for a mixture) and its text
    #: description; where None, both are read from the material's name (`material_types`).
    types: Mapping[str, tuple[str, ...]] | None = None
    descriptions: Mapping[str, str] | None = None

    def load(self, material: str) -> Material:
        if material not in self.materials:
            raise DataError(f"dataset {self.name!r} has no material {material!r}; it has {len(self.materials)} materials")
        loaded = self.loader(material)
        check_table(loaded)
        return loaded

    def category(self, material: str) -> str:
        return (self.categories or {}).get(material, "unknown")

    def material_types(self, material: str) -> tuple[str, ...]:
        """The material's MERL types (Zhou et al.'s 48): none for a material outside MERL."""
        if self.types is not None and material in self.types:
            return tuple(self.types[material])
        found = material_type(material)
        return (found,) if found else ()

    def description(self, material: str) -> str:
        """The material's text description (its name as a phrase unless the dataset says otherwise)."""
        if self.descriptions is not None and material in self.descriptions:
            return self.descriptions[material]
        return describe(material)

    def __iter__(self) -> Iterator[Material]:
        return (self.load(m) for m in self.materials)

    def __len__(self) -> int:
        return len(self.materials)

    def subset(self, names: list[str] | None = None, limit: int | None = None) -> "Dataset":
        """The same dataset restricted to `names` (in the given order) and/or the first `limit`."""
        chosen = list(self.materials)
        if names is not None and not names:
            raise DataError(f"materials=[]: an empty selection of dataset {self.name!r}; leave materials out to take every material")
        if names:
            unknown = [n for n in names if n not in self.materials]
            if unknown:
                raise DataError(f"dataset {self.name!r} has no material(s) {', '.join(map(repr, unknown))}")
            chosen = list(names)
        if limit is not None:
            chosen = chosen[:limit]
        kept = set(chosen)
        splits = None if self.splits is None else {k: tuple(m for m in v if m in kept) for k, v in self.splits.items()}
        categories = None if self.categories is None else {m: c for m, c in self.categories.items() if m in kept}
        types = None if self.types is None else {m: t for m, t in self.types.items() if m in kept}
        descriptions = None if self.descriptions is None else {m: d for m, d in self.descriptions.items() if m in kept}
        return Dataset(self.name, tuple(chosen), self.loader, self.fingerprint, categories, splits, self.weights,
                       types, descriptions)
