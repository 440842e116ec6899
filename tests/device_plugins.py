"""Small device-aware plugins shared by the CPU and the GPU tests of the device checks."""

from __future__ import annotations

import torch

from brdfbench.protocols.generator import Generator
from brdfbench_generators.samples import WeightSamples


class PlacedGaussian(Generator):
    """Per-coordinate Gaussian over NBRDF weight vectors that declares the GPU and moves its
    state: a small correct generator for the device checks."""

    learns_from = "nbrdf"
    devices = frozenset({"cpu", "cuda"})

    def __init__(self):
        super().__init__()
        self.mean = self.std = None

    def fit(self, data, *, seed=0, progress=False):
        v = torch.from_numpy(data.weights().vectors).double().to(self.device)
        self.mean, self.std = v.mean(0), v.std(0) + 1e-6
        return self

    def _move(self, device):
        if self.mean is not None:
            self.mean, self.std = self.mean.to(device), self.std.to(device)

    def _sample(self, n, condition, seed):
        z = torch.randn(n, self.mean.numel(), generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
        return WeightSamples(self.mean + self.std * z.to(self.mean.device))

    def sample_nbytes(self, n):
        return 3 * 8 * n * 675

    def state_dict(self):
        return {} if self.mean is None else {"mean": self.mean, "std": self.std}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        if tensors:
            model.mean, model.std = tensors["mean"], tensors["std"]
        return model
