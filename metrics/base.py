"""Streaming metric classes: `update` over chunks, `compute` at the end, `reset` to reuse.

Sums accumulate in float64 so chunking does not change the result beyond rounding.
"""

from __future__ import annotations

from typing import Callable, ClassVar

import torch

from . import functional as F


class Metric:
    """Mean of per-element terms; subclasses set `terms`, `unit`, `higher_is_better`, `domain`."""

    terms: ClassVar[Callable]
    unit: ClassVar[str] = ""
    higher_is_better: ClassVar[bool] = False
    #: where the harness evaluates it: "merl_grid" (all valid table cells) or "random_pairs".
    domain: ClassVar[str] = "merl_grid"

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self._sum = 0.0
        self._count = 0

    def update(self, pred: torch.Tensor, target: torch.Tensor, cos_i: torch.Tensor | None = None) -> None:
        t = type(self).terms(pred, target, cos_i)
        self._sum += float(t.sum())
        self._count += t.numel()

    def _finish(self, mean: float) -> float:
        return mean

    def compute(self) -> float:
        if self._count == 0:
            raise ValueError(f"{type(self).__name__}.compute() called before any update")
        return self._finish(self._sum / self._count)


class L1(Metric):
    terms = staticmethod(F.l1_terms)
    unit = "1/sr"


class L1Log(Metric):
    terms = staticmethod(F.l1_log_terms)
    unit = "log(1+1/sr)"


class L1LogCos(Metric):
    terms = staticmethod(F.l1_log_cos_terms)
    unit = "log(1+1/sr)"


class HDRMAE(Metric):
    terms = staticmethod(F.l1_terms)
    unit = "1/sr"
    domain = "random_pairs"


class HDRRMSE(Metric):
    terms = staticmethod(F.squared_error_terms)
    unit = "1/sr"
    domain = "random_pairs"

    def _finish(self, mean: float) -> float:
        return mean ** 0.5
