"""Sample sets of the built-in generators: NBRDF networks from weight vectors, and tables.

Each item is built when it is asked for, so a set of full 90×90×180 tables (35 MB each)
never has to sit in memory at once; the set's `array` keeps the raw per-sample
parameters the generator drew.

Devices: `array` lives where the generator sampled. A weight sample is built there too (an
NBRDF moved with `to`, evaluating inputs on that device: `brdfbench.device.on_host` wraps
it for host inputs); a table sample is always a CPU table (`to_table` returns one).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch

from brdfbench.protocols.generator import SampleSet
from brdfbench.merl import MerlTable
from brdfbench.nbrdf.layouts import unflatten
from brdfbench.nbrdf.network import Network
from brdfbench.protocols.representation import Material, Representation
from brdfbench_representations.merl import TabulatedMERL


class WeightSamples(SampleSet):
    """Samples as NBRDF networks: `array` (n, W) holds flattened weight vectors (the layout
    of `brdfbench.nbrdf.layouts.flatten`, 675 values for 6-21-21-3)."""

    representation = "nbrdf"

    def __init__(self, array: torch.Tensor, hidden: Sequence[int] = (21, 21), features: str = "rusinkiewicz",
                 raw_units: bool = False):
        super().__init__(array.detach().to(torch.float32))
        if self.array.ndim != 2:
            raise ValueError(f"weight samples must be (n, W), got {tuple(self.array.shape)}")
        self.hidden = tuple(int(h) for h in hidden)
        self.features = features
        self.raw_units = bool(raw_units)
        if features == "directions":
            self.representation = "naive_mlp"

    def network(self, i: int) -> Network:
        weights = unflatten(self.array[i], self.hidden, where=f"sample {i}")
        return Network(weights=weights, features=self.features, raw_units=self.raw_units)

    def _build(self, i: int) -> Representation:
        from brdfbench_representations.nbrdf import NaiveMLP, NBRDF  # lazy: h5py, safetensors

        cls = NaiveMLP if self.features == "directions" else NBRDF
        model = cls.from_network(self.network(i))
        return model if self.array.device.type == "cpu" else model.to(self.array.device)


class TableSamples(SampleSet):
    """Samples as tabulated MERL materials: `array` (n, ...) holds whatever a generator
    draws (coefficients, a downsampled table), and `to_table(array[i])` makes the full table."""

    representation = "merl"

    def __init__(self, array: torch.Tensor, to_table: Callable[[torch.Tensor], MerlTable], name: str = "sample"):
        super().__init__(array)
        self.to_table = to_table
        self.name = name

    def table(self, i: int) -> MerlTable:
        if not bool(self.finite[i]):
            raise ValueError(f"sample {i} has non-finite parameters; it cannot be built")
        return self.to_table(self.array[i])

    def _build(self, i: int) -> Representation:
        return TabulatedMERL().fit(Material(f"{self.name}-{i}", self.table(i), "generated"))
