"""Direction-pair coordinates: (ωi, ωo) ⇄ Rusinkiewicz half/difference angles.

The one place where half/difference angles are computed. Directions are unit vectors in
the local shading frame (z = normal), torch tensors of shape (N, 3), fp32 or fp64; the
result keeps the input dtype. Angles come from atan2 of (sine, cosine) pairs rather than
acos, so they stay accurate at the poles (θh = 0, θd = 0) and at grazing angles.

Conventions: θh, θd in [0, π]; φh in (-π, π]; φd in [0, 2π). An azimuth whose polar
angle is exactly 0 is 0 (so for h = normal, φh = 0 and φd is the azimuth of ωi); within
rounding of a pole it is as arbitrary as the rounding (e.g. φd for ωi = ωo). Only when
ωi + ωo = 0 exactly is the half vector undefined: `half_vector` then picks the unit
vector ⊥ ωi nearest the normal.

MERL cells do not come from these angles: the reference reader's are less accurate (acos
near the poles) and its φd keeps atan2's sign, which [0, 2π) loses at φd = ±π (its −π
folds into cell 0, +π into 179), so brdfbench.merl follows the reader's own arithmetic.

Conditioning (what any method working on rounded unit vectors can achieve, u = unit
roundoff of the dtype): directions → angles → directions is accurate to a few u
everywhere. Angles → directions → angles is accurate to a few u in θh, θd, and in φh, φd
away from the coordinate singularities, but degrades like u / cos θd near θd = π/2 (h is
undefined for opposite directions), u / sin θh for φh, and u / sin θd + u / sin θh for φd
(azimuths are undefined at the poles). In fp32 (u ≈ 6e-8) θh, θd stay within 1e-5 rad for
θd ≤ 89°, and φh, φd for sin θh, sin θd ≥ 0.05 with θd ≤ 84°; tests/unit/test_coords.py
checks both, and that the fp32 limit near the singular sets lies in the rounded inputs.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

Tensor = torch.Tensor

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
    phi = torch.where(phi == -math.pi, -phi, phi)  # atan2(-0, x < 0) = -π; keep φ in (-π, π]
    return theta, phi


def _rotate_z(v: Tensor, cos_a: Tensor, sin_a: Tensor) -> Tensor:
    x, y, z = v.unbind(-1)
    return torch.stack((cos_a * x - sin_a * y, sin_a * x + cos_a * y, z), dim=-1)


def _rotate_y(v: Tensor, cos_a: Tensor, sin_a: Tensor) -> Tensor:
    x, y, z = v.unbind(-1)
    return torch.stack((cos_a * x + sin_a * z, y, -sin_a * x + cos_a * z), dim=-1)


def half_vector(wi: Tensor, wo: Tensor) -> Tensor:
    """Unit half vector of (ωi, ωo): ωi + ωo normalised.

    Floating-point addition is accurate relative to its result, so ωi + ωo keeps its
    direction however small it gets (it is rescaled before use so that tiny sums do not
    underflow). For nearly opposite pairs (θd > π/4) h is instead the part of ωi + ωo
    ⊥ ωi − ωo, computed as d × (s × d) with s = ωi + ωo, d = ωi − ωo: the same direction
    for exact unit vectors, but ⊥ d to rounding even when the inputs' norms differ by
    O(eps), which would otherwise tilt h by O(eps / |ωi + ωo|) and break the mirror
    symmetry ωo = 2(ωi·h)h − ωi that `from_half_diff` relies on. Swapping ωi and ωo
    negates d and s × d only, so h is bitwise the same either way. Only when ωo = −ωi
    exactly is h undefined; then the unit vector ⊥ ωi nearest the normal is used (the
    normal when ωi is horizontal, +x when ωi = ±z), so θd = π/2 and the pair still
    round-trips.
    """
    s = wi + wo
    diff = wi - wo
    opposite = (diff * diff).sum(-1, keepdim=True) > (s * s).sum(-1, keepdim=True)
    scale = s.abs().amax(dim=-1, keepdim=True)
    s = s / torch.where(scale > 0, scale, torch.ones_like(scale))
    n = torch.linalg.cross(s, diff)
    # ωo = −ωi exactly: s = 0. Use z × d instead (h ∝ d × (z × d), the normal projected
    # off ωi), or x × d when d ∥ z (h = +x). Both flip with d, keeping the swap symmetry.
    for axis in ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]):
        e = wi.new_tensor(axis).expand_as(wi)
        n = torch.where((n == 0).all(-1, keepdim=True), torch.linalg.cross(e, diff), n)
    v = torch.where(opposite, torch.linalg.cross(diff, n), s)
    scale = v.abs().amax(dim=-1, keepdim=True)
    return normalize(v / torch.where(scale > 0, scale, torch.ones_like(scale)))


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
    # atan2 gives [-π, π]; negatives move up by 2π. A tiny negative one rounds up to 2π:
    # keep it just below 2π (not 0), where it belongs, so [0, 2π) holds and the order is kept.
    two_pi = torch.tensor(2 * math.pi, dtype=phi_d.dtype, device=phi_d.device)
    phi_d = torch.where(phi_d < 0, phi_d + two_pi, phi_d)
    phi_d = torch.where(phi_d >= two_pi, torch.nextafter(two_pi, torch.zeros_like(two_pi)), phi_d)
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
