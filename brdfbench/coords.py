"""Direction-pair coordinates: (ωi, ωo) ⇄ Rusinkiewicz half/difference angles.

The one place where half/difference angles are computed. Directions are unit vectors in
the local shading frame (z = normal), torch tensors of shape (N, 3), fp32 or fp64; the
result keeps the input dtype. Angles come from atan2 of (sine, cosine) pairs rather than
acos, so they stay accurate at the poles (θh = 0, θd = 0) and at grazing angles.

Conventions: θh, θd in [0, π]; φh in (-π, π]; φd in [0, 2π). When ωi + ωo ≈ 0 the half
vector is undefined and the normal is used; when θh = 0, φh is 0.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

Tensor = torch.Tensor

#: |ωi + ωo| below this (relative to the dtype's eps) counts as opposite directions.
_DEGENERATE_SCALE = 64.0


class HalfDiff(NamedTuple):
    theta_h: Tensor
    phi_h: Tensor
    theta_d: Tensor
    phi_d: Tensor


def normalize(v: Tensor) -> Tensor:
    """Unit vectors along the last axis; zero vectors stay zero."""
    norm = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    return v / torch.where(norm > 0, norm, torch.ones_like(norm))


def spherical_to_vector(theta: Tensor, phi: Tensor) -> Tensor:
    """Unit vector from polar angle θ (from +z) and azimuth φ."""
    st = torch.sin(theta)
    return torch.stack((st * torch.cos(phi), st * torch.sin(phi), torch.cos(theta)), dim=-1)


def vector_to_spherical(v: Tensor) -> tuple[Tensor, Tensor]:
    """(θ, φ) of vectors; θ via atan2 so it is exact near both poles."""
    rho = torch.hypot(v[..., 0], v[..., 1])
    theta = torch.atan2(rho, v[..., 2])
    phi = torch.where(rho > 0, torch.atan2(v[..., 1], v[..., 0]), torch.zeros_like(rho))
    return theta, phi


def _rotate_z(v: Tensor, cos_a: Tensor, sin_a: Tensor) -> Tensor:
    x, y, z = v.unbind(-1)
    return torch.stack((cos_a * x - sin_a * y, sin_a * x + cos_a * y, z), dim=-1)


def _rotate_y(v: Tensor, cos_a: Tensor, sin_a: Tensor) -> Tensor:
    x, y, z = v.unbind(-1)
    return torch.stack((cos_a * x + sin_a * z, y, -sin_a * x + cos_a * z), dim=-1)


def half_vector(wi: Tensor, wo: Tensor) -> Tensor:
    """Normalised ωi + ωo; the normal where the two directions are (nearly) opposite."""
    s = wi + wo
    norm = torch.linalg.vector_norm(s, dim=-1, keepdim=True)
    tiny = _DEGENERATE_SCALE * torch.finfo(s.dtype).eps
    normal = torch.zeros_like(s)
    normal[..., 2] = 1.0
    return torch.where(norm > tiny, s / torch.where(norm > tiny, norm, torch.ones_like(norm)), normal)


def to_half_diff(wi: Tensor, wo: Tensor) -> HalfDiff:
    """Rusinkiewicz angles of direction pairs (N, 3) → four (N,) tensors."""
    if wi.shape != wo.shape or wi.shape[-1] != 3:
        raise ValueError(f"directions must both have shape (N, 3), got {tuple(wi.shape)} and {tuple(wo.shape)}")
    h = half_vector(wi, wo)
    theta_h, phi_h = vector_to_spherical(h)
    # Rotate ωi so that h becomes the pole: first by -φh about z, then by -θh about y.
    rho = torch.hypot(h[..., 0], h[..., 1])
    safe_rho = torch.where(rho > 0, rho, torch.ones_like(rho))
    cos_p = torch.where(rho > 0, h[..., 0] / safe_rho, torch.ones_like(rho))
    sin_p = torch.where(rho > 0, h[..., 1] / safe_rho, torch.zeros_like(rho))
    d = _rotate_z(wi, cos_p, -sin_p)
    d = _rotate_y(d, h[..., 2], -rho)
    theta_d, phi_d = vector_to_spherical(d)
    phi_d = torch.remainder(phi_d, 2 * math.pi)
    phi_d = torch.where(phi_d >= 2 * math.pi, phi_d - 2 * math.pi, phi_d)  # remainder may round up
    return HalfDiff(theta_h, phi_h, theta_d, phi_d)


def from_half_diff(theta_h: Tensor, phi_h: Tensor, theta_d: Tensor, phi_d: Tensor) -> tuple[Tensor, Tensor]:
    """Direction pairs (ωi, ωo) from Rusinkiewicz angles; ωo is ωi mirrored about h."""
    d = spherical_to_vector(theta_d, phi_d)
    d_mirror = torch.stack((-d[..., 0], -d[..., 1], d[..., 2]), dim=-1)
    cos_t, sin_t = torch.cos(theta_h), torch.sin(theta_h)
    cos_p, sin_p = torch.cos(phi_h), torch.sin(phi_h)
    wi = _rotate_z(_rotate_y(d, cos_t, sin_t), cos_p, sin_p)
    wo = _rotate_z(_rotate_y(d_mirror, cos_t, sin_t), cos_p, sin_p)
    return wi, wo


def above_horizon(wi: Tensor, wo: Tensor) -> Tensor:
    """Mask of pairs with both directions strictly above the surface."""
    return (wi[..., 2] > 0) & (wo[..., 2] > 0)
