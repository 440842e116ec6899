"""What every simulator shares: a render call, a finiteness check, and the cached camera hits.

A simulator turns (scene, representation) into a linear-radiance image (H, W, 3) float32.
Closed form and direct MIS evaluate the representation through its own torch `eval`; the
path tracer goes through the Mitsuba adapter. Non-finite radiance is never hidden: it
raises `RenderError` naming the material and how many pixels it spoiled.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import torch

from ..errors import RenderError
from ..protocols.representation import Representation
from ..scenes import Scene
from . import sphere
from .camera import Camera

Tensor = torch.Tensor


@dataclass(frozen=True)
class SphereHits:
    """Camera samples that hit the unit sphere: their sample index, shading frame and view direction."""

    index: Tensor  # (M,) positions in the flat sample array that hit
    frame: Tensor  # (M, 3, 3) rows s, t, n
    view: Tensor  # (M, 3) local direction toward the camera


def sphere_hits(camera: Camera, film: Tensor) -> SphereHits:
    origin, direction = camera.rays(film)
    t, hit = sphere.intersect(origin, direction)
    index = hit.nonzero().squeeze(1)
    point = origin[index] + t[index, None] * direction[index]
    normal = point / point.norm(dim=-1, keepdim=True)
    frame = sphere.shading_frame(normal)
    return SphereHits(index, frame, sphere.to_local(frame, -direction[index]))


class Simulator(ABC):
    """Renders one scene for any representation; `samples` is the camera samples per render."""

    name: str
    noise_free: bool = False

    def __init__(self, scene: Scene, *, dtype: torch.dtype = torch.float32):
        self.scene = scene
        self.dtype = dtype

    @property
    @abstractmethod
    def samples(self) -> int:
        """Camera samples one render takes (pixels × samples per pixel)."""

    @abstractmethod
    def _render(self, model: Representation, *, seed: int, material: str) -> Tensor:
        """Linear radiance (H, W, 3)."""

    def render(self, model: Representation, *, seed: int = 0, material: str = "", label: str = "") -> Tensor:
        """Linear radiance (H, W, 3) float32; RenderError if any pixel is NaN or infinite."""
        image = self._render(model, seed=seed, material=material).to(torch.float32)
        if np.isfinite(image.numpy()).all():  # numpy's check: cheaper than torch's on busy cores
            return image
        bad = ~torch.isfinite(image).all(dim=-1)
        if bool(bad.any()):
            who = label or type(model).__name__
            raise RenderError(
                f"{self.name} render of {who} on material {material or '?'}: {int(bad.sum())} of {bad.numel()} pixels "
                f"are NaN/Inf (the representation returned non-finite BRDF values)"
            )
        return image


def light_terms(scene: Scene) -> list[tuple[Tensor, Tensor]]:
    """(unit direction toward the light, irradiance) per directional light, fp64."""
    out = []
    for light in scene.lights:
        toward = -torch.tensor(light.direction, dtype=torch.float64)
        out.append((toward / toward.norm(), torch.tensor(light.irradiance, dtype=torch.float64)))
    return out


def eval_brdf(model: Representation, wi: Tensor, wo: Tensor, dtype: torch.dtype) -> Tensor:
    """BRDF values (N, 3) in fp64 for local directions given in any float dtype, evaluated in `dtype`."""
    return model.eval(wi.to(dtype), wo.to(dtype)).to(torch.float64)
