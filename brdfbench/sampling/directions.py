"""Direction helpers for samplers: spherical ↔ Cartesian, reflection about a half vector.

Samplers build directions from (cos θ, sin² θ, φ) rather than from θ: both halves of the
pair can be computed without cancellation (sin² θ as u(2 − u), −expm1(2 log cos θ), …),
which keeps a lobe of width 1e-3 rad resolved in fp32, where 1 − cos θ would be lost.
"""

from __future__ import annotations

import math

import torch

from ..coords import spherical_to_vector, vector_to_spherical

Tensor = torch.Tensor

TWO_PI = 2.0 * math.pi

__all__ = [
    "cartesian_to_spherical",
    "direction",
    "log_cos_theta",
    "norm",
    "reflect",
    "sin2_theta",
    "spherical_to_cartesian",
]


def spherical_to_cartesian(theta: Tensor, phi: Tensor) -> Tensor:
    """Unit vectors (N, 3) from polar angle θ (from +z) and azimuth φ."""
    return spherical_to_vector(theta, phi)


def cartesian_to_spherical(v: Tensor) -> tuple[Tensor, Tensor]:
    """(θ, φ) of vectors (N, 3); θ via atan2, accurate at both poles."""
    return vector_to_spherical(v)


def direction(cos_theta: Tensor, sin2_theta: Tensor, phi: Tensor) -> Tensor:
    """Unit vectors from cos θ, sin² θ (computed without cancellation) and azimuth φ."""
    sin_theta = torch.sqrt(sin2_theta.clamp(min=0.0))
    return torch.stack((sin_theta * torch.cos(phi), sin_theta * torch.sin(phi), cos_theta), dim=-1)


def reflect(wi: Tensor, h: Tensor) -> Tensor:
    """ωi mirrored about the unit vector h: 2(ωi·h)h − ωi."""
    return 2.0 * (wi * h).sum(-1, keepdim=True) * h - wi


def norm(v: Tensor) -> Tensor:
    """Euclidean norms (N,) that neither underflow nor overflow (rescaled by the largest component)."""
    scale = v.abs().amax(dim=-1)
    safe = torch.where(scale > 0, scale, torch.ones_like(scale))
    return scale * torch.linalg.vector_norm(v / safe[..., None], dim=-1)


def sin2_theta(v: Tensor) -> Tensor:
    """sin² θ of unit vectors as x² + y², relatively accurate near the pole."""
    return (v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]).clamp(0.0, 1.0)


def log_cos_theta(v: Tensor) -> Tensor:
    """log cos θ of unit vectors above the horizon, accurate at both ends.

    Near the pole ½·log1p(−sin²θ) (z ≈ 1 carries no information there: in fp32 its
    rounding alone is 3.5e-4 rad); near the horizon log z (x² + y² ≈ 1 cancels there).
    """
    s2 = sin2_theta(v)
    z = v[..., 2].clamp(min=torch.finfo(v.dtype).tiny)
    near_pole = s2 <= 0.5
    return torch.where(near_pole, 0.5 * torch.log1p(-torch.where(near_pole, s2, torch.zeros_like(s2))), torch.log(z))
