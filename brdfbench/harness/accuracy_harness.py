"""The BRDF-space harness plugin (`harness=default`, kind `accuracy`): accuracy on the MERL
grid and random pairs, and evaluation throughput."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from . import Harness, HarnessConfig, Measurement

DEFAULT_METRICS = ("l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae")


@dataclass(frozen=True)
class AccuracyConfig(HarnessConfig):
    kind: str = "accuracy"
    metrics: tuple[str, ...] = DEFAULT_METRICS
    n_random: int = field(default=2**20, metadata={"min": 1})  # random (ωi, ωo) pairs of the HDR metrics
    throughput_batch: int = field(default=2**16, metadata={"min": 1})  # pairs per timed evaluation batch


class AccuracyHarness(Harness):
    name = "accuracy"
    Config = AccuracyConfig
    domains = ("merl_grid", "random_pairs")

    def measure(self, model, material, label: str) -> list[Measurement]:
        from .accuracy import evaluate_accuracy
        from .cost import evaluation_throughput

        c, ctx = self.config, self.context
        dtype = getattr(torch, c.dtype)
        out = evaluate_accuracy(model, material, ctx.metric_specs, n_random=c.n_random, seed=ctx.seed, dtype=dtype)
        return out + [evaluation_throughput(model, batch=c.throughput_batch, seed=ctx.seed, dtype=dtype)]
