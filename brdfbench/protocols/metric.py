"""What a metric is, for each domain a harness measures on; metric plugins implement these.

A metric class declares `unit`, `higher_is_better` and `domain`, which says how a harness
feeds it:

- `"merl_grid"`, `"random_pairs"` (`Metric`): BRDF values (N, 3) of the model and the
  target over the valid MERL cells or over random direction pairs, streamed in chunks;
- `"image"` (`ImageMetric`): a rendered image (H, W, 3) or a batch (N, H, W, 3) against the
  reference render, streamed image by image;
- `"set"` (`SetMetric`): a generated set S against a reference set R, from their distance
  matrices over one distance;
- `"image_set"` (`ImageSetMetric`): S against R from the two sets' rendered images.

Streaming metrics keep a mergeable state (a float64 sum and a count): `update` adds a
chunk, `merge` adds another instance's state (chunks scored apart, e.g. in two workers),
`compute` finishes, `reset` starts again. Chunking changes the result only by rounding.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import torch

#: The domains the built-in harnesses feed, in the order above.
DOMAINS = ("merl_grid", "random_pairs", "image", "set", "image_set")
#: The streaming domains (`update` / `merge` / `compute`), against the one-shot set domains.
STREAMING = ("merl_grid", "random_pairs", "image")


class StreamingMean:
    """A mean over everything `update` was given, with a state that merges."""

    unit: ClassVar[str] = ""
    higher_is_better: ClassVar[bool] = False
    domain: ClassVar[str] = ""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self._sum = 0.0
        self._count = 0

    def _add(self, values: torch.Tensor) -> None:
        self._sum += float(values.sum())
        self._count += values.numel()

    def merge(self, other: "StreamingMean") -> "StreamingMean":
        """Add `other`'s state to this one (same class): as if this had seen its chunks too."""
        if type(other) is not type(self):
            raise TypeError(f"{type(self).__name__}.merge({type(other).__name__}): only the same metric merges")
        self._sum += other._sum
        self._count += other._count
        return self

    def _finish(self, mean: float) -> float:
        """The figure from the mean (e.g. a square root for an RMSE); the mean by default."""
        return mean

    def compute(self) -> float:
        if self._count == 0:
            raise ValueError(f"{type(self).__name__}.compute() called before any update")
        return self._finish(self._sum / self._count)


class Metric(StreamingMean):
    """A BRDF-space metric: the mean of per-element `terms(pred, target, cos_i)` (N, 3) -> (N, 3)."""

    terms: ClassVar[Callable]
    domain: ClassVar[str] = "merl_grid"

    def update(self, pred: torch.Tensor, target: torch.Tensor, cos_i: torch.Tensor | None = None) -> None:
        self._add(type(self).terms(pred, target, cos_i))


class ImageMetric(StreamingMean):
    """An image metric: the mean over images of `values(pred, target)`, one value per image."""

    domain: ClassVar[str] = "image"

    def values(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """One value per image of a batch (N, H, W, 3), or of one image (H, W, 3)."""
        raise NotImplementedError

    def update(self, pred: torch.Tensor, target: torch.Tensor) -> None:
        """Add one image (H, W, 3) or a batch (N, H, W, 3) of images."""
        self._add(self.values(pred, target).reshape(-1))


class SetMetric:
    """A figure of S against R over one distance; `unit_for(distance_unit)` is its stored unit."""

    domain: ClassVar[str] = "set"
    unit: ClassVar[str] = ""
    higher_is_better: ClassVar[bool] = False
    #: True: `compute` takes `device=` (the job's device) for its own work.
    uses_device: ClassVar[bool] = False

    def unit_for(self, distance_unit: str) -> str:
        return self.unit

    def compute(self, d_rr, d_ss, d_rs) -> float:
        """From the distance matrices R×R, S×S and R×S (numpy, float64)."""
        raise NotImplementedError


class ImageSetMetric:
    """A figure of S against R from their rendered images (each a stack (N, H, W, 3))."""

    domain: ClassVar[str] = "image_set"
    unit: ClassVar[str] = ""
    higher_is_better: ClassVar[bool] = False
    uses_device: ClassVar[bool] = False

    def compute(self, images_r: Any, images_s: Any, **kwargs: Any) -> float:
        raise NotImplementedError
