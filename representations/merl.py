"""The tabulated MERL table itself as a representation: the ground-truth baseline.

Nearest-cell lookup reproduces the reference reader; trilinear interpolates between cell
centres. With `downsample` = x > 1 the table keeps one sample per block of x cells in
each dimension (the block's centre cell, or its valid cell nearest the centre) and
reconstructs by nearest neighbour: the baseline of the sparse-reconstruction experiment.
Invalid (negative) cells evaluate to 0, so the output is always non-negative.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from brdfbench import merl
from brdfbench.errors import ConfigError
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material, Representation
from brdfbench.state_checks import expect_tensor

MODES = ("nearest", "trilinear")
DENSITIES = (1, 2, 4, 8, 16, 24, 32)

# Arithmetic per lookup, counted as analytic.py counts (each add, multiply, divide, sqrt,
# trig function one operation; memory gathers not counted): half vector 12, ωi rotated into
# the half-vector frame 18, θh, θd, φd 6, fold and three cell indices 9.
NEAREST_FLOPS = 12 + 18 + 6 + 9
# Trilinear adds, per axis, the fractional offset and two weights (3 × 3), and for each of
# the 8 corners a weight product, validity weight and RGB multiply-add (8 × 10), then the
# normalisation (4).
TRILINEAR_FLOPS = NEAREST_FLOPS + 9 + 80 + 4


def block_samples(raw: np.ndarray, x: int) -> np.ndarray:
    """One sample per x×x×x block of a (3, 90, 90, 180) table: (3, ⌈90/x⌉, ⌈90/x⌉, ⌈180/x⌉).

    The sample is the block's centre cell where valid, else its valid cell nearest the
    centre (in index distance), else invalid.
    """
    nb = [math.ceil(n / x) for n in merl.SHAPE]
    padded = np.full((3, *(b * x for b in nb)), merl.INVALID_RAW)
    padded[:, : merl.SHAPE[0], : merl.SHAPE[1], : merl.SHAPE[2]] = raw
    blocks = padded.reshape(3, nb[0], x, nb[1], x, nb[2], x).transpose(0, 1, 3, 5, 2, 4, 6).reshape(3, *nb, x**3)
    offset = np.arange(x) - (x - 1) / 2
    distance = (offset[:, None, None] ** 2 + offset[None, :, None] ** 2 + offset[None, None, :] ** 2).reshape(-1)
    valid = np.all(blocks >= 0, axis=0)  # (*nb, x³)
    score = np.where(valid, distance, np.inf)
    choice = np.argmin(score, axis=-1)  # nearest valid to the centre; ties resolved by the lowest index
    return np.take_along_axis(blocks, choice[None, ..., None], axis=-1)[..., 0]


class TabulatedMERL(Representation):
    tags = frozenset({"isotropic", "reciprocal", "fittable", "tabulated"})

    def __init__(self, mode: str = "nearest", downsample: int = 1):
        if mode not in MODES:
            raise ConfigError(f"merl: unknown mode {mode!r}; expected one of {', '.join(MODES)}")
        if downsample not in DENSITIES:
            raise ConfigError(f"merl: downsample={downsample!r}; expected one of {', '.join(map(str, DENSITIES))}")
        if downsample > 1 and mode != "nearest":
            raise ConfigError(f"merl: downsample={downsample} reconstructs by nearest neighbour; mode={mode!r} is not supported with it")
        super().__init__(mode=mode, downsample=downsample)
        self.mode = mode
        self.downsample = downsample
        self.table: MerlTable | None = None
        self.samples: np.ndarray | None = None  # (3, ⌈90/x⌉, ⌈90/x⌉, ⌈180/x⌉) raw values when downsampled

    def fit(self, target: Material, *, seed: int = 0) -> "TabulatedMERL":
        if self.downsample == 1:
            self.table = target.table
        else:
            self.samples = block_samples(target.table.raw, self.downsample)
        return self

    def _eval(self, wi, wo):
        if self.downsample == 1:
            if self.table is None:
                raise RuntimeError("merl: evaluate after fit() or load")
            return self.table.lookup(wi, wo, self.mode).clamp_min(0.0)
        if self.samples is None:
            raise RuntimeError("merl: evaluate after fit() or load")
        ih, id_, ip = merl.cell_indices(wi, wo)
        x = self.downsample
        raw = torch.from_numpy(self.samples)[:, ih // x, id_ // x, ip // x].T
        scales = torch.tensor(merl.CHANNEL_SCALES, dtype=torch.float64)
        return (raw * scales).clamp_min(0.0)

    @property
    def flops_per_eval(self) -> int:
        if self.mode == "trilinear":
            return TRILINEAR_FLOPS
        return NEAREST_FLOPS + (3 if self.downsample > 1 else 0)  # three block divisions

    def state_dict(self):
        if self.downsample > 1:
            return {} if self.samples is None else {"samples": torch.from_numpy(self.samples)}
        return {} if self.table is None else {"raw": torch.from_numpy(self.table.raw)}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        owner = "merl model"
        raw = expect_tensor(tensors, "raw", (3, *merl.SHAPE), owner=owner, required=False)
        if raw is not None:
            model.table = MerlTable(raw.double().numpy())
        x = model.downsample
        blocks = (3, *(math.ceil(n / x) for n in merl.SHAPE))
        samples = expect_tensor(tensors, "samples", blocks, owner=owner, required=False)
        if samples is not None:
            model.samples = samples.double().numpy()
        return model

    def drjit_kernel(self):
        """The table lookup in drjit operations, for this exact class only (a subclass may change
        `_eval`); drjit is imported here, not with the representation."""
        if type(self) is not TabulatedMERL:
            return None
        from .drjit_kernels import merl_kernel  # lazy: drjit

        return merl_kernel(self)
