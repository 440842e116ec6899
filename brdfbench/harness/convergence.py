"""Monte Carlo convergence: how fast a model's own render converges, per sampler.

For one fitted model and material, render the scene at every spp of a ladder (default
1, 2, 4, …, 64) and compare each image with a render of the SAME model at
`reference_spp` (default 1024). Both sides evaluate the same representation, so the error
is Monte Carlo noise only, not representation error: it measures how well the importance
sampler suits that representation (Sztrajman et al. 2021's error-vs-spp plots).

Every render draws its own random numbers (a seed derived from the base seed per rung
and for the reference), so rung errors are independent samples and not correlated
through shared directions; each rung is a separate render. With per-sample variance σ²,
the expected squared error at n spp is σ²(1/n + 1/N) for an N-spp reference: at the
default top rung the reference adds 1/16 of the rung's own noise.

Per rung the harness records the image metrics of `harness.metrics` (as shipped: the RMSE,
MAE, MAPE and PSNR of HDR radiance, the four panels of Sztrajman et al.'s convergence
figures), the relative MSE, the render time (so error against time is available) and
`convergence_rmse`, the RMSE of HDR radiance that the 1/√spp law is about, whatever
`harness.metrics` holds; over the rungs, the least-squares slope of its log against log spp
(−½ for an unbiased estimator of finite variance; flatter when rare fireflies dominate,
since a few spp seldom catch them) and its value at 1 spp implied by the 1/√spp law
fitted to all rungs, a one-number efficiency of the sampler.
"""

from __future__ import annotations

import copy
import hashlib
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import torch

from ..distances.image_functional import rmse
from ..errors import ConfigError
from ..protocols.representation import Material, Representation
from ..provenance import config_hash
from ..plugins.specs import MetricSpec
from . import Harness, HarnessContext, Measurement
from .render import MONTE_CARLO, RenderConfig, cached_render, check_simulation
from ..render.build import build_simulator

#: ε of the relative MSE (p − r)² / (r² + ε), as in denoising work (Rousselle et al. 2011).
RELMSE_EPS = 1e-2


# --------------------------------------------------------------------------- configuration


def check_ladder(ladder: Any, reference_spp: Any) -> tuple[int, ...]:
    """The ladder as a tuple of ints; ConfigError naming the key unless it is at least two
    strictly increasing positive integers, all below an integer `reference_spp`."""
    if isinstance(ladder, (str, bytes)) or not isinstance(ladder, Sequence):
        raise ConfigError(f"harness.spp_ladder={ladder!r} must be a list of positive integers")
    if len(ladder) < 2 or any(isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in ladder):
        raise ConfigError(f"harness.spp_ladder={list(ladder)!r} must hold at least two positive integers "
                          "(a slope needs two rungs)")
    if any(b <= a for a, b in zip(ladder, ladder[1:])):
        raise ConfigError(f"harness.spp_ladder={list(ladder)!r} must be strictly increasing")
    if isinstance(reference_spp, bool) or not isinstance(reference_spp, int) or reference_spp <= ladder[-1]:
        raise ConfigError(f"harness.reference_spp={reference_spp!r} must be an integer above the ladder's top "
                          f"rung {ladder[-1]} (the reference must be much less noisy than any rung)")
    return tuple(ladder)


def check_config(harness, scene) -> None:
    """Up-front checks of a convergence harness on `scene` (before any fitting)."""
    if harness.spp is not None:
        raise ConfigError(f"harness.spp={harness.spp!r} must be null for harness=convergence: "
                          "harness.spp_ladder and harness.reference_spp set the samples per pixel")
    chosen = harness.simulator or scene.simulator()
    if chosen not in MONTE_CARLO:
        raise ConfigError(f"scene={scene.name!r} renders with harness.simulator={chosen!r}, which is noise-free: "
                          f"harness=convergence needs a Monte Carlo simulator ({', '.join(MONTE_CARLO)}), "
                          "e.g. scene=sphere_envmap")
    check_ladder(harness.spp_ladder, harness.reference_spp)


def sampler_label(sampler: str, sampler_params: dict[str, Any] | None = None) -> str:
    """The store's sampler column, so samplers and their parameters stay apart: `ggx(alpha=0.2)`."""
    params = ",".join(f"{k}={v}" for k, v in sorted((sampler_params or {}).items()))
    return sampler + (f"({params})" if params else "")


def derive_seed(seed: int, tag: str) -> int:
    """An independent seed per (base seed, render), so rungs and reference never share random
    numbers; 31 bits, within every simulator's range (Mitsuba's samplers take 32-bit seeds)."""
    digest = hashlib.sha256(f"brdfbench-convergence/{seed}/{tag}".encode()).digest()
    return int.from_bytes(digest[:4], "little") >> 1


# --------------------------------------------------------------------------- errors and the fit


def image_metric(spec: MetricSpec, image: torch.Tensor, reference: torch.Tensor) -> Measurement:
    """One registered image metric of `image` against `reference`, with the spec's unit and direction."""
    metric = spec.load()()
    metric.update(image, reference)
    return Measurement(spec.name, float(metric.compute()), spec.unit, spec.higher_is_better)


def relative_mse(image: torch.Tensor, reference: torch.Tensor, eps: float = RELMSE_EPS) -> float:
    """Mean over pixels and channels of (p − r)² / (r² + ε): squared error relative to brightness."""
    p, r = image.to(torch.float64), reference.to(torch.float64)
    return float(((p - r) ** 2 / (r * r + eps)).mean())


def fit_slope(spp: Sequence[int], errors: Sequence[float]) -> tuple[float, float]:
    """(slope of log error on log spp by least squares, error at 1 spp under the 1/√spp law).

    Rungs with zero error (a noise-free image) carry no rate and are left out; NaN when
    fewer than two rungs remain."""
    pts = [(math.log(n), math.log(e)) for n, e in zip(spp, errors) if e > 0 and math.isfinite(e)]
    if len(pts) < 2:
        return math.nan, math.nan
    x = torch.tensor([p[0] for p in pts], dtype=torch.float64)
    y = torch.tensor([p[1] for p in pts], dtype=torch.float64)
    xc = x - x.mean()
    slope = float((xc * (y - y.mean())).sum() / (xc * xc).sum())
    return slope, float(torch.exp((y + 0.5 * x).mean()))


# --------------------------------------------------------------------------- the harness


def _at_spp(simulator, spp: int, build: Callable[[int], Any]):
    """`simulator` at another spp: a shallow copy with its `spp` set, where that attribute sets
    its sample count (the built-in simulators do); otherwise a fresh `build(spp)`."""
    own = getattr(simulator, "spp", None)
    if isinstance(own, int) and own > 0 and simulator.samples % own == 0:
        twin = copy.copy(simulator)
        twin.spp = spp
        if twin.samples == simulator.samples // own * spp:
            return twin
    return build(spp)


class ConvergenceLadder:
    """Error of renders along an spp ladder against the same model's high-spp render.

    `build(spp)` returns the simulator at that spp (sampler, scene and dtype fixed). It is
    called once, for the reference; the rungs are copies of that simulator at their spp
    (sharing its environment map and sampler, which take longer to build than a small
    render), or their own `build` where a simulator keeps no `spp` attribute to set.
    All are made up front and reused for every material. References are cached as
    EXR under `out_dir/<key hash>/reference/<label>/<material>.exr`, keyed by everything
    that changes them (the runner passes scene, sampler, dtype, representation and its
    parameters; the simulator and backend are read off the built simulators), so a re-run
    with another ladder does not render them again. Each rung is rendered once untimed
    before its timed render, so its time leaves out one-time costs (JIT compilation of
    the kernels of that spp, first-call caches) and reflects the cost of the samples.
    """

    def __init__(self, build: Callable[[int], Any], ladder: Sequence[int], reference_spp: int, *,
                 metrics: Sequence[MetricSpec], out_dir: Path, dataset_fingerprint: str, seed: int = 0,
                 exposure: float = 0.0, save_images: bool = True, key: dict[str, Any] | None = None):
        """`metrics`: the image metrics measured at every rung, beside `convergence_rmse`."""
        self.metrics = tuple(metrics)
        self.ladder = check_ladder(ladder, reference_spp)
        self.reference_spp = reference_spp
        self.reference_simulator = build(reference_spp)
        self.rungs = {n: _at_spp(self.reference_simulator, n, build) for n in self.ladder}
        self.seed = seed
        self.exposure = exposure
        self.save_images = save_images
        first = self.rungs[self.ladder[0]]
        if getattr(first, "noise_free", False):
            raise ConfigError(f"harness.simulator={first.name!r} is noise-free: "
                              "harness=convergence needs a Monte Carlo simulator")
        key = {**(key or {}), "simulator": first.name, "backend": getattr(first, "backend", None),
               "reference_spp": reference_spp, "dataset": dataset_fingerprint, "seed": seed}
        self.dir = Path(out_dir) / config_hash(key)[:12]

    def reference(self, model: Representation, material: Material, label: str) -> torch.Tensor:
        """The model's own `reference_spp` render, from the cache when a readable one is there."""
        return cached_render(
            self.dir / "reference" / label / f"{material.name}.exr",
            lambda: self.reference_simulator.render(model, seed=derive_seed(self.seed, "reference"),
                                                    material=material.name, label=f"{label} reference"),
            exposure=self.exposure, png=self.save_images, what="the convergence reference",
        )

    def measure(self, model: Representation, material: Material, label: str) -> list[Measurement]:
        """Per rung: each metric, relmse_hdr, convergence_rmse and render_time; then, of
        convergence_rmse, convergence_slope and convergence_rmse_1spp (its value at 1 spp
        under the 1/√spp law)."""
        reference = self.reference(model, material, label)
        out, errors = [], []
        for n, simulator in self.rungs.items():
            who = {"material": material.name, "label": label}
            simulator.render(model, seed=derive_seed(self.seed, f"warm-up/spp={n}"), **who)
            t0 = time.perf_counter()
            image = simulator.render(model, seed=derive_seed(self.seed, f"spp={n}"), **who)
            seconds = time.perf_counter() - t0
            black = not bool((reference > 0).any())
            rung = []
            for spec in self.metrics:
                try:
                    rung.append(image_metric(spec, image, reference))
                except ValueError:  # a metric relative to the reference's range (HDR PSNR) has none
                    if not black:
                        raise
            error = float(rmse(image, reference, space="hdr"))
            errors.append(error)
            out += [Measurement(m.metric, m.value, m.unit, m.higher_is_better, spp=n) for m in rung]
            out += [
                Measurement("convergence_rmse", error, "radiance", False, spp=n),
                Measurement("relmse_hdr", relative_mse(image, reference), "1", False, spp=n),
                Measurement("render_time", seconds, "s", False, spp=n),
            ]
        slope, at_one = fit_slope(self.ladder, errors)
        if math.isfinite(slope):
            out += [Measurement("convergence_slope", slope, "1", False),
                    Measurement("convergence_rmse_1spp", at_one, "radiance", False)]
        return out


# --------------------------------------------------------------------------- the harness plugin


@dataclass(frozen=True)
class ConvergenceConfig(RenderConfig):
    kind: str = "convergence"
    metrics: tuple[str, ...] = ()  # measured per rung, the first one's slope fitted (the shipped option lists them)
    spp_ladder: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64)  # spp of the rungs, strictly increasing
    reference_spp: int = 1024  # spp of the model's own reference render; above the ladder


class ConvergenceHarness(Harness):
    """Error against spp (`harness=convergence`): see `ConvergenceLadder`."""

    name = "convergence"
    Config = ConvergenceConfig
    domains = ("image",)
    rendered = True

    @classmethod
    def validate(cls, config, scene, metric_specs) -> None:
        super().validate(config, scene, metric_specs)
        check_config(config, scene)
        check_simulation(config, scene)

    @classmethod
    def columns(cls, config, scene) -> dict[str, Any]:
        return {"scene": scene.name, "sampler": sampler_label(config.sampler, config.sampler_params)}

    def __init__(self, config: ConvergenceConfig, context: HarnessContext):
        super().__init__(config, context)

        c = config

        def build(spp: int):
            return build_simulator(context.scene, name=c.simulator, sampler=c.sampler, sampler_params=c.sampler_params,
                                   spp=spp, dtype=getattr(torch, c.dtype), backend=c.backend)

        self.harness = ConvergenceLadder(
            build, c.spp_ladder, c.reference_spp, metrics=context.metric_specs,
            out_dir=context.results_dir / "renders" / context.scene.name / "convergence",
            dataset_fingerprint=context.dataset_fingerprint, seed=context.seed, exposure=c.exposure,
            save_images=c.save_images,
            key={"scene": context.scene_name, "scene_params": context.scene_params, "sampler": c.sampler,
                 "sampler_params": c.sampler_params, "dtype": c.dtype, "representation": context.representation,
                 "params": context.representation_params},
        )

    def measure(self, model, material, label: str) -> list[Measurement]:
        return self.harness.measure(model, material, label)
