"""Direct lighting of a convex object under an environment map (and directional lights),
by Monte Carlo with multiple importance sampling.

For a convex object every direction above the surface sees the environment, so direct
lighting is exact. Each camera sample (a box-filtered film position, as Mitsuba draws
them) takes one environment sample and one BRDF-sampler sample, weighted by the power
heuristic; directional lights add their closed-form term. The BRDF sampler draws the
light direction given the view direction (its ωi is the view, its ωo the light).
Random numbers come from one seeded generator in a fixed order, so a reference render
and a model render with the same seed use the same directions wherever the sampler does.
"""

from __future__ import annotations

import functools

import torch

from ..protocols.representation import Representation
from ..sampling import Sampler
from ..scenes import Scene
from . import sphere
from .envmap import Envmap
from .simulator import Simulator, eval_brdf, light_terms, sphere_hits

Tensor = torch.Tensor
CHUNK = 2**17  # camera samples per batch: bounds memory at a few hundred MB


def power_heuristic(a: Tensor, b: Tensor) -> Tensor:
    a2, b2 = a * a, b * b
    total = a2 + b2
    return torch.where(total > 0, a2 / total.clamp_min(1e-300), torch.zeros_like(a))


class DirectMIS(Simulator):
    backend = "torch"
    name = "direct_mis"

    def __init__(self, scene: Scene, envmap: Envmap, sampler: Sampler, *, spp: int | None = None,
                 dtype: torch.dtype = torch.float32):
        super().__init__(scene, dtype=dtype)
        self.envmap = envmap
        self.sampler = sampler
        self.spp = spp or scene.spp

    @property
    def samples(self) -> int:
        return self.scene.camera.width * self.scene.camera.height * self.spp

    @functools.cached_property
    def _light_terms(self) -> list[tuple[Tensor, Tensor]]:
        return light_terms(self.scene)

    def _render(self, model: Representation, *, seed: int, material: str = "") -> Tensor:
        cam = self.scene.camera
        generator = torch.Generator().manual_seed(seed)
        pixel_sum = torch.zeros(cam.width * cam.height, 3, dtype=torch.float64)
        for start in range(0, self.samples, CHUNK):
            count = min(CHUNK, self.samples - start)
            pixels = torch.div(torch.arange(start, start + count), self.spp, rounding_mode="floor")
            film = cam.random_film(pixels, generator)
            u_env = torch.rand(count, 2, generator=generator, dtype=torch.float64)
            u_brdf = torch.rand(count, 2, generator=generator, dtype=torch.float64)
            hits = sphere_hits(cam, film)
            if hits.index.numel() == 0:
                continue
            radiance = self._shade(model, hits.frame, hits.view, u_env[hits.index], u_brdf[hits.index])
            pixel_sum.index_add_(0, pixels[hits.index], radiance)
        return (pixel_sum / self.spp).reshape(cam.height, cam.width, 3)

    def _shade(self, model: Representation, frame: Tensor, view: Tensor, u_env: Tensor, u_brdf: Tensor) -> Tensor:
        """One MIS estimate of reflected radiance (M, 3) per shading point."""
        radiance = torch.zeros(view.shape[0], 3, dtype=torch.float64)
        # environment sample
        d_env, p_env = self.envmap.sample(u_env)
        d_env, p_env = d_env.to(torch.float64), p_env.to(torch.float64)
        wi = sphere.to_local(frame, d_env)
        p_brdf = self._sampler_pdf(view, wi)
        weight = power_heuristic(p_env, p_brdf) / p_env.clamp_min(1e-300)
        f = eval_brdf(model, wi, view, self.dtype) * wi[:, 2:3].clamp_min(0)
        radiance += torch.where((p_env > 0)[:, None], f * self.envmap.eval(d_env).to(torch.float64) * weight[:, None], 0.0)
        # BRDF-sampler sample
        wi = self.sampler.sample(view.to(self.dtype), u_brdf.to(self.dtype)).to(torch.float64)
        wi = wi / wi.norm(dim=-1, keepdim=True)
        p_brdf = self._sampler_pdf(view, wi)
        d_world = sphere.to_world(frame, wi)
        p_env = self.envmap.pdf(d_world).to(torch.float64)
        weight = power_heuristic(p_brdf, p_env) / p_brdf.clamp_min(1e-300)
        f = eval_brdf(model, wi, view, self.dtype) * wi[:, 2:3].clamp_min(0)
        radiance += torch.where((p_brdf > 0)[:, None], f * self.envmap.eval(d_world).to(torch.float64) * weight[:, None], 0.0)
        # directional lights: closed form
        for toward, irradiance in self._light_terms:
            wl = sphere.to_local(frame, toward.expand_as(view))
            radiance += eval_brdf(model, wl, view, self.dtype) * wl[:, 2:3].clamp_min(0) * irradiance
        return radiance

    def _sampler_pdf(self, view: Tensor, wi: Tensor) -> Tensor:
        return self.sampler.pdf(view.to(self.dtype), wi.to(self.dtype)).to(torch.float64)
