"""Lambertian BRDF: f = rho / pi, constant per channel.

The albedo is fitted as pi times the cosine-weighted median of the valid measured values:
a median, because a mean would be dominated by the specular peak of shiny materials.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from brdfbench import merl
from brdfbench.protocols.representation import Material, Representation
from brdfbench.state_checks import expect_tensor


def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cum = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cum, 0.5 * cum[-1])])


def _channel_medians(values: np.ndarray, weights: np.ndarray) -> list[float]:
    """weighted_median of each channel; the channels are sorted in parallel threads (numpy
    sorts without the GIL), up to torch's thread count, so a fit uses the cores a job was
    given. Each channel's arithmetic is the same as alone."""
    workers = min(len(values), max(1, torch.get_num_threads()))
    if workers == 1:
        return [weighted_median(v, weights) for v in values]
    with ThreadPoolExecutor(workers, thread_name_prefix="lambert-median") as pool:
        return list(pool.map(weighted_median, values, [weights] * len(values)))


class Lambert(Representation):
    tags = frozenset({"isotropic", "reciprocal", "fittable", "analytic"})
    #: evaluates on a GPU; the fit (a weighted median) runs on the CPU wherever the model is
    devices = frozenset({"cpu", "cuda"})

    def __init__(self):
        super().__init__()
        self.albedo = torch.full((3,), 0.5, dtype=torch.float64)

    def fit(self, target: Material, *, seed: int = 0) -> "Lambert":
        wi, wo = (d[:, 2].numpy() for d in merl.grid_directions())
        valid = target.table.valid.reshape(-1) & merl.grid_above_horizon().numpy()
        weights = (wi * wo)[valid]
        values = target.table.values.reshape(3, -1)[:, valid]
        self.albedo = torch.tensor([math.pi * m for m in _channel_medians(values, weights)], dtype=torch.float64)
        self._move(self.device)
        return self

    def _move(self, device):
        self.albedo = self.albedo.to(device)

    def _eval(self, wi, wo):
        return (self.albedo / math.pi).to(wi.dtype).expand(wi.shape[0], 3).clone()

    def state_dict(self):
        return {"albedo": self.albedo}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        model.albedo = expect_tensor(tensors, "albedo", (3,), owner="lambert model", nonneg=True).double()
        return model

    @property
    def flops_per_eval(self) -> int:
        return 3

    def drjit_kernel(self):
        """ρ/π in drjit operations, for this exact class only (a subclass may change
        `_eval`); drjit is imported here, not with the representation."""
        if type(self) is not Lambert:
            return None
        from .drjit_kernels import LambertKernel  # lazy: drjit

        return LambertKernel(self)

