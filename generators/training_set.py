"""The training set scored as if it were a generator: the ceiling row of Zhou et al.'s Table 1.

`sample(n)` returns n distinct training materials, chosen at random (seeded), as the tables
they are. A generator that reproduces its training data scores like this row; a figure
beyond it says more about the split than about the generator.

It holds its training materials' names, not their tables (those are the dataset's): a
saved one records the names, and a loaded one samples only once `attach`ed to the data
again. That is why the kit's save/load round trip is an expected failure for it.
"""

from __future__ import annotations

from typing import Any

import torch

from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import Generator, SampleSet, TrainingData
from brdfbench.merl import N_CELLS

from .samples import TableSamples


class TrainingSet(Generator):
    learns_from = "tables"

    def __init__(self):
        super().__init__()
        self.data: TrainingData | None = None
        self.names: tuple[str, ...] = ()

    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "TrainingSet":
        if len(data) < 1:
            raise ConfigError("training_set: the training split is empty")
        self.data, self.names = data, tuple(data.names)
        return self

    def attach(self, data: TrainingData) -> "TrainingSet":
        """Give a loaded generator its materials back (names must match)."""
        if tuple(data.names) != self.names:
            raise ConfigError("training_set: the data attached are not the materials it was fitted to")
        self.data = data
        return self

    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        if n > len(self.names):
            raise ConfigError(f"training_set: n={n} samples asked of a training split of {len(self.names)} materials "
                              "(it draws without replacement)")
        if self.data is None:
            raise RuntimeError("training_set: a loaded training set holds names only; attach() its data to sample")
        order = torch.randperm(len(self.names), generator=torch.Generator().manual_seed(seed))[:n]
        data, names = self.data, self.names
        return TableSamples(order[:, None].to(torch.float64), lambda row: data.load(names[int(row[0])]).table,
                            name="training")

    def sample_nbytes(self, n: int) -> int:
        return 8 * n + 2 * 8 * 3 * N_CELLS  # the indices, and one table (values and raw) built at a time

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {} if not self.names else {"count": torch.tensor([len(self.names)], dtype=torch.int64)}

    def metadata(self) -> dict[str, Any]:
        return {"names": list(self.names)}

    @classmethod
    def from_state(cls, params, tensors, metadata) -> "TrainingSet":
        model = cls(**params)
        names = metadata.get("names", [])
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ModelFileError("training_set: metadata 'names' must be a list of material names")
        if tensors and int(tensors["count"][0]) != len(names):
            raise ModelFileError(f"training_set: tensor 'count' says {int(tensors['count'][0])} materials, "
                                 f"the metadata names {len(names)}")
        model.names = tuple(names)
        return model
