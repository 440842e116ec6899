"""Datasets: named collections of target materials, loaded one at a time."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Iterator

from ..errors import DataError

if TYPE_CHECKING:  # keep `import brdfbench.data.specs` light: listing plugins must not import torch
    from ..protocol import Material


@dataclass(frozen=True)
class Dataset:
    """Material names plus a loader; materials load lazily (a full table is 35 MB).

    `fingerprint` identifies the content (e.g. generator version + seed, or file sizes and
    mtimes) so the results store can tell a re-run of the same data from new data.
    """

    name: str
    materials: tuple[str, ...]
    loader: Callable[[str], Material]
    fingerprint: str
    categories: dict[str, str] | None = None

    def load(self, material: str) -> Material:
        if material not in self.materials:
            raise DataError(f"dataset {self.name!r} has no material {material!r}; it has {len(self.materials)} materials")
        return self.loader(material)

    def category(self, material: str) -> str:
        return (self.categories or {}).get(material, "unknown")

    def __iter__(self) -> Iterator[Material]:
        return (self.load(m) for m in self.materials)

    def __len__(self) -> int:
        return len(self.materials)

    def subset(self, names: list[str] | None = None, limit: int | None = None) -> "Dataset":
        """The same dataset restricted to `names` (in the given order) and/or the first `limit`."""
        chosen = list(self.materials)
        if names:
            unknown = [n for n in names if n not in self.materials]
            if unknown:
                raise DataError(f"dataset {self.name!r} has no material(s) {', '.join(map(repr, unknown))}")
            chosen = list(names)
        if limit is not None:
            chosen = chosen[:limit]
        return Dataset(self.name, tuple(chosen), self.loader, self.fingerprint, self.categories)
