"""A pinhole camera with Mitsuba 3's `perspective` sensor conventions, in torch.

Film coordinates (x, y) ∈ [0, 1]² run right and down. `look_at` builds the camera frame as
Mitsuba's `ScalarTransform4f.look_at` does (columns: left, up, forward), and the horizontal
field of view `fov` (degrees) spans the film width, so a ray here and the ray Mitsuba's
sensor generates for the same film position are the same ray (checked in
tests/integration/test_render.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

Tensor = torch.Tensor


@dataclass(frozen=True)
class Camera:
    width: int = 256
    height: int = 256
    fov: float = 30.0  # degrees, across the film width
    origin: tuple[float, float, float] = (0.0, 0.0, 4.0)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)

    def frame(self) -> Tensor:
        """(3, 3) camera-to-world rotation, columns (left, up, forward)."""
        origin, target, up = (torch.tensor(v, dtype=torch.float64) for v in (self.origin, self.target, self.up))
        forward = _normalize(target - origin)
        left = _normalize(torch.linalg.cross(up, forward))
        return torch.stack([left, torch.linalg.cross(forward, left), forward], dim=1)

    def rays(self, film: Tensor) -> tuple[Tensor, Tensor]:
        """Ray origins and unit directions (N, 3), fp64, for film positions (N, 2) in [0, 1]²."""
        film = film.to(torch.float64)
        half = math.tan(math.radians(self.fov) / 2)
        aspect = self.width / self.height
        local = torch.stack([(1 - 2 * film[:, 0]) * half, (1 - 2 * film[:, 1]) * half / aspect,
                             torch.ones_like(film[:, 0])], dim=1)
        d = _normalize(local @ self.frame().T)
        return torch.tensor(self.origin, dtype=torch.float64).expand_as(d), d

    def stratified_film(self, per_axis: int) -> Tensor:
        """Film positions (H·W·per_axis², 2): per_axis² stratum centres in every pixel, pixel-major."""
        k = (torch.arange(per_axis, dtype=torch.float64) + 0.5) / per_axis
        sy, sx = torch.meshgrid(k, k, indexing="ij")
        py, px = torch.meshgrid(torch.arange(self.height, dtype=torch.float64), torch.arange(self.width, dtype=torch.float64), indexing="ij")
        x = (px[..., None] + sx.reshape(-1)) / self.width
        y = (py[..., None] + sy.reshape(-1)) / self.height
        return torch.stack([x.reshape(-1), y.reshape(-1)], dim=1)

    def random_film(self, pixels: Tensor, generator: torch.Generator) -> Tensor:
        """One uniformly jittered film position per entry of `pixels` (flat indices), as a box filter draws them."""
        u = torch.rand(pixels.shape[0], 2, generator=generator, dtype=torch.float64)
        x = (pixels % self.width).to(torch.float64) + u[:, 0]
        y = torch.div(pixels, self.width, rounding_mode="floor").to(torch.float64) + u[:, 1]
        return torch.stack([x / self.width, y / self.height], dim=1)

    def mitsuba_dict(self, spp: int, seed: int = 0) -> dict:
        """The same camera as a Mitsuba `perspective` sensor with a box-filtered HDR film."""
        import mitsuba as mi

        return {
            "type": "perspective", "fov": self.fov, "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(origin=list(self.origin), target=list(self.target), up=list(self.up)),
            "film": {"type": "hdrfilm", "width": self.width, "height": self.height, "rfilter": {"type": "box"},
                     "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        }


def _normalize(v: Tensor) -> Tensor:
    return v / v.norm(dim=-1, keepdim=True)
