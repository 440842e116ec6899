"""Pick and build the simulator a scene calls for (see the table in brdfbench.scenes)."""

from __future__ import annotations

from typing import Any

import torch

from .. import mitsuba_env
from ..plugins import registry
from ..errors import ConfigError
from ..scenes import PROCEDURAL_SKY, Environment, Scene
from .simulator import Simulator
from .closed_form import ClosedForm
from .direct import DirectMIS
from .envmap import Envmap, load_envmap, procedural_sky
from .mitsuba_sim import MitsubaSimulator


def build_sampler(name: str, params: dict[str, Any] | None = None):
    spec = registry.get("samplers", name)
    try:
        return spec.create(**(params or {}))
    except TypeError as exc:
        raise ConfigError(f"harness.sampler_params {params!r} do not fit sampler {name!r}: {exc}") from None


def load_environment(env: Environment):
    if env.source == PROCEDURAL_SKY:
        return Envmap(procedural_sky(), scale=env.scale)
    return load_envmap(env.source, scale=env.scale)


def build_simulator(scene: Scene, *, name: str | None = None, sampler: str = "cosine",
                    sampler_params: dict[str, Any] | None = None, spp: int | None = None,
                    dtype: torch.dtype = torch.float32, backend: str | None = None) -> Simulator:
    """The cheapest exact simulator for `scene`, or `name` if it is exact for the scene too.

    `backend` "mitsuba" runs closed form and direct MIS on Mitsuba's JIT (the default where
    drjit loads LLVM ≥ 19), "torch" in torch (the default elsewhere: scalar Mitsuba would
    take one sample per call); the path tracer is always Mitsuba's."""
    chosen = scene.chosen_simulator(name)
    if spp is not None and (isinstance(spp, bool) or not isinstance(spp, int) or spp < 1):
        raise ConfigError(f"harness.spp={spp!r} must be a positive integer")
    if backend not in (None, "mitsuba", "torch"):
        raise ConfigError(f"harness.backend={backend!r} must be 'mitsuba' or 'torch'")
    backend = backend or ("mitsuba" if chosen == "path" or mitsuba_env.choose_variant(warn=False) == mitsuba_env.LLVM_VARIANT
                          else "torch")
    if chosen in ("closed_form", "direct_mis", "path") and backend == "mitsuba":
        build_sampler(sampler, sampler_params)  # a bad sampler fails here, before any fitting
        env = load_environment(scene.environment) if scene.environment is not None else None
        return MitsubaSimulator(scene, env, kind=chosen, sampler=sampler, sampler_params=sampler_params or {}, spp=spp)
    if chosen == "closed_form":
        return ClosedForm(scene, dtype=dtype)
    if chosen == "direct_mis":
        return DirectMIS(scene, load_environment(scene.environment), build_sampler(sampler, sampler_params),
                         spp=spp, dtype=dtype)
    if chosen == "path":
        raise ConfigError("the path tracer runs on Mitsuba only (harness.backend=mitsuba)")
    raise ConfigError(f"scene {scene.name!r} is not rendered (simulator {chosen!r}); use the BRDF-space harness")
