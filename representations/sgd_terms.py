"""The SGD model's terms in torch (Bagher, Soler and Holzschuch 2012; see `sgd.py`): the
per-material constants formed once in fp64, the NDF, the shadowing, the Fresnel and the lobe.
Imported by the model and by its drjit twin (`sgd_kernel.py`), which imports no model."""

from __future__ import annotations

import math

import torch

from .analytic_terms import ALPHA_MIN, Geometry

Tensor = torch.Tensor

INV_PI = 1.0 / math.pi
#: s = α + tan²θh/α above which D is exactly 0 in fp64 (exp(−1e4) underflows even with the
#: largest 1/cos⁴θh): the cap only keeps p·log(s) finite where tan²θh/α overflows.
S_MAX = 1e4
#: w = log((E − E*)/E* + 1) and E − E* are capped here (G1 = 0 long before: E − E* > 0),
#: so that no exp in the shadowing overflows, in fp32 or in the fit's gradients.
W_MAX = 80.0
#: Λ is floored here (its log1p(1/Λ) stays finite): G1 = 1 − Λ expm1(E) differs from 1
#: by less than 1e-30·expm1(E) for any smaller Λ.
LAMBDA_MIN = 1e-30

# --------------------------------------------------------------------------- the terms


def sgd_constants(c: dict[str, Tensor]) -> dict[str, Tensor]:
    """Per-material (3,) constants of the lobe from its shape coefficients, in their dtype
    (`SGD._eval` and the drjit kernel form them in fp64 and round them once).

    The shadowing is rewritten about its zero: with E = c (θ − θ0)^k and E* = log(1 + 1/Λ)
    (where G1 = 0), G1 = −(1 + Λ) expm1(E − E*) and E − E* = E* expm1(w), w = w_h +
    k log1p(−ψ/x_h), ψ = π/2 − θ, x_h = π/2 − θ0, w_h = log(c x_h^k / E*) (≈ 0 for the
    published fits): every factor is relatively accurate, so no fp32 rounding of θ is
    amplified by k (up to 856 published)."""
    alpha = c["alpha"].clamp(min=ALPHA_MIN)
    f0 = c["f0"]
    lam = c["sh_lambda"].clamp(min=LAMBDA_MIN)
    e_star = torch.log1p(1.0 / lam)
    x_h = 0.5 * math.pi - c["sh_theta0"]
    x_h_safe = torch.where(x_h > 0, x_h, torch.ones_like(x_h))  # θ0 ≥ π/2: no shadowing
    k = c["sh_k"]
    return {
        "alpha": alpha,
        "inv_alpha": 1.0 / alpha,
        "p": c["p"].clamp(min=0.0),
        "k_pi2": c["K_ap"] * (INV_PI * INV_PI),  # D's 1/π and the model's 1/π
        "f0": f0,
        "f1": c["f1"],
        "one_minus_f0": 1.0 - f0,
        "x_h": x_h,
        "inv_x_h": 1.0 / x_h_safe,
        "k": k,
        # −inf for c = 0 (G1 = 1); the published c reaches 1.6e109, its log is an fp32 number.
        "w_h": torch.log(c["sh_c"].clamp(min=0.0)) + k * torch.log(x_h_safe) - torch.log(e_star),
        "e_star": e_star,
        "one_plus_lam": 1.0 + lam,
    }


def horizon_angle(cos: Tensor, sin2: Tensor) -> Tensor:
    """ψ = π/2 − θ = atan2(cosθ, sinθ), relatively accurate near the horizon (where G1 falls)."""
    return torch.atan2(cos, torch.sqrt(sin2))


def sgd_ndf_over_pi(k: dict[str, Tensor], g: Geometry) -> Tensor:
    """D(θh)/π, (N, 3): (K_ap/π²) exp(−s − p log s − 2 log cos²θh), s = α + tan²θh/α;
    0 where h_z = 0."""
    tiny = torch.finfo(g.cos2_h.dtype).tiny
    c2 = g.cos2_h.clamp(min=tiny)
    tan2 = (g.sin2_h / c2)[:, None]
    log_c2 = torch.log(c2)[:, None]
    s = (k["alpha"] + tan2 * k["inv_alpha"]).clamp(max=S_MAX)
    d = k["k_pi2"] * torch.exp(-s - k["p"] * torch.log(s) - 2.0 * log_c2)
    return torch.where((g.cos2_h > 0)[:, None], d, torch.zeros_like(d))


def sgd_g1(k: dict[str, Tensor], psi: Tensor) -> Tensor:
    """G1, (N, 3), of directions at ψ = π/2 − θ from the horizon: −(1 + Λ) expm1(E* expm1(w))
    above θ0 (w = w_h + k log1p(−ψ/x_h), see `sgd_constants`), clamped at 0; 1 below θ0."""
    above = psi[:, None] < k["x_h"]
    eps = torch.finfo(psi.dtype).eps  # q < 1: a finite log1p, also in the fit's gradients
    q = torch.where(above, (psi[:, None] * k["inv_x_h"]).clamp(max=1.0 - eps), torch.zeros_like(k["x_h"]))
    w = (k["w_h"] + k["k"] * torch.log1p(-q)).clamp(max=W_MAX)
    v = (k["e_star"] * torch.expm1(w)).clamp(max=W_MAX)  # E − E*
    g = (-k["one_plus_lam"] * torch.expm1(v)).clamp(min=0.0)
    return torch.where(above, g, torch.ones_like(g))


def sgd_fresnel(k: dict[str, Tensor], cos_d: Tensor) -> Tensor:
    """F = F0 − F1 cosθd + (1 − F0)(1 − cosθd)^5, (N, 3), clamped at 0 (a reflectance)."""
    m = 1.0 - cos_d
    m2 = m * m
    m5 = (m2 * m2 * m)[:, None]
    return (k["f0"] - k["f1"] * cos_d[:, None] + k["one_minus_f0"] * m5).clamp(min=0.0)


def sgd_lobe(k: dict[str, Tensor], g: Geometry) -> Tensor:
    """D · G1(θi) G1(θo) · F / (π cosθi cosθo), (N, 3), from `sgd_constants`."""
    d = sgd_ndf_over_pi(k, g)
    shadow = sgd_g1(k, horizon_angle(g.cos_i, g.sin2_i)) * sgd_g1(k, horizon_angle(g.cos_o, g.sin2_o))
    inv_cc = (1.0 / (g.cos_i * g.cos_o))[:, None]
    return d * shadow * sgd_fresnel(k, g.cos_d) * inv_cc


# --------------------------------------------------------------------------- published parameters
