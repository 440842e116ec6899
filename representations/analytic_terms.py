"""The analytic BRDFs' terms in torch: per-pair geometry, NDFs, shadowing, Fresnel.

Written once, used by the models' `_eval` (in the input dtype) and by their fit (float64
with autograd, `fitting.py`). Forms that stay accurate and finite in fp32 as well as fp64,
for any pair both above the horizon, down to GGX α = 1e-3 (Cook-Torrance roughness 1e-3,
α = 1e-6) and Blinn-Phong exponents up to 1e6:

- The half vector comes from `brdfbench.coords.half_vector` (stable for ωi + ωo ≈ 0);
  sin²θh = h_x² + h_y² is taken from its components, never as 1 − cos²θh, which cancels
  in fp32 exactly where a narrow lobe lives.
- GGX D = α² / (π (α² h_z² + h_x² + h_y²)²): no ((α² − 1) cos²θh + 1) cancellation and
  no tangent (infinite at grazing h).
- Height-correlated Smith: G2 / (4 cosθi cosθo) =
  0.5 / (cosθo √(cos²θi + α² sin²θi) + cosθi √(cos²θo + α² sin²θo)), no division by a
  vanishing cosine; Schlick-GGX: G / (4 cos cos) = 1 / (4 (cosθi (1−k) + k)(cosθo (1−k) + k)).
- cos^n θh = exp(n/2 · log1p(−sin²θh)): no overflow, no pow(0, 0), and accurate for huge n
  (log(cosθh) in fp32 has an absolute error of ~6e-8, i.e. 6 % at n = 1e6; log1p(−sin²θh)
  is relatively accurate).
- cosθd = |ωi + ωo| / 2 (exactly symmetric in ωi, ωo, so reciprocity holds bitwise).
- Cosines are clamped to ≥ COS_MIN = 1e-7 (directions within 1e-7 rad of the horizon
  only), which bounds the 1/(cosθi cosθo) of Cook-Torrance's nearly shadowing-free G;
  α is floored at ALPHA_MIN = 1e-6 (by the models).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from brdfbench.coords import half_vector

Tensor = torch.Tensor

COS_MIN = 1e-7
ALPHA_MIN = 1e-6
#: Beckmann's m is floored here (by the Beckmann models)
BECKMANN_M_MIN = 1e-6
#: GGX: D(θh)/D(0) = 1/2 at tanθh = HALF_WIDTH_PER_ALPHA·α (the fit's roughness estimate and starts).
HALF_WIDTH_PER_ALPHA = math.sqrt(math.sqrt(2.0) - 1.0)


# --------------------------------------------------------------------------- geometry


class Geometry(NamedTuple):
    """Per-pair quantities every lobe needs (all (N,), in the input dtype)."""

    cos_i: Tensor  # ωi_z, clamped to [COS_MIN, 1]
    cos_o: Tensor
    sin2_i: Tensor  # ωi_x² + ωi_y², in [0, 1]
    sin2_o: Tensor
    cos2_h: Tensor  # h_z² (h_z clamped ≥ 0)
    sin2_h: Tensor  # h_x² + h_y², in [0, 1]
    cos_d: Tensor  # ωi·h = |ωi + ωo| / 2, in [0, 1]
    dot_xy: Tensor  # ωi_x ωo_x + ωi_y ωo_y (the tangential part of ωi·ωo), in [-1, 1]
    sin2_d: Tensor  # sin²θd = |ωi − ωo|²/4, in [0, 1]: relatively accurate where ωi ≈ ωo


def geometry(wi: Tensor, wo: Tensor) -> Geometry:
    """Geometry of pairs both above the horizon (the protocol masks the others)."""
    h = half_vector(wi, wo)
    hz = h[:, 2].clamp(min=0.0)
    sin2_h = (h[:, 0] * h[:, 0] + h[:, 1] * h[:, 1]).clamp(0.0, 1.0)
    cos_d = (0.5 * torch.linalg.vector_norm(wi + wo, dim=-1)).clamp(0.0, 1.0)
    return Geometry(
        cos_i=wi[:, 2].clamp(COS_MIN, 1.0),
        cos_o=wo[:, 2].clamp(COS_MIN, 1.0),
        sin2_i=(wi[:, 0] * wi[:, 0] + wi[:, 1] * wi[:, 1]).clamp(0.0, 1.0),
        sin2_o=(wo[:, 0] * wo[:, 0] + wo[:, 1] * wo[:, 1]).clamp(0.0, 1.0),
        cos2_h=hz * hz,
        sin2_h=sin2_h,
        cos_d=cos_d,
        dot_xy=(wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]).clamp(-1.0, 1.0),
        sin2_d=(0.25 * ((wi - wo) ** 2).sum(dim=-1)).clamp(0.0, 1.0),
    )


# --------------------------------------------------------------------------- terms


def ggx_ndf(alpha: Tensor, g: Geometry) -> Tensor:
    """GGX / Trowbridge-Reitz D(h) = α² / (π (α² cos²θh + sin²θh)²), normalised so that
    ∫ D cosθh dωh = 1."""
    a2 = alpha * alpha
    q = a2 * g.cos2_h + g.sin2_h
    return a2 / (math.pi * q * q)


def smith_g2_over_4cc(alpha: Tensor, g: Geometry) -> Tensor:
    """Height-correlated Smith G2 of GGX divided by 4 cosθi cosθo (Heitz 2014, eq. 99)."""
    a2 = alpha * alpha
    ai = torch.sqrt(g.cos_i * g.cos_i + a2 * g.sin2_i)
    ao = torch.sqrt(g.cos_o * g.cos_o + a2 * g.sin2_o)
    return 0.5 / (g.cos_o * ai + g.cos_i * ao)


def schlick_g_over_4cc(k: Tensor, g: Geometry) -> Tensor:
    """Separable Schlick-GGX G1(ωi) G1(ωo) / (4 cosθi cosθo), G1(v) = n·v / (n·v (1−k) + k)."""
    return 0.25 / ((g.cos_i * (1.0 - k) + k) * (g.cos_o * (1.0 - k) + k))


def schlick_fresnel(f0: Tensor, cos_d: Tensor) -> Tensor:
    """Schlick's F = F0 + (1 − F0)(1 − cosθd)^5."""
    m = 1.0 - cos_d
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)


def blinn_phong_lobe(n: Tensor, g: Geometry) -> Tensor:
    """(n + 8)/(8π) cos^n θh, as exp(n/2 · log1p(−sin²θh)); 0 where h_z = 0."""
    eps = torch.finfo(g.sin2_h.dtype).eps
    log_cos = 0.5 * torch.log1p(-g.sin2_h.clamp(max=1.0 - eps))
    lobe = (n + 8.0) / (8.0 * math.pi) * torch.exp(n * log_cos)
    return torch.where(g.cos2_h > 0, lobe, torch.zeros_like(lobe))


def ior_to_f0(ior: Tensor) -> Tensor:
    r = (ior - 1.0) / (ior + 1.0)
    return r * r


def fresnel_dielectric(eta: Tensor, cos_d: Tensor) -> Tensor:
    """Unpolarised Fresnel reflectance of a dielectric of relative index η > 0 (Cook and
    Torrance 1982, eq. in §"The Fresnel term"): with c = cosθd and g² = η² + c² − 1,
    F = ½ (g − c)²/(g + c)² · (1 + ((c(g + c) − 1)/(c(g − c) + 1))²); 1 where g² ≤ 0
    (total internal reflection, η < 1)."""
    c = cos_d
    e = (eta - 1.0) * (eta + 1.0)  # η² − 1, exact to rounding for η near 1 (η − 1 is exact there)
    g2 = e + c * c  # η² − 1 first: at η ≈ 1 a tiny c² is not lost to rounding
    g = torch.sqrt(g2.clamp(min=0.0))
    s = (g + c).clamp(min=torch.finfo(c.dtype).tiny)
    g_minus_c = e / s  # g² − c² = η² − 1: no cancellation for η near 1
    a = g_minus_c / s
    b = (c * s - 1.0) / (c * g_minus_c + 1.0)
    f = 0.5 * a * a * (1.0 + b * b)
    return torch.where(g2 > 0, f.clamp(0.0, 1.0), torch.ones_like(f))
