"""The BRDF-space harness plugin (`harness=default`, kind `accuracy`): accuracy on the MERL
grid and random pairs, and evaluation throughput; each cell also records its target's lobe
half-width (`target_lobe_half_width`, a property of the material that the report's
sharpest-decile table sorts by) and saves its in-plane lobe slices beside its table's
(`lobes`), for the report's polar plots."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import torch

from . import Harness, HarnessConfig, lobes, Measurement
from .lobes import TARGET_HALF_WIDTH
from .. import artifacts
from ..device import on_host
from .accuracy import evaluate_accuracy, forget_derived
from .cost import evaluation_throughput

@dataclass(frozen=True)
class AccuracyConfig(HarnessConfig):
    kind: str = "accuracy"
    metrics: tuple[str, ...] = ()  # the shipped harness=accuracy option lists the default metrics
    n_random: int = field(default=2**20, metadata={"min": 1})  # random (ωi, ωo) pairs of the HDR metrics
    throughput_batch: int = field(default=2**16, metadata={"min": 1})  # pairs per timed evaluation batch
    lobes: bool = True  # save in-plane lobe slices of each cell under <results>/artifacts (not hashed)
    # pairs per timed batch for a model on a GPU, where 2^16 pairs measure kernel launches
    # rather than arithmetic (not hashed: the device is run control; rows record it)
    gpu_throughput_batch: int = field(default=2**22, metadata={"min": 1})

    RUN_CONTROL: ClassVar[tuple[str, ...]] = (*HarnessConfig.RUN_CONTROL, "lobes", "gpu_throughput_batch")


class AccuracyHarness(Harness):
    name = "accuracy"
    Config = AccuracyConfig
    domains = ("merl_grid", "random_pairs")
    measures_on_device = True

    def __init__(self, config, context):
        super().__init__(config, context)

        forget_derived()  # the previous job's models' derived data (see brdfbench.reused)

    def measure(self, model, material, label: str) -> list[Measurement]:
        c, ctx = self.config, self.context
        dtype = getattr(torch, c.dtype)
        out = evaluate_accuracy(model, material, ctx.metric_specs, n_random=c.n_random, seed=ctx.seed, dtype=dtype)
        batch = c.throughput_batch if model.device.type == "cpu" else c.gpu_throughput_batch
        out.append(evaluation_throughput(model, batch=batch, seed=ctx.seed, dtype=dtype))
        width = lobes.table_half_width(material.table)
        if width is not None:
            out.append(Measurement(TARGET_HALF_WIDTH, width, "rad", False))
        if c.lobes and ctx.config_hash:
            self._save_lobes(model, material, label, dtype)
        return out

    def _save_lobes(self, model, material, label: str, dtype) -> None:
        ctx = self.context
        path = artifacts.index_path(ctx.results_dir, ctx.config_hash, material.name).with_suffix(".lobes.json")
        lobes.write(path, lobes.slices(on_host(model.eval, model.device), dtype), lobes.slices(material.table.lookup),
                    label, material.name)
        artifacts.record(ctx.results_dir, ctx.config_hash, material.name, "lobes", path,
                         theta_i_deg=list(lobes.THETA_I_DEG))
