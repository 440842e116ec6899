"""The tabulated MERL table itself as a representation: the ground-truth baseline.

Nearest-cell lookup reproduces the reference reader; trilinear interpolates between cell
centres. Invalid (negative) cells evaluate to 0, so the output is always non-negative.
"""

from __future__ import annotations

import torch

from brdfbench.errors import ConfigError
from brdfbench.merl import MerlTable
from brdfbench.protocol import Material, Representation

MODES = ("nearest", "trilinear")


class TabulatedMERL(Representation):
    tags = frozenset({"isotropic", "reciprocal", "fittable", "tabulated"})

    def __init__(self, mode: str = "nearest"):
        if mode not in MODES:
            raise ConfigError(f"merl: unknown mode {mode!r}; expected one of {', '.join(MODES)}")
        super().__init__(mode=mode)
        self.mode = mode
        self.table: MerlTable | None = None

    def fit(self, target: Material, *, seed: int = 0) -> "TabulatedMERL":
        self.table = target.table
        return self

    def _eval(self, wi, wo):
        if self.table is None:
            raise RuntimeError("merl: evaluate after fit() or load")
        return self.table.lookup(wi, wo, self.mode).clamp_min(0.0)

    def state_dict(self):
        if self.table is None:
            return {}
        return {"raw": torch.from_numpy(self.table.raw)}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        if "raw" in tensors:
            model.table = MerlTable(tensors["raw"].double().numpy())
        return model
