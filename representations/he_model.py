"""He, Torrance, Sillion and Greenberg, "A comprehensive physical model for light reflection"
(SIGGRAPH 1991), in the form Ngan, Durand and Matusik fitted it to MERL ("Experimental
Analysis of BRDF Models", EGSR 2005): f = k_d/π + k_s ⊙ ρ_dd, He's directional-diffuse term
beside a Lambertian. Per RGB channel of wavelength λ (the paper's eqs. 24-25, 76-84):

    ρ_dd = F(η, cosθd) · G · S(θi) S(θo) · D / (π cosθi cosθo),    G = (|v|²/v_z)², v = ωi + ωo,
    D = π²τ²/(4λ²) Σ_{m≥1} g^m e^{−g}/(m!·m) exp(−π²τ² v_xy²/(λ² m)),  g = (2πσ (cosθi + cosθo)/λ)²,
    σ = σ0/√(1 + x²), x e^{x²/2} = (K_i + K_o)/√(8π), K = tanθ erfc(u), u = τ cotθ/(2σ0),
    S = (1 − ½ erfc u)/(1 + Λ), Λ = ½ (e^{−u²}/(√π u) − erfc u),

σ0 the rms roughness and τ the autocorrelation length (µm), η a real index of refraction.

Conventions, each checked against BBM, which evaluates the published fits (github.com/
bsdfbenchmark/bbm: include/bsdfmodel/ngan.h, he.h, scaledmodel.h; include/bbm/fresnel_cook.h;
the backbones' rgbConfig), and by the published parameters' mean l1_log_cos against the NBRDF
networks of the same 86 MERL materials (test_he_model.py; figures on 4096 cells: this reading
0.111, Ngan's other fits 0.119-0.162 on 2^15 cells, where this reading gives 0.112):
- σ0, τ in µm; λ = 0.645, 0.526, 0.444 µm for R, G, B (BBM's rgbConfig, "in micron"). One λ
  = 0.55 µm scores the same (0.111), the λ reversed 0.113; σ0, τ read in nm leave no lobe (0.240).
- v in eq. 78 carries the wave number, v = (2π/λ)(k_r − k_i), as the paper defines it (BBM's
  he_eq78::Westin, used by ngan.h): without it (τ² v_xy²/(4m)) the fits score 0.460.
- Eq. 25 with the errata's e^{−u²} (Holzschuch and Pacanowski; BBM's he_eq25::Errata, as
  ngan.h), Smith's shadowing of Gaussian heights; without it 0.112 (the data cannot tell).
- F: Cook and Torrance's unpolarised dielectric Fresnel of a real η at cosθd (ngan.h's
  fresnel::cook, "non-complex eta"). η = 1 makes the lobe 0: four published fits print
  η = 1.0, their albedo (2e5-2e9) compensating an index rounded to three digits.
- "albedo" multiplies the whole ρ_dd (BBM's scaledmodel): k_s. Ngan's form has no specular
  spike (He's delta at the mirror direction) and no uniform-diffuse term (k_d instead).
- The paper's G carries [(ŝ_r·k_i)² + (p̂_r·k_i)²][(ŝ_i·k_r)² + (p̂_i·k_r)²]/|k_i × k_r|⁴,
  which is 1: (ŝ, p̂, k) is orthonormal, each bracket 1 − (k_i·k_r)² (BBM takes G = 1 at its
  0/0, ωi = ωo; here the limit holds there too).
- The series itself is summed. BBM (after Westin et al.'s code) replaces it by the rough-
  surface limit e^{−a/g}/g for g > 18: the published fits score the same (0.111). As g → ∞,
  ρ_dd → F S D_Beckmann/(4 cosθi cosθo) with m = 2σ/τ (a test checks it).

Numerics (fp32 and fp64 over the whole coefficient range):
- Everything but F is a log, exponentiated once: no overflow of G/(cosθi cosθo) at grazing,
  no underflow of g^m/m!. x² = W(f0²) (`lambert_w_log`); K = (τ/(2σ0)) erfc(u)/u; v_xy² =
  4 cos²θd sin²θh from the half vector (no cancellation at the mirror direction); F with
  η² − 1 formed apart from cos²θd (`fresnel`). ωi ↔ ωo symmetric bit for bit.
- The series (`he_log_series`, a = π²τ² v_xy²/λ²): its terms are log-concave in m (m ≥ 2)
  with one peak m_c (log(g/m) + a/m² = 0 by Lambert's W, two Newton steps) of width s =
  (1/(m + ½) − 1/m² + 2a/m³)^−½. Where m_c < M_SWITCH or s < S_MIN, the N_DOWN + 1 + N_UP
  exact terms around round(m_c) are summed, each from its neighbour, outward from the peak
  (rounding does not grow where the weight is). Elsewhere m = 1 lies e^{−M_SWITCH} below the
  peak and the terms vary on a scale s ≥ S_MIN, so the sum is the integral of their
  continuation (Γ for m!) to e^{−2π²s²} (Poisson summation), taken by the trapezoid rule on
  N_STRIDED nodes over [m_c − 7s, m_c + 9s], each term's log in Loader's deviance form.
  Truncation: what the windows leave out is below ~e^{−28} of the peak; against long-double
  sums of every term over g ∈ [1e-9, 3e5], a ∈ {0} ∪ [1e-4, 1e8] the relative error is
  ≤ 3e-12 (the test checks 1e-10); fp32 keeps a few ulp of the log's magnitude.
"""

from __future__ import annotations

import math
from typing import ClassVar

import torch

from .analytic import _KD, Coefficient
from .analytic_terms import Geometry
from .he_terms import (CHUNK, HALF_LOG_2PI, INV_SQRT_8PI, INV_SQRT_PI, LOG_CAP, M_SWITCH, N_DOWN, N_STRIDED, N_UP,
                       S_MIN, STIRLERR, T_HI, T_LO, U_MAX, WAVELENGTHS_UM)
from .ngan_models import NganBRDF

Tensor = torch.Tensor

# FLOPS, counted as in analytic.py (each add, multiply, divide, sqrt, exp, log, erfc, round,
# clamp or select one operation; per-material constants hoisted). Shared by the channels:
# v_z 1, cos²θd 2, v_xy² 2; per direction u 5, erfc 1, Λ 7, log S 4, K 2 (38); log f0² 5;
# W 41; 1 + x² 1; the Fresnel 20; log G − log(π cosθi cosθo) and the sums 10; v_z²/(1 + x²) 2.
# Per channel: g, a, log g 4; the peak (W 41, start 10, two Newton steps 42, s 11) 104; the
# regime 3; the integer window: round 2, each step above 13, below 15, log t at round(m_c) 56,
# log(1 + Σ) 3; the trapezoid: setup 8, log t at m_c 56, Stirling at m_c 11, each node 51,
# log(h Σ) 2; the select 1; the log lobe, exp, ·F 4. Both branches counted (the drjit
# kernel evaluates both), then the RGB combine 6.
_SHARED_FLOPS = 1 + 2 + 2 + 2 * 19 + 5 + 41 + 1 + 20 + 10 + 2
_INTEGER_FLOPS = 2 + 13 * N_UP + 15 * N_DOWN + 56 + 3
_TRAPEZOID_FLOPS = 8 + 56 + 11 + 51 * N_STRIDED + 2
_CHANNEL_FLOPS = 4 + 104 + 3 + _INTEGER_FLOPS + _TRAPEZOID_FLOPS + 1 + 4


# --------------------------------------------------------------------------- the series


def lambert_w_log(L: Tensor, steps: int = 4) -> Tensor:
    """Lambert's W(e^L) (principal branch, W e^W = e^L) from L, for any real L: Newton on
    w + log w = L, w ← w(1 + L − log w)/(1 + w), from Winitzki's log1p form (L < 1) or
    L − log L + log L/L (L ≥ 1); 4 steps reach fp64 rounding. e^L itself below L = −40
    (W(z) = z − z² + …)."""
    lc = L.clamp(min=-40.0)  # the Newton branch stays finite (and so its gradient) below
    z = torch.exp(lc.clamp(max=1.0))
    lz = torch.log1p(z)
    small = lz * (1.0 - torch.log1p(lz) / (2.0 + lz))
    big_l = lc.clamp(min=1.0)
    log_big = torch.log(big_l)
    w = torch.where(lc < 1.0, small, big_l - log_big + log_big / big_l)
    for _ in range(steps):
        w = w * (1.0 + lc - torch.log(w)) / (1.0 + w)
    return torch.where(L < -40.0, torch.exp(L.clamp(max=-40.0)), w)


def stirlerr_series(m: Tensor) -> Tensor:
    """Stirling's series for lgamma(m+1) − (m + ½) log m + m − ½ log 2π, 5 terms: error
    < 3e-13 from m = 8 (1e-4 at m = 1, where the trapezoid's nodes carry no weight)."""
    r = 1.0 / m
    r2 = r * r
    return r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 * (1.0 / 1680.0 - r2 / 1188.0))))


def stirlerr(m: Tensor) -> Tensor:
    """lgamma(m+1) − (m + ½) log m + m − ½ log 2π: exact at the integers 1..7, the series from 8."""
    out = stirlerr_series(m)
    for k in range(7, 0, -1):
        out = torch.where(m < k + 0.5, torch.full_like(m, STIRLERR[k - 1]), out)
    return out


def bd0(x: Tensor, mean: Tensor, diff: Tensor) -> Tensor:
    """Loader's deviance x log(x/M) + M − x ≥ 0, `diff` = x − M: by the series
    diff·v + 2x v³ (1/3 + v²/5 + …), v = diff/(x + M), where |v| < 0.05 (no cancellation),
    else directly."""
    v = diff / (x + mean)
    w = v * v
    p = 1.0 / 3.0 + w * (1.0 / 5.0 + w * (1.0 / 7.0 + w * (1.0 / 9.0 + w / 11.0)))
    series = diff * v + 2.0 * x * (v * w) * p
    direct = x * torch.log(x / mean) - diff
    return torch.where(v.abs() < 0.05, series, direct)


def log_term(m: Tensor, g: Tensor, a: Tensor) -> Tensor:
    """log t_m = log(g^m e^{−g}/(m!·m)) − a/m in Loader's form: −bd0(m, g) − 1.5 log m
    − ½ log 2π − stirlerr(m) − a/m."""
    return -bd0(m, g, m - g) - 1.5 * torch.log(m) - HALF_LOG_2PI - stirlerr(m) - a / m


def series_peak(g: Tensor, a: Tensor, log_g: Tensor) -> tuple[Tensor, Tensor]:
    """(m_c, s): the maximum of t_m over real m ≥ 1 and the width there. The start solves
    log(g/m) + a/m² = 0, m = g e^{W(2a/g²)/2}; two Newton steps (in log m) on
    log g − log(m + ½) − 1/m + a/m² = 0 (ψ(m + 1) ≈ log(m + ½)) refine it to ≤ 0.07 s."""
    tiny = torch.finfo(g.dtype).tiny
    w = lambert_w_log(math.log(2.0) + torch.log(a.clamp(min=tiny)) - 2.0 * log_g)
    m = (g * torch.exp(0.5 * w)).clamp(min=1.0)
    for _ in range(2):
        r = log_g - torch.log(m + 0.5) - 1.0 / m + a / (m * m)
        dr = -m / (m + 0.5) + 1.0 / m - 2.0 * a / (m * m)
        m = (m * torch.exp((-r / dr.clamp(max=-1e-3)).clamp(-3.0, 3.0))).clamp(min=1.0)
    curvature = 1.0 / (m + 0.5) - 1.0 / (m * m) + 2.0 * a / (m * m * m)
    return m, torch.rsqrt(curvature.clamp(min=1e-12))


def _integer_window(g: Tensor, a: Tensor, m_c: Tensor) -> Tensor:
    """log Σ over the integers round(m_c) − N_DOWN … round(m_c) + N_UP (≥ 1), each term from
    its neighbour's, outward from round(m_c)."""
    m_r = torch.round(m_c).clamp(min=1.0)
    up = m_r[:, None] + torch.arange(N_UP, dtype=g.dtype, device=g.device)  # the node below each step
    gg, aa = g[:, None], a[:, None]
    step = torch.log((gg / (up + 1.0)) * (up / (up + 1.0))) + aa / (up * (up + 1.0))
    above = torch.exp(torch.cumsum(step, dim=1).clamp(max=LOG_CAP)).sum(dim=1)
    down = m_r[:, None] - torch.arange(N_DOWN, dtype=g.dtype, device=g.device)  # the node above each step
    valid = down >= 2.0
    d = down.clamp(min=2.0)
    step = torch.log((gg / d) * ((d - 1.0) / d)) + aa / ((d - 1.0) * d)
    terms = torch.exp((-torch.cumsum(step, dim=1)).clamp(max=LOG_CAP))
    below = torch.where(valid, terms, torch.zeros_like(terms)).sum(dim=1)
    return log_term(m_r, g, a) + torch.log(1.0 + above + below)


def _trapezoid(g: Tensor, a: Tensor, log_g: Tensor, m_c: Tensor, s: Tensor) -> Tensor:
    """log Σ as the trapezoid rule on the continuation t(x), N_STRIDED nodes m_c + d."""
    low = torch.minimum(T_LO * s, m_c - 1.0)
    h = (low + T_HI * s) / (N_STRIDED - 1)
    k = torch.arange(N_STRIDED, dtype=g.dtype, device=g.device)
    mc, aa = m_c[:, None], a[:, None]
    d = k * h[:, None] - low[:, None]
    x = mc + d
    log_ratio = (-bd0(x, mc, d) + d * torch.log(g / m_c)[:, None] - 1.5 * torch.log1p(d / mc)
                 - (stirlerr_series(x) - stirlerr_series(mc)) + aa * d / (x * mc))
    return log_term(m_c, g, a) + torch.log(h * torch.exp(log_ratio).sum(dim=1))


def he_log_series(g: Tensor, a: Tensor) -> Tensor:
    """log Σ_{m≥1} g^m e^{−g}/(m!·m) e^{−a/m} for g > 0, a ≥ 0 (any shape; module docstring):
    the exact terms around the peak, or the trapezoid rule on their continuation where the
    peak is wide and far from m = 1. Each element takes one branch (computed on its subset,
    in blocks of CHUNK)."""
    shape = g.shape
    g = g.reshape(-1).clamp(min=torch.finfo(g.dtype).tiny)
    a = a.reshape(-1)
    log_g = torch.log(g)
    m_c, s = series_peak(g, a, log_g)
    strided = (m_c >= M_SWITCH) & (s >= S_MIN)
    out = torch.zeros_like(g)
    for rows in torch.nonzero(~strided).reshape(-1).split(CHUNK):
        out = out.index_put((rows,), _integer_window(g[rows], a[rows], m_c[rows]))
    for rows in torch.nonzero(strided).reshape(-1).split(CHUNK):
        out = out.index_put((rows,), _trapezoid(g[rows], a[rows], log_g[rows], m_c[rows], s[rows]))
    return out.reshape(shape)


# --------------------------------------------------------------------------- the model


def fresnel(eta: Tensor, cos_d: Tensor) -> Tensor:
    """Cook and Torrance's unpolarised dielectric F of a real η ≥ 1 at c = cosθd, as
    analytic_terms.fresnel_dielectric but with η² − 1 = (η − 1)(η + 1) formed apart from c²:
    g² = η² − 1 + c² keeps c² where η = 1 (there `η² + c² − 1` rounds to 0 for c < 3e-4 in
    fp32 and would read as total reflection), so F(η = 1) = 0 for every c > 0."""
    c = cos_d
    e = (eta - 1.0) * (eta + 1.0)
    g = torch.sqrt(e + c * c)
    s = (g + c).clamp(min=torch.finfo(c.dtype).tiny)
    g_minus_c = e / s
    a = g_minus_c / s
    b = (c * s - 1.0) / (c * g_minus_c + 1.0)
    return (0.5 * a * a * (1.0 + b * b)).clamp(0.0, 1.0)


def log_shadowing(q: Tensor, cos: Tensor, sin2: Tensor) -> tuple[Tensor, Tensor]:
    """(log S(θ), K(θ)) of one direction, q = τ/(2σ0): u = q cotθ (≤ U_MAX), S = (1 − ½ erfc
    u)/(1 + Λ), K = tanθ erfc(u) = q erfc(u)/u."""
    tiny = torch.finfo(cos.dtype).tiny
    u = (q * cos * torch.rsqrt(sin2.clamp(min=tiny))).clamp(max=U_MAX)
    e = torch.special.erfc(u)
    lam = 0.5 * (torch.exp(-u * u) * INV_SQRT_PI / u - e)
    return torch.log1p(-0.5 * e) - torch.log1p(lam), q * e / u


def he_lobe(p: dict[str, Tensor], g: Geometry) -> Tensor:
    """ρ_dd (k_s = 1) of every pair and channel, (N, 3), from `He.constants` `p`."""
    tiny = torch.finfo(g.cos_i.dtype).tiny
    vz = g.cos_i + g.cos_o
    cd2 = (g.cos_d * g.cos_d).clamp(min=tiny)
    vxy2 = 4.0 * cd2 * g.sin2_h
    log_s_i, k_i = log_shadowing(p["q"], g.cos_i, g.sin2_i)
    log_s_o, k_o = log_shadowing(p["q"], g.cos_o, g.sin2_o)
    f0 = ((k_i + k_o) * INV_SQRT_8PI).clamp(min=tiny)
    one_plus_w = 1.0 + lambert_w_log(2.0 * torch.log(f0))  # 1 + x², x = z0/σ0
    f = fresnel(p["ior"], g.cos_d)
    shared = (log_s_i + log_s_o) + 2.0 * torch.log(4.0 * cd2 / vz) - torch.log(math.pi * (g.cos_i * g.cos_o))
    vz2 = vz * vz / one_plus_w
    lobes = []
    for c in range(3):
        log_sum = he_log_series(p[f"b{c}"] * vz2, p[f"a{c}"] * vxy2)
        lobes.append(f * torch.exp(shared + p[f"log_norm{c}"] + log_sum))
    return torch.stack(lobes, dim=1)


class He(NganBRDF):
    """He, Torrance, Sillion and Greenberg's directional-diffuse term as Ngan et al. fitted it
    (BBM's NganHe), module docstring: lobe = F G S(θi) S(θo) D/(π cosθi cosθo) per channel.
    Published "albedo" → ks, "roughness" → sigma0 (σ0, µm), "autocorrelation" → tau (τ, µm),
    "eta" → ior. Coefficients: kd, ks (RGB), sigma0, tau, ior. ks reaches 1e10: the published
    albedos with η = 1.0 are up to 2e9.
    """

    NAME = "he"
    PUBLISHED_AS = ("NganHe",)
    PUBLISHED_PARAMS = {"albedo": "ks", "roughness": "sigma0", "autocorrelation": "tau", "eta": "ior"}
    COEFFS = (
        _KD,
        Coefficient("ks", 3, 1.0, 1e-8, 1e10, log=True),
        Coefficient("sigma0", 1, 0.3, 1e-3, 20.0, log=True),
        Coefficient("tau", 1, 28.0, 0.1, 500.0, log=True),
        Coefficient("ior", 1, 1.5, 1.0, 50.0, log=True),
    )
    FLOPS = _SHARED_FLOPS + 3 * _CHANNEL_FLOPS + 6
    #: τ of the fit's starts (the commonest published value), σ0 = α τ/2 (Beckmann m = 2σ0/τ)
    TAU_INIT: ClassVar[float] = 28.0

    @classmethod
    def constants(cls, c):
        sigma0, tau = c["sigma0"], c["tau"]
        out = {"q": tau / (2.0 * sigma0), "ior": c["ior"]}
        for j, lam in enumerate(WAVELENGTHS_UM):
            b = 2.0 * math.pi / lam * sigma0
            k = math.pi / lam * tau
            out[f"b{j}"] = b * b  # g = b (cosθi + cosθo)²/(1 + x²)
            out[f"a{j}"] = k * k  # a = π²τ² v_xy²/λ²
            out[f"log_norm{j}"] = torch.log(0.25 * (k * k))  # log π²τ²/(4λ²)
        return out

    @classmethod
    def lobe(cls, g, c):
        return he_lobe(cls.constants(c), g)

    @classmethod
    def init_shape(cls, alpha):
        return {"sigma0": 0.5 * alpha * cls.TAU_INIT, "tau": cls.TAU_INIT, "ior": 1.5}

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        if type(self) is not He:
            return None
        from .he_kernel import HeKernel  # lazy: drjit

        return HeKernel(self)


MODELS: dict[str, type[NganBRDF]] = {He.NAME: He}
