"""Closed form for a convex object under directional lights: noise-free, one BRDF evaluation
per pixel stratum and light.

Radiance toward the camera is Σ_lights f(ωi, ωo) · E · max(0, cos θi): a convex object
casts no shadow on itself and sees nothing but the lights. Each pixel averages a fixed
grid of `supersample`² stratum centres, which approximates the box-filtered pixel the
path tracer estimates (the sphere's edge pixels differ by the grid's quadrature error).
"""

from __future__ import annotations

import functools

import torch

from ..protocols.representation import Representation
from . import sphere
from .simulator import Simulator, SphereHits, eval_brdf, light_terms, sphere_hits

Tensor = torch.Tensor


class ClosedForm(Simulator):
    backend = "torch"
    name = "closed_form"
    noise_free = True

    @property
    def samples(self) -> int:
        cam = self.scene.camera
        return cam.width * cam.height * self.scene.supersample ** 2

    @functools.cached_property
    def _hits(self) -> SphereHits:
        return sphere_hits(self.scene.camera, self.scene.camera.stratified_film(self.scene.supersample))

    def _render(self, model: Representation, *, seed: int, material: str = "") -> Tensor:
        cam, hits = self.scene.camera, self._hits
        radiance = torch.zeros(self.samples, 3, dtype=torch.float64)
        shaded = torch.zeros(hits.index.shape[0], 3, dtype=torch.float64)
        for toward, irradiance in light_terms(self.scene):
            wi = sphere.to_local(hits.frame, toward.expand(hits.index.shape[0], 3))
            f = eval_brdf(model, wi, hits.view, self.dtype)
            shaded += f * wi[:, 2:3].clamp_min(0) * irradiance
        radiance[hits.index] = shaded
        return radiance.reshape(cam.height, cam.width, -1, 3).mean(dim=2)
