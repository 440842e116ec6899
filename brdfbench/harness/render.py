"""Image-space accuracy: render each material with the representation and with its
tabulated ground truth through the same simulator, and compare the images.

The reference is the target's MERL table (nearest-cell lookup, as the reference reader
does), rendered with the same seed, so Monte Carlo simulators draw the same directions for
both images wherever the sampler does not depend on the material: the comparison then
measures the representation, not the noise. References are cached on disk per (scene,
simulator, sampler, spp, seed, dataset, material) and reused across the representations
of a sweep. Images land as EXR (radiance) and PNG (tone-mapped) under
`<results>/renders/<scene>/<simulator key>/`.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Callable

import torch

from .. import images
from ..errors import DataError
from ..protocol import Material, Representation
from ..provenance import config_hash
from ..specs import MetricSpec
from . import Measurement

log = logging.getLogger(__name__)


class TableReference(Representation):
    """The target's own table as a representation: the ground truth a render is compared with."""

    def __init__(self, material: Material):
        super().__init__()
        self.table = material.table

    def _eval(self, wi, wo):
        return self.table.lookup(wi.to(torch.float64), wo.to(torch.float64), "nearest").clamp_min(0.0)

    def drjit_kernel(self):
        """The same nearest-cell lookup as a drjit gather, for the Mitsuba adapter."""
        from ..render.drjit_kernels import table_kernel

        return table_kernel(self.table.values, name="reference")

    def fit(self, target, *, seed=0):
        raise NotImplementedError

    def state_dict(self):
        return {}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        raise NotImplementedError


class RenderHarness:
    """Renders, scores and saves; `measure` returns the image metrics plus render cost."""

    def __init__(self, simulator, metric_specs: list[MetricSpec], *, out_dir: Path, dataset_fingerprint: str,
                 seed: int = 0, exposure: float = 0.0, save_images: bool = True, key: dict[str, Any] | None = None):
        self.simulator = simulator
        self.metric_specs = metric_specs
        self.seed = seed
        self.exposure = exposure
        self.save_images = save_images
        self.dir = Path(out_dir) / config_hash({**(key or {}), "dataset": dataset_fingerprint, "seed": seed})[:12]

    def reference(self, material: Material) -> torch.Tensor:
        return cached_render(
            self.dir / "reference" / f"{material.name}.exr",
            lambda: self.simulator.render(TableReference(material), seed=self.seed, material=material.name, label="reference"),
            exposure=self.exposure, what="the reference",
        )

    def measure(self, model: Representation, material: Material, label: str) -> list[Measurement]:
        reference = self.reference(material)
        t0 = time.perf_counter()
        image = self.simulator.render(model, seed=self.seed, material=material.name, label=label)
        seconds = time.perf_counter() - t0
        if self.save_images:
            save_image(self.dir / label / f"{material.name}.exr", image, exposure=self.exposure)
        out = []
        for spec in self.metric_specs:
            metric = spec.load()(exposure=self.exposure)
            metric.update(image, reference)
            out.append(Measurement(spec.name, metric.compute(), spec.unit, spec.higher_is_better))
        out.append(Measurement("render_time", seconds, "s", False))
        out.append(Measurement("render_samples_per_s", self.simulator.samples / seconds, "samples/s", True))
        return out


def save_image(exr: Path, image: torch.Tensor, *, exposure: float, png: bool = True) -> None:
    """Write the radiance as EXR and, with `png`, the tone-mapped image beside it."""
    exr.parent.mkdir(parents=True, exist_ok=True)
    images.write_exr(exr, image)
    if png:
        images.write_png(exr.with_suffix(".png"), image, exposure=exposure)


def cached_render(exr: Path, render: Callable[[], torch.Tensor], *, exposure: float, png: bool = True,
                  what: str = "the image") -> torch.Tensor:
    """The image cached at `exr` when it reads back, else `render()`, saved there."""
    if exr.is_file():
        try:
            return images.read_exr(exr)
        except DataError as exc:  # a damaged cache entry is rendered again, not trusted
            log.warning("re-rendering %s: %s", what, exc)
    image = render()
    save_image(exr, image, exposure=exposure, png=png)
    return image

