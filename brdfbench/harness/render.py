"""Image-space accuracy: render each material with the representation and with its
tabulated ground truth through the same simulator, and compare the images.

The reference is the target's MERL table (nearest-cell lookup, as the reference reader
does), rendered with the same seed, so Monte Carlo simulators draw the same directions for
both images wherever the sampler does not depend on the material: the comparison then
measures the representation, not the noise. References are cached on disk per (scene,
simulator, sampler, spp, seed, dataset, material) and reused across the representations
of a sweep. Images land as EXR (radiance) and PNG (tone-mapped) under
`<results>/renders/<scene>/<simulator key>/`. With `harness.display_spp`, each cell also
saves the pair the report shows (`DisplayRenders`: that spp, and a BRDF sampler fitted to
the material), which no metric sees.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar

import torch

from .. import artifacts, images
from ..errors import ConfigError, DataError
from ..protocols.representation import Material, Representation
from ..provenance import config_hash
from ..plugins.specs import MetricSpec
from . import Harness, HarnessConfig, HarnessContext, Measurement
from ..plugins import registry
from ..render.build import build_sampler, build_simulator

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
        from ..render.drjit_kernels import table_kernel  # lazy: drjit

        return table_kernel(self.table.values, name="reference")

    def fit(self, target, *, seed=0):
        raise NotImplementedError

    def state_dict(self):
        return {}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        raise NotImplementedError


class RenderScorer:
    """Renders, scores and saves; `measure` returns the image metrics plus render cost."""

    def __init__(self, simulator, metric_specs: list[MetricSpec], *, out_dir: Path, dataset_fingerprint: str,
                 seed: int = 0, exposure: float = 0.0, save_images: bool = True, key: dict[str, Any] | None = None,
                 record_to: tuple[Path, str] | None = None, image_meta: dict[str, Any] | None = None,
                 display=None):
        """`record_to` (results folder, config hash): index each saved image there
        (`brdfbench.artifacts`) with `image_meta` (spp, sampler, simulator) for the report.
        `display` (`DisplayRenders`): the renders of the model and of the table saved for
        a person to look at, converged at display size; the metrics never see them."""
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

        results_dir, chash = self.record_to
        for kind, path in (("image", exr), ("reference", reference)):
            artifacts.record(results_dir, chash, material.name, kind, path, png=str(path.with_suffix(".png").name),
                             exposure=self.exposure, **meta)

    def _folder(self, label: str) -> str:
        """A configuration's image folder: its label, and its config hash where known (two
        configurations of one label in a sweep must not share files)."""
        return label if self.record_to is None else f"{label}-{self.record_to[1][:8]}"

    def _save(self, model: Representation, material: Material, label: str, image: torch.Tensor) -> None:
        """Save the measured render; with display renders, also the converged pair shown."""
        folder = self.dir / self._folder(label)
        exr = folder / f"{material.name}.exr"
        save_image(exr, image, exposure=self.exposure)
        if self.display is None:
            return self._record(material, exr, self.dir / "reference" / f"{material.name}.exr", self.image_meta)
        simulator, sampler, params = self.display.for_material(material)
        shown = folder / f"{material.name}.display.exr"
        save_image(shown, simulator.render(model, seed=self.seed, material=material.name, label=label),
                   exposure=self.exposure)
        reference = self.dir / "reference" / f"{material.name}.{self.display.key(sampler, params)}.display.exr"
        cached_render(reference, lambda: simulator.render(TableReference(material), seed=self.seed,
                                                          material=material.name, label="reference"),
                      exposure=self.exposure, what="the display reference")
        meta = dict(self.image_meta, spp=self.display.spp, measured_spp=self.image_meta.get("spp"), sampler=sampler,
                    sampler_params=params, display_sampler=self.display.sampler,
                    measured_sampler=self.image_meta.get("sampler"))
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


# --------------------------------------------------------------------------- display renders

#: The samplers a material's display sampler is fitted among: cosine for diffuse lobes,
#: GGX visible normals from sharp to broad for the rest.
DISPLAY_CANDIDATES: tuple[tuple[str, dict[str, float]], ...] = (
    ("cosine", {}), *(("ggx_vndf", {"alpha": a}) for a in (0.03, 0.06, 0.12, 0.25, 0.5)))
FITTED = "fitted"
_VIEWS_DEG = (10.0, 40.0, 70.0)


def fitted_sampler(material: Material, candidates=DISPLAY_CANDIDATES, n: int = 4096) -> tuple[str, dict[str, float]]:
    """The candidate whose one-sample estimate of the table's reflected luminance,
    f·cosθ/pdf, has the least relative variance, averaged over three view inclinations: the
    BRDF half of direct MIS fitted to the material, so that a sharp lobe and a diffuse one
    both look converged. Deterministic (fixed random numbers)."""
    table = TableReference(material)
    views = torch.tensor([[math.sin(math.radians(d)), 0.0, math.cos(math.radians(d))] for d in _VIEWS_DEG],
                         dtype=torch.float64).repeat_interleave(n, 0)
    u = torch.rand(views.shape[0], 2, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    luminance = torch.tensor([0.2126, 0.7152, 0.0722], dtype=torch.float64)
    best, best_score = candidates[0], math.inf
    for name, params in candidates:
        sampler = build_sampler(name, params)
        wi = sampler.sample(views, u)
        wi = wi / wi.norm(dim=-1, keepdim=True)
        pdf = sampler.pdf(views, wi)
        f = table.eval(wi, views).to(torch.float64) @ luminance
        w = torch.where(pdf > 0, f * wi[:, 2].clamp_min(0) / pdf.clamp_min(1e-300), 0.0).reshape(len(_VIEWS_DEG), n)
        score = float((w.var(dim=1) / w.mean(dim=1).clamp_min(1e-12) ** 2).mean())
        if score < best_score:
            best, best_score = (name, params), score
    return best[0], dict(best[1])


class DisplayRenders:
    """The simulators of the images a person looks at: `spp` samples per pixel and, per
    material, the display sampler (`fitted_sampler` for "fitted"), one simulator per
    sampler. Run control: the measured renders keep their own spp and sampler."""

    def __init__(self, build: Callable[[str, dict[str, Any]], Any], sampler: str, sampler_params: dict[str, Any],
                 spp: int):
        self.build, self.sampler, self.sampler_params, self.spp = build, sampler, dict(sampler_params), spp
        self._chosen: dict[str, tuple[str, dict[str, Any]]] = {}
        self._simulators: dict[str, Any] = {}

    def key(self, sampler: str, params: dict[str, Any]) -> str:
        """Names a display reference by what renders it, so another spp or sampler renders it afresh."""
        return config_hash({"sampler": sampler, "sampler_params": params, "spp": self.spp})[:8]

    def for_material(self, material: Material) -> tuple[Any, str, dict[str, Any]]:
        """(simulator, sampler name, its parameters) of a material's display renders."""
        if material.name not in self._chosen:
            self._chosen[material.name] = (fitted_sampler(material) if self.sampler == FITTED
                                           else (self.sampler, self.sampler_params))
        sampler, params = self._chosen[material.name]
        key = self.key(sampler, params)
        if key not in self._simulators:
            self._simulators[key] = self.build(sampler, params)
        return self._simulators[key], sampler, params


# --------------------------------------------------------------------------- the harness plugin

#: Simulators whose renders carry Monte Carlo noise (the closed form is noise-free).
MONTE_CARLO = ("direct_mis", "path")


@dataclass(frozen=True)
class RenderConfig(HarnessConfig):
    kind: str = "render"
    metrics: tuple[str, ...] = ()  # the shipped harness=render option lists the default metrics
    timeout_s: float | None = field(default=1800.0, metadata={"min_exclusive": 0})
    simulator: str | None = None  # None: the cheapest exact one for the scene
    backend: str | None = field(default=None, metadata={"choices": ("mitsuba", "torch")})  # None: mitsuba where LLVM >= 19 loads
    sampler: str = "cosine"  # BRDF importance sampler of Monte Carlo simulators
    sampler_params: dict[str, Any] = field(default_factory=dict)
    spp: int | None = field(default=None, metadata={"min": 1})  # samples per pixel; None: the scene's
    exposure: float = 0.0  # stops, for tone-mapped (LDR) metrics and PNGs
    save_images: bool = True
    # Monte Carlo simulators: also save renders at this spp for the report's image grids (a
    # person judges converged images; the metrics never see them), with `display_sampler`
    # ("fitted": chosen per material, see `fitted_sampler`; else a sampler's name, with
    # `sampler_params` where it is `sampler`). Run control: not hashed.
    display_spp: int | None = field(default=None, metadata={"min": 1})
    display_sampler: str = FITTED

    RUN_CONTROL: ClassVar[tuple[str, ...]] = (*HarnessConfig.RUN_CONTROL, "display_spp", "display_sampler")


def check_simulation(config, scene) -> None:
    """Light up-front checks of the simulator, backend and sampler a rendered harness asks for."""
    scene.chosen_simulator(config.simulator)
    spec = registry.get("samplers", config.sampler)
    try:
        spec.create(**config.sampler_params)
    except TypeError as exc:
        raise ConfigError(f"harness.sampler_params={config.sampler_params!r} for sampler {config.sampler!r}: {exc}") from None


class RenderHarness(Harness):
    """Image-space accuracy (`harness=render`): see `RenderScorer`."""

    name = "render"
    Config = RenderConfig
    domains = ("image",)
    rendered = True

    @classmethod
    def validate(cls, config, scene, metric_specs) -> None:
        super().validate(config, scene, metric_specs)
        check_simulation(config, scene)
        if config.display_sampler != FITTED:
            registry.get("samplers", config.display_sampler)

    @classmethod
    def columns(cls, config, scene) -> dict[str, Any]:
        chosen = config.simulator or scene.simulator()
        return {"scene": scene.name, "sampler": config.sampler if chosen in MONTE_CARLO else ""}

    def __init__(self, config: RenderConfig, context: HarnessContext):
        super().__init__(config, context)

        c = config
        simulator = build_simulator(context.scene, name=c.simulator, sampler=c.sampler, sampler_params=c.sampler_params,
                                    spp=c.spp, dtype=getattr(torch, c.dtype), backend=c.backend)
        measured_spp = c.spp or context.scene.spp
        display = None
        if c.save_images and c.display_spp and simulator.name in MONTE_CARLO and c.display_spp > measured_spp:
            display = DisplayRenders(
                lambda sampler, params: build_simulator(context.scene, name=c.simulator, sampler=sampler,
                                                        sampler_params=params, spp=c.display_spp,
                                                        dtype=getattr(torch, c.dtype), backend=c.backend),
                c.display_sampler, c.sampler_params if c.display_sampler == c.sampler else {}, c.display_spp)
        self.harness = RenderScorer(
            simulator, context.metric_specs, out_dir=context.results_dir / "renders" / context.scene.name,
            dataset_fingerprint=context.dataset_fingerprint, seed=context.seed, exposure=c.exposure,
            save_images=c.save_images,
            key={"scene": context.scene_name, "scene_params": context.scene_params, "simulator": simulator.name,
                 "backend": simulator.backend, "sampler": c.sampler, "sampler_params": c.sampler_params, "spp": c.spp,
                 "dtype": c.dtype},
            record_to=(context.results_dir, context.config_hash) if context.config_hash else None,
            image_meta={"simulator": simulator.name,
                        "spp": measured_spp if simulator.name in MONTE_CARLO else None,
                        "sampler": c.sampler if simulator.name in MONTE_CARLO else None},
            display=display,
        )

    def measure(self, model, material, label: str) -> list[Measurement]:
        return self.harness.measure(model, material, label)
