"""The unit sphere at the origin: ray intersection and Mitsuba's shading frame on it.

The frame matters to representations that are not isotropic: the tangent is Mitsuba's
normalised ∂p/∂u for its `sphere` shape, (−y, x, 0)/|…| (u the azimuth about +z), and the
bitangent n × s, so a local direction here is the local direction Mitsuba's BSDF sees.
"""

from __future__ import annotations

import torch

Tensor = torch.Tensor


def intersect(origin: Tensor, direction: Tensor, radius: float = 1.0) -> tuple[Tensor, Tensor]:
    """Nearest positive hit distance (N,) and hit mask (N,) of unit-direction rays with the sphere."""
    b = (origin * direction).sum(-1)
    c = (origin * origin).sum(-1) - radius * radius
    disc = b * b - c
    hit = disc >= 0
    root = disc.clamp_min(0).sqrt()
    near, far = -b - root, -b + root
    t = torch.where(near > 0, near, far)
    return t, hit & (t > 0)


def shading_frame(n: Tensor) -> Tensor:
    """(N, 3, 3) rows (s, t, n) at unit normals n; near the poles (±z), s falls back to +x-ish."""
    s = torch.stack([-n[:, 1], n[:, 0], torch.zeros_like(n[:, 0])], dim=1)
    length = s.norm(dim=-1, keepdim=True)
    pole = length[:, 0] < 1e-12
    fallback = torch.tensor([1.0, 0.0, 0.0], dtype=n.dtype).expand_as(n)
    s = torch.where(pole[:, None], fallback, s / length.clamp_min(1e-300))
    s = s - n * (s * n).sum(-1, keepdim=True)
    s = s / s.norm(dim=-1, keepdim=True)
    return torch.stack([s, torch.linalg.cross(n, s), n], dim=1)


def to_local(frame: Tensor, v: Tensor) -> Tensor:
    """World vectors (N, 3) in the frames' local coordinates."""
    return torch.einsum("nij,nj->ni", frame, v)


def to_world(frame: Tensor, v: Tensor) -> Tensor:
    return torch.einsum("nji,nj->ni", frame, v)
