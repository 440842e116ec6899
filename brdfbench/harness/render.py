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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar

import torch

from .. import images
from ..errors import ConfigError, DataError
from ..protocol import Material, Representation
from ..provenance import config_hash
from ..specs import MetricSpec
from . import Harness, HarnessConfig, HarnessContext, Measurement

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
                 seed: int = 0, exposure: float = 0.0, save_images: bool = True, key: dict[str, Any] | None = None,
                 record_to: tuple[Path, str] | None = None, image_meta: dict[str, Any] | None = None,
                 display=None):
        """`record_to` (results folder, config hash): index each saved image there
        (`brdfbench.artifacts`) with `image_meta` (spp, sampler, simulator) for the report.
        `display`: a simulator at more samples per pixel whose renders (of the model and
        of the table) are saved for a person to look at; the metrics never see them."""
        self.simulator = simulator
        self.display = display
        self.record_to = record_to
        self.image_meta = dict(image_meta or {})
        self.metric_specs = metric_specs
        self.seed = seed
        self.exposure = exposure
        self.save_images = save_images
        self.dir = Path(out_dir) / config_hash({**(key or {}), "dataset": dataset_fingerprint, "seed": seed})[:12]

    def _record(self, material: Material, exr: Path, reference: Path, meta: dict[str, Any]) -> None:
        if self.record_to is None:
            return
        from .. import artifacts

        results_dir, chash = self.record_to
        for kind, path in (("image", exr), ("reference", reference)):
            artifacts.record(results_dir, chash, material.name, kind, path, png=str(path.with_suffix(".png").name),
                             exposure=self.exposure, **meta)

    def _folder(self, label: str) -> str:
        """A configuration's image folder: its label, and its config hash where known (two
        configurations of one label in a sweep must not share files)."""
        return label if self.record_to is None else f"{label}-{self.record_to[1][:8]}"

    def _save(self, model: Representation, material: Material, label: str, image: torch.Tensor) -> None:
        """Save the measured render; with a display simulator, also the converged pair shown."""
        folder = self.dir / self._folder(label)
        exr = folder / f"{material.name}.exr"
        save_image(exr, image, exposure=self.exposure)
        if self.display is None:
            return self._record(material, exr, self.dir / "reference" / f"{material.name}.exr", self.image_meta)
        shown = folder / f"{material.name}.display.exr"
        save_image(shown, self.display.render(model, seed=self.seed, material=material.name, label=label),
                   exposure=self.exposure)
        reference = self.dir / "reference" / f"{material.name}.display.exr"
        cached_render(reference, lambda: self.display.render(TableReference(material), seed=self.seed,
                                                             material=material.name, label="reference"),
                      exposure=self.exposure, what="the display reference")
        meta = dict(self.image_meta, spp=self.image_meta.get("display_spp"), measured_spp=self.image_meta.get("spp"))
        self._record(material, shown, reference, meta)

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
            self._save(model, material, label, image)
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



# --------------------------------------------------------------------------- the harness plugin

#: Simulators whose renders carry Monte Carlo noise (the closed form is noise-free).
MONTE_CARLO = ("direct_mis", "path")


@dataclass(frozen=True)
class RenderConfig(HarnessConfig):
    kind: str = "render"
    metrics: tuple[str, ...] = ("psnr_ldr", "ssim_ldr", "flip_ldr", "rmse_hdr")
    timeout_s: float | None = field(default=1800.0, metadata={"min_exclusive": 0})
    simulator: str | None = None  # None: the cheapest exact one for the scene
    backend: str | None = field(default=None, metadata={"choices": ("mitsuba", "torch")})  # None: mitsuba where LLVM >= 19 loads
    sampler: str = "cosine"  # BRDF importance sampler of Monte Carlo simulators
    sampler_params: dict[str, Any] = field(default_factory=dict)
    spp: int | None = field(default=None, metadata={"min": 1})  # samples per pixel; None: the scene's
    exposure: float = 0.0  # stops, for tone-mapped (LDR) metrics and PNGs
    save_images: bool = True
    # Monte Carlo simulators: also save renders at this spp for the report's image grids (a
    # person judges converged images; the metrics never see them). Run control: not hashed.
    display_spp: int | None = field(default=None, metadata={"min": 1})

    RUN_CONTROL: ClassVar[tuple[str, ...]] = (*HarnessConfig.RUN_CONTROL, "display_spp")


def check_simulation(config, scene) -> None:
    """Light up-front checks of the simulator, backend and sampler a rendered harness asks for."""
    from .. import registry

    scene.chosen_simulator(config.simulator)
    spec = registry.get("samplers", config.sampler)
    try:
        spec.create(**config.sampler_params)
    except TypeError as exc:
        raise ConfigError(f"harness.sampler_params={config.sampler_params!r} for sampler {config.sampler!r}: {exc}") from None


class ImageHarness(Harness):
    """Image-space accuracy (`harness=render`): see `RenderHarness`."""

    name = "render"
    Config = RenderConfig
    domains = ("image",)
    rendered = True

    @classmethod
    def validate(cls, config, scene, metric_specs) -> None:
        super().validate(config, scene, metric_specs)
        check_simulation(config, scene)

    @classmethod
    def columns(cls, config, scene) -> dict[str, Any]:
        chosen = config.simulator or scene.simulator()
        return {"scene": scene.name, "sampler": config.sampler if chosen in MONTE_CARLO else ""}

    def __init__(self, config: RenderConfig, context: HarnessContext):
        super().__init__(config, context)
        from ..render.simulate import build_simulator

        c = config
        simulator = build_simulator(context.scene, name=c.simulator, sampler=c.sampler, sampler_params=c.sampler_params,
                                    spp=c.spp, dtype=getattr(torch, c.dtype), backend=c.backend)
        measured_spp = c.spp or context.scene.spp
        display = None
        if c.save_images and c.display_spp and simulator.name in MONTE_CARLO and c.display_spp > measured_spp:
            display = build_simulator(context.scene, name=c.simulator, sampler=c.sampler,
                                      sampler_params=c.sampler_params, spp=c.display_spp, dtype=getattr(torch, c.dtype),
                                      backend=c.backend)
        self.harness = RenderHarness(
            simulator, context.metric_specs, out_dir=context.results_dir / "renders" / context.scene.name,
            dataset_fingerprint=context.dataset_fingerprint, seed=context.seed, exposure=c.exposure,
            save_images=c.save_images,
            key={"scene": context.scene_name, "scene_params": context.scene_params, "simulator": simulator.name,
                 "backend": simulator.backend, "sampler": c.sampler, "sampler_params": c.sampler_params, "spp": c.spp,
                 "dtype": c.dtype},
            record_to=(context.results_dir, context.config_hash) if context.config_hash else None,
            image_meta={"simulator": simulator.name,
                        "spp": measured_spp if simulator.name in MONTE_CARLO else None,
                        "display_spp": c.display_spp if display is not None else None,
                        "sampler": c.sampler if simulator.name in MONTE_CARLO else None},
            display=display,
        )

    def measure(self, model, material, label: str) -> list[Measurement]:
        return self.harness.measure(model, material, label)
