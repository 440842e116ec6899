"""Streaming image metrics: `update` with one image or a batch, `compute` = mean over images.

Each concrete class fixes a metric and a space ("ldr" or "hdr", see `image_functional`), so
the registry builds it without arguments and its unit is exact; keyword arguments are the
functional metric's options, e.g. `PSNRHDR(data_range=4.0)` or `FLIPLDR(exposure=1.0)`.
`device=` (e.g. `SSIMLDR(device="cuda")`) is where MSE, RMSE, MAE, MAPE, PSNR and SSIM compute
(see `image_functional`); FLIP is numpy and always computes on the CPU, whatever `device` says.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import torch

from brdfbench.protocols.metric import ImageMetric as ImageMetricProtocol

from brdfbench.distances import image_functional as IF


class ImageMetric(ImageMetricProtocol):
    """Mean over images of a per-image value; subclasses set `fn`, `space`, `unit`, `higher_is_better`."""

    fn: ClassVar[Callable]
    space: ClassVar[str]
    #: True: `fn` is torch and takes `device`; False (FLIP): it computes on the CPU.
    torch_device: ClassVar[bool] = True

    def __init__(self, *, device: "torch.device | str | None" = None, **options: Any):
        if not hasattr(type(self), "space"):
            raise TypeError(f"{type(self).__name__} has no space; use its LDR or HDR subclass")
        self.options = options
        #: where the metric computes (None: where the images lie; FLIP: always the CPU)
        self.device = None if device is None else torch.device(device)
        super().__init__()

    def values(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        where = {"device": self.device} if self.device is not None and type(self).torch_device else {}
        return type(self).fn(pred, target, space=self.space, reduction="none", **where, **self.options)


class MSE(ImageMetric):
    fn = staticmethod(IF.mse)


class RMSE(ImageMetric):
    fn = staticmethod(IF.rmse)


class MAE(ImageMetric):
    fn = staticmethod(IF.mae)


class MAPE(ImageMetric):
    fn = staticmethod(IF.mape)
    unit = "%"
    higher_is_better = False


class PSNR(ImageMetric):
    fn = staticmethod(IF.psnr)
    unit = "dB"
    higher_is_better = True


class SSIM(ImageMetric):
    fn = staticmethod(IF.ssim)
    unit = "1"
    higher_is_better = True


class FLIP(ImageMetric):
    fn = staticmethod(IF.flip)
    unit = "1"
    torch_device = False  # flip-evaluator is numpy: FLIP runs on the CPU


# The (metric, space) pairs, one registered spec each. LDR values are display code values in [0, 1]
# (dimensionless); HDR values are radiance in the scene's units.

class MSELDR(MSE):
    space = "ldr"
    unit = "1"


class MSEHDR(MSE):
    space = "hdr"
    unit = "radiance²"


class RMSELDR(RMSE):
    space = "ldr"
    unit = "1"


class RMSEHDR(RMSE):
    space = "hdr"
    unit = "radiance"


class MAELDR(MAE):
    space = "ldr"
    unit = "1"


class MAEHDR(MAE):
    space = "hdr"
    unit = "radiance"


class MAPELDR(MAPE):
    space = "ldr"


class MAPEHDR(MAPE):
    space = "hdr"


class PSNRLDR(PSNR):
    space = "ldr"


class PSNRHDR(PSNR):
    space = "hdr"


class SSIMLDR(SSIM):
    space = "ldr"


class SSIMHDR(SSIM):
    space = "hdr"


class FLIPLDR(FLIP):
    space = "ldr"


class FLIPHDR(FLIP):
    space = "hdr"
