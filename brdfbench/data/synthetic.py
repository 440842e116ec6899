"""The embedded default dataset: deterministic, measured-like synthetic materials.

Why: the benchmark must run on a fresh machine with no downloads, yet a target that one
analytic model reproduces exactly would crown that model. So each material here mixes
physically based terms that no single Lambert + GGX (or any one closed-form) model has:

- a Lambertian base (albedo/π), optionally seen through a dielectric coat and with
  Oren–Nayar roughness;
- one or two microfacet lobes with non-GGX distributions: a shifted-gamma slope
  distribution (after Bagher et al. 2012) and the ABC / K-correlation form
  (after Löw et al. 2012), each exactly normalised, with the height-correlated Smith
  shadowing of that very distribution (Λ tabulated numerically, so energy is conserved);
- full dielectric or conductor Fresnel (complex RGB index of refraction for coloured
  metals), or Schlick with an RGB F0 for metallic flakes;
- a Charlie sheen lobe and a retro-reflection hump for fabrics;
- measurement effects: mild per-cell multiplicative noise, a finite footprint that bounds
  the specular 1/(cosθi cosθo) near grazing, a soft sensor knee above 1000 1/sr, and
  invalid cells: every cell whose centre lies below the horizon, plus a small random
  fraction (0.1-2 %) of the cells with θi or θo beyond 80°.

Materials are written as MERL `.binary` files into a cache folder and read back with
`brdfbench.merl.read_binary`, so every run exercises the real file path. Material i
depends only on (seed, i), never on the dataset size.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from .. import merl
from ..atomic import replacing
from ..coords import half_vector
from ..errors import ConfigError, DataError
from ..merl import MerlTable
from ..protocols.representation import Material
from . import Dataset
from .content_hash import DigestCache, cache_root, recorded_digest, sha256_file

log = logging.getLogger(__name__)

#: Bump when the generator's output changes: it names the cache folder and the fingerprint.
GENERATOR_VERSION = "v1"
CATEGORIES = ("plastic", "metal", "metallic-paint", "fabric", "rubber", "phenolic")
SIZES = {"default": 24, "small": 6}
MAX_SIZE = 1000
#: Cells with θi or θo beyond this count as grazing; a few of them are made invalid.
GRAZING_DEG = 80.0
#: Cosine softening of the specular 1/(4 cosθi cosθo): a finite measurement footprint.
APERTURE = 0.02
#: Values above this (1/sr) are compressed logarithmically: a finite sensor dynamic range.
SENSOR_KNEE = 1000.0

Tensor = torch.Tensor
RGB = tuple[float, float, float]

# Base colours (linear RGB reflectances) for dielectric materials, by name.
_COLOURS: dict[str, RGB] = {
    "red": (0.55, 0.06, 0.05),
    "orange": (0.65, 0.25, 0.04),
    "yellow": (0.62, 0.50, 0.06),
    "green": (0.08, 0.35, 0.10),
    "teal": (0.04, 0.30, 0.28),
    "blue": (0.05, 0.12, 0.50),
    "purple": (0.25, 0.07, 0.38),
    "pink": (0.70, 0.30, 0.38),
    "white": (0.78, 0.78, 0.75),
    "grey": (0.22, 0.22, 0.22),
    "black": (0.025, 0.025, 0.028),
    "brown": (0.22, 0.10, 0.04),
    "beige": (0.55, 0.45, 0.32),
}
# Complex indices of refraction (n, k) at roughly 650 / 550 / 450 nm.
_METALS: dict[str, tuple[RGB, RGB]] = {
    "gold": ((0.15, 0.42, 1.37), (3.70, 2.40, 1.75)),
    "copper": ((0.21, 0.95, 1.15), (3.90, 2.50, 2.20)),
    "silver": ((0.15, 0.12, 0.14), (4.10, 3.30, 2.40)),
    "aluminium": ((1.60, 0.95, 0.60), (8.30, 6.60, 5.30)),
    "chrome": ((3.10, 3.20, 2.40), (3.30, 3.30, 3.20)),
    "brass": ((0.44, 0.53, 1.10), (3.70, 2.80, 1.85)),
    "nickel": ((2.00, 1.80, 1.60), (3.80, 3.40, 2.80)),
    "titanium": ((2.70, 2.50, 2.20), (3.80, 3.40, 3.00)),
}
_FABRICS = ("velvet", "satin", "felt", "denim", "cotton", "silk")


# --------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class Fresnel:
    """Reflectance at the microfacet: 'dielectric' (eta), 'conductor' (eta, k RGB) or 'schlick' (f0 RGB)."""

    kind: str
    eta: RGB = (1.5, 1.5, 1.5)
    k: RGB = (0.0, 0.0, 0.0)
    f0: RGB = (0.04, 0.04, 0.04)


@dataclass(frozen=True)
class Lobe:
    """One microfacet lobe.

    kind 'sgd': shifted-gamma slope density p(u) ∝ exp(-u/a) (a + u)^-b, u = tan²θh
    (a ~ roughness², b = tail exponent; b = 0 is Beckmann). kind 'abc': D ∝
    (1 + a (1 - cos θh))^-b. `weight` scales the lobe per channel.
    """

    kind: str
    a: float
    b: float
    weight: RGB
    fresnel: Fresnel


@dataclass(frozen=True)
class MaterialParams:
    """Everything that defines one synthetic material; cheap to draw, no tables."""

    index: int
    name: str
    category: str
    albedo: RGB
    oren_nayar_sigma: float = 0.0  # 0 = Lambert
    coat_eta: float | None = None  # diffuse seen through a dielectric interface
    lobes: tuple[Lobe, ...] = ()
    sheen: RGB = (0.0, 0.0, 0.0)
    sheen_r: float = 0.5
    retro: RGB = (0.0, 0.0, 0.0)
    retro_width: float = 0.3
    noise: float = 0.0  # relative σ of per-cell multiplicative noise
    invalid_fraction: float = 0.005  # of grazing cells


def _rng(index: int, seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, index])


def _jitter(rng: np.random.Generator, rgb: RGB, rel: float, lo: float = 0.0, hi: float = 1.0) -> RGB:
    scale = rng.uniform(1.0 - rel, 1.0 + rel, size=3)
    return tuple(float(v) for v in np.clip(np.asarray(rgb) * scale, lo, hi))  # type: ignore[return-value]


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _sgd_lobe(rng, m_lo, m_hi, weight, fresnel) -> Lobe:
    m = _log_uniform(rng, m_lo, m_hi)
    return Lobe("sgd", m * m, float(rng.uniform(0.3, 1.8)), weight, fresnel)


def _abc_lobe(rng, m_lo, m_hi, weight, fresnel) -> Lobe:
    m = _log_uniform(rng, m_lo, m_hi)
    return Lobe("abc", 2.0 / (m * m), float(rng.uniform(0.55, 1.5)), weight, fresnel)


def _lobe(rng, m_lo, m_hi, weight, fresnel) -> Lobe:
    make = _sgd_lobe if rng.random() < 0.5 else _abc_lobe
    return make(rng, m_lo, m_hi, weight, fresnel)


def _dielectric(rng, lo=1.40, hi=1.60) -> Fresnel:
    eta = float(rng.uniform(lo, hi))
    return Fresnel("dielectric", eta=(eta, eta, eta))


def material_params(index: int, seed: int = 0) -> MaterialParams:
    """Draw the parameters of material `index` from a Generator seeded by (seed, index)."""
    _check_seed(seed)
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise ConfigError(f"synthetic material index must be a non-negative integer, got {index!r}")
    index = int(index)
    rng = _rng(index, seed)
    category = CATEGORIES[index % len(CATEGORIES)]
    common = dict(
        noise=float(rng.uniform(0.004, 0.015)),
        invalid_fraction=_log_uniform(rng, 0.001, 0.02),
    )
    one = (1.0, 1.0, 1.0)

    if category == "metal":
        variant = str(rng.choice(sorted(_METALS)))
        eta, k = _METALS[variant]
        fres = Fresnel("conductor", eta=_jitter(rng, eta, 0.08, 0.05, 10.0), k=_jitter(rng, k, 0.08, 0.5, 12.0))
        lobes = [_lobe(rng, 0.015, 0.25, one, fres)]
        if rng.random() < 0.6:  # a broad haze lobe around the sharp one
            w = float(rng.uniform(0.05, 0.3))
            lobes.append(_lobe(rng, 0.2, 0.5, (w, w, w), fres))
            lobes[0] = replace(lobes[0], weight=(1 - w,) * 3)
        dust = float(rng.uniform(0.002, 0.02))
        params = MaterialParams(index, "", category, albedo=(dust, dust, dust), lobes=tuple(lobes), **common)

    elif category == "metallic-paint":
        variant = str(rng.choice(["red", "blue", "green", "silver", "gold", "purple", "teal", "black"]))
        base = {**_COLOURS, "silver": (0.35, 0.36, 0.38), "gold": (0.45, 0.32, 0.08)}[variant]
        base = _jitter(rng, base, 0.15, 0.005, 0.9)
        flake_f0 = _jitter(rng, tuple(0.25 + 0.7 * c for c in base), 0.1, 0.05, 0.98)
        flakes = _lobe(rng, 0.25, 0.45, (float(rng.uniform(0.2, 0.6)),) * 3, Fresnel("schlick", f0=flake_f0))
        coat = _lobe(rng, 0.01, 0.06, one, _dielectric(rng, 1.45, 1.55))
        params = MaterialParams(
            index, "", category, albedo=tuple(c * float(rng.uniform(0.2, 0.5)) for c in base),
            coat_eta=coat.fresnel.eta[0], lobes=(coat, flakes), **common,
        )

    elif category == "fabric":
        variant = str(rng.choice(_FABRICS))
        colour = str(rng.choice(sorted(_COLOURS)))
        base = _jitter(rng, _COLOURS[colour], 0.15, 0.01, 0.85)
        sheen_scale = float(rng.uniform(0.1, 0.5)) * (2.0 if variant in ("velvet", "silk", "satin") else 1.0)
        sheen = tuple(min(1.0, sheen_scale * (0.5 + 0.5 * c / max(base))) for c in base)
        lobes = (_lobe(rng, 0.25, 0.6, (float(rng.uniform(0.1, 0.5)),) * 3, _dielectric(rng)),)
        params = MaterialParams(
            index, "", category, albedo=base, oren_nayar_sigma=float(rng.uniform(0.2, 0.6)), lobes=lobes,
            sheen=sheen, sheen_r=float(rng.uniform(0.2, 0.9)),
            retro=tuple(c * float(rng.uniform(0.1, 0.5)) for c in base), retro_width=float(rng.uniform(0.15, 0.5)),
            **common,
        )
        variant = f"{variant}-{colour}"

    elif category == "rubber":
        variant = str(rng.choice(["black", "grey", "red", "blue", "green", "yellow"]))
        base = _jitter(rng, _COLOURS[variant], 0.2, 0.005, 0.8)
        f0 = float(rng.uniform(0.03, 0.06))
        lobes = (_lobe(rng, 0.25, 0.6, one, Fresnel("schlick", f0=(f0, f0, f0))),)
        params = MaterialParams(
            index, "", category, albedo=base, oren_nayar_sigma=float(rng.uniform(0.1, 0.4)), lobes=lobes,
            retro=tuple(c * float(rng.uniform(0.0, 0.15)) for c in base), retro_width=float(rng.uniform(0.3, 0.6)),
            **common,
        )

    else:  # plastic, phenolic: diffuse under a dielectric coat, one or two glossy lobes
        if category == "phenolic":
            variant = str(rng.choice(["black", "brown", "red", "green", "beige", "blue"]))
            m_lo, m_hi, eta_lo, eta_hi = 0.02, 0.12, 1.55, 1.65
        else:
            variant = str(rng.choice(sorted(_COLOURS)))
            m_lo, m_hi, eta_lo, eta_hi = 0.03, 0.3, 1.45, 1.55
        base = _jitter(rng, _COLOURS[variant], 0.15, 0.005, 0.9)
        fres = _dielectric(rng, eta_lo, eta_hi)
        lobes = [_lobe(rng, m_lo, m_hi, one, fres)]
        if rng.random() < 0.5:
            w = float(rng.uniform(0.2, 0.8))
            lobes.append(_lobe(rng, 0.25, 0.55, (w, w, w), fres))
        params = MaterialParams(index, "", category, albedo=base, coat_eta=fres.eta[0], lobes=tuple(lobes), **common)

    name = f"synth-{category}-{variant}-{index:02d}"
    return replace(params, name=name)


# --------------------------------------------------------------------------- evaluation


class Geometry(NamedTuple):
    """Cosines of direction pairs that an isotropic BRDF depends on.

    The tensors only need to broadcast together: flat (N,) for arbitrary pairs, or on the
    MERL grid (90, 1, 1) for θh and (1, 90, 1) for θd terms next to full (90, 90, 180)
    ones, so that D and Fresnel are computed on 90 values rather than 1.46 M. `mirrored`
    says that cos_o is cos_i flipped along the last axis (true on the grid: φd → π - φd
    swaps ωi and ωo), so per-direction terms are computed once and flipped.
    """

    cos_i: Tensor  # ωi·n
    cos_o: Tensor  # ωo·n
    cos_h: Tensor  # h·n
    cos_d: Tensor  # ωi·h
    cos_io: Tensor  # ωi·ωo
    cos_dphi: Tensor  # cos(φi - φo), 1 where an azimuth is undefined
    mirrored: bool = False


def _cos_dphi(wi: Tensor, wo: Tensor) -> Tensor:
    den = torch.hypot(wi[..., 0], wi[..., 1]) * torch.hypot(wo[..., 0], wo[..., 1])
    dot = wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1]
    return torch.where(den > 0, dot / torch.where(den > 0, den, 1.0), 1.0).clamp(-1.0, 1.0)


def geometry(wi: Tensor, wo: Tensor) -> Geometry:
    """Geometry of arbitrary direction pairs (N, 3), in float64."""
    wi, wo = wi.double(), wo.double()
    h = half_vector(wi, wo)
    return Geometry(wi[:, 2], wo[:, 2], h[:, 2], (wi * h).sum(-1), (wi * wo).sum(-1), _cos_dphi(wi, wo))


@lru_cache(maxsize=1)
def grid_geometry() -> tuple[Geometry, np.ndarray, np.ndarray]:
    """Geometry at the MERL cell centres (broadcast shapes), the above-horizon mask and the
    larger of θi, θo in degrees, both (90, 90, 180). Cached: every material of a set shares it."""
    wi, wo = merl.grid_directions(torch.float64)
    angles = merl.grid_angles(torch.float64)
    theta_h = angles.theta_h.reshape(merl.SHAPE)[:, :1, :1]
    theta_d = angles.theta_d.reshape(merl.SHAPE)[:1, :, :1]
    cos_i = wi[:, 2].reshape(merl.SHAPE)
    cos_o = wo[:, 2].reshape(merl.SHAPE)
    above = merl.grid_above_horizon().reshape(merl.SHAPE)
    # The grid is symmetric under φd → π - φd (ωi ⇄ ωo); use it exactly so terms are computed once.
    mirrored = bool(torch.equal(above, above.flip(-1)) and (cos_i.flip(-1) - cos_o).abs().max() < 1e-12)
    g = Geometry(
        cos_i, cos_i.flip(-1).contiguous() if mirrored else cos_o, torch.cos(theta_h), torch.cos(theta_d),
        torch.cos(2 * theta_d), _cos_dphi(wi, wo).reshape(merl.SHAPE), mirrored,
    )
    max_theta = torch.rad2deg(torch.acos(torch.minimum(cos_i, cos_o).clamp(-1.0, 1.0))).numpy()
    return g, above.numpy(), max_theta


def _rgb(values, like: Tensor) -> Tensor:
    """An RGB triple shaped (3, 1, ...) to broadcast against `like`."""
    return torch.tensor(values, dtype=torch.float64).reshape(3, *([1] * like.ndim))


def _dielectric_reflectance(eta: float | Tensor, c: Tensor) -> Tensor:
    """Unpolarised Fresnel reflectance of a dielectric (relative index eta > 1) at cosine c in [0, 1]."""
    ct = torch.sqrt((1 - (1 - c * c) / (eta * eta)).clamp(min=0.0))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def fresnel(f: Fresnel, c: Tensor) -> Tensor:
    """Unpolarised reflectance (3, *c.shape) at cosine c between light and microfacet normal."""
    c = c.clamp(0.0, 1.0)[None]
    if f.kind == "schlick":
        f0 = _rgb(f.f0, c[0])
        return f0 + (1 - f0) * (1 - c) ** 5
    eta = _rgb(f.eta, c[0])
    if f.kind == "dielectric":
        r = _dielectric_reflectance(eta[:1] if len(set(f.eta)) == 1 else eta, c)
        return r.expand(3, *r.shape[1:])
    if f.kind == "conductor":
        k = _rgb(f.k, c[0])
        c2 = c * c
        s2 = 1 - c2
        t0 = eta * eta - k * k - s2
        a2b2 = torch.sqrt(t0 * t0 + 4 * eta * eta * k * k)
        a = torch.sqrt((0.5 * (a2b2 + t0)).clamp(min=0.0))
        t1 = a2b2 + c2
        t2 = 2 * a * c
        rs = (t1 - t2) / (t1 + t2)
        t3 = c2 * a2b2 + s2 * s2
        t4 = t2 * s2
        rp = rs * (t3 - t4) / (t3 + t4)
        return 0.5 * (rs + rp)
    raise ValueError(f"unknown Fresnel kind {f.kind!r}")


def _sgd_norm(a: float, b: float) -> float:
    """∫0^∞ exp(-u/a) (a+u)^-b du = a^(1-b) ∫0^∞ e^-t (1+t)^-b dt (Gauss–Laguerre: smooth integrand)."""
    t, w = np.polynomial.laguerre.laggauss(80)
    return float(a ** (1 - b) * np.sum(w * (1 + t) ** -b))


def _abc_norm(a: float, b: float) -> float:
    """2π ∫0^1 (1 + a(1-x))^-b x dx in closed form, stable near b = 1 and b = 2."""
    L = math.log1p(a)

    def e(p):  # ∫1^(1+a) y^(p-1) dy
        return math.expm1(p * L) / p if abs(p) > 1e-12 else L

    return 2 * math.pi / (a * a) * ((a + 1) * e(1 - b) - e(2 - b))


def _distribution(kind: str, a: float, b: float, cos_h: Tensor) -> Tensor:
    c = cos_h.double().clamp(min=0.0)
    if kind == "sgd":
        cc = c.clamp(min=1e-8)
        c2 = cc * cc
        u = (1 - c2) / c2
        d = torch.exp(-u / a) * (a + u) ** (-b) / (math.pi * c2 * c2 * _sgd_norm(a, b))
    elif kind == "abc":
        d = (1 + a * (1 - c)) ** (-b) / _abc_norm(a, b)
    else:
        raise ValueError(f"unknown lobe kind {kind!r}")
    return torch.where(c > 0, d, torch.zeros_like(d))


def distribution(lobe: Lobe, cos_h: Tensor) -> Tensor:
    """Normalised microfacet distribution D(h) (∫ D cosθh dω = 1); 0 at or below the horizon."""
    return _distribution(lobe.kind, lobe.a, lobe.b, cos_h)


#: Nodes (uniform in cos θ over [0, 1]) of the tabulated projected areas, and θh quadrature points.
_AREA_NODES = 513
_AREA_QUAD = 2048


@lru_cache(maxsize=256)
def _projected_area(kind: str, a: float, b: float) -> Tensor:
    """P(θ) = ∫ D(h) max(0, ω·h) dh at cos θ = linspace(0, 1, _AREA_NODES), so that Smith's
    Λ(ω) = P / cos θ - 1 for this very D. The azimuth is integrated in closed form; θh by a
    midpoint rule in √θh (fine near the peak), normalised so that P(0°) = 1 exactly."""
    t = (np.arange(_AREA_QUAD) + 0.5) / _AREA_QUAD
    theta_h = 0.5 * np.pi * t * t
    weight = _distribution(kind, a, b, torch.from_numpy(np.cos(theta_h))).numpy() * np.sin(theta_h) * np.pi * t
    cos_o = np.linspace(0.0, 1.0, _AREA_NODES)[:, None]
    sin_o = np.sqrt(1 - cos_o * cos_o)
    A = cos_o * np.cos(theta_h)  # ω·h = A + B cos φ
    B = sin_o * np.sin(theta_h)
    ratio = np.clip(-A / np.where(B > 0, B, 1.0), -1.0, 1.0)
    ratio = np.where(B > 0, ratio, np.where(A >= 0, -1.0, 1.0))
    kernel = 2 * (A * np.arccos(ratio) + np.sqrt(np.clip(B * B - A * A, 0.0, None)))
    area = (kernel * weight).sum(axis=1) / _AREA_QUAD  # numpy pairwise sum: same bits on any BLAS
    return torch.from_numpy(area / area[-1])


@lru_cache(maxsize=64)
def _coat_transmission_ratio(eta: float) -> Tensor:
    """(1 - F(θ)) / cos θ of a dielectric interface at the cos θ nodes: smooth and finite at
    grazing (1 - F vanishes linearly there), so linear interpolation of it is accurate."""
    c = torch.linspace(0.0, 1.0, _AREA_NODES, dtype=torch.float64)
    c[0] = 1e-9  # the finite limit at grazing
    return (1 - _dielectric_reflectance(eta, c)) / c


def coat_transmission(eta: float, c: Tensor) -> Tensor:
    """1 - F of a dielectric interface at cosines c in [0, 1], from the table."""
    return _lerp(_coat_transmission_ratio(eta), _interp_index(c)).mul_(c)


def _interp_index(c: Tensor) -> tuple[Tensor, Tensor]:
    """Node index and fraction of cosines c (clamped to [0, 1]) in the uniform cos θ tables."""
    x = c.clamp(0.0, 1.0) * (_AREA_NODES - 1)
    i0 = x.long().clamp_(max=_AREA_NODES - 2)
    return i0, x.sub_(i0)


def _lerp(table: Tensor, at: tuple[Tensor, Tensor]) -> Tensor:
    i0, frac = at
    slope = table[1:] - table[:-1]
    return table[i0].addcmul_(slope[i0], frac)


def smith_g2(lobe: Lobe, cos_i: Tensor, cos_o: Tensor) -> Tensor:
    """Height-correlated Smith shadowing-masking 1 / (1 + Λ(ωi) + Λ(ωo)) of the lobe's D (cosines > 0)."""
    area = _projected_area(lobe.kind, lobe.a, lobe.b)
    return 1 / (_lerp(area, _interp_index(cos_i)) / cos_i + _lerp(area, _interp_index(cos_o)) / cos_o - 1)


def evaluate(p: MaterialParams, g: Geometry) -> Tensor:
    """Noise-free BRDF values (3, *shape) in 1/sr; symmetric in (ωi, ωo); 0 below the horizon.

    The specular 1/(4 cosθi cosθo) uses cosines softened by APERTURE, as a real instrument
    averages over a finite footprint near grazing; without it sharp lobes reach 10^6 1/sr there.
    """
    below = (g.cos_i <= 0) | (g.cos_o <= 0)
    ci = g.cos_i.clamp(1e-12, 1.0)
    co = ci.flip(-1) if g.mirrored else g.cos_o.clamp(1e-12, 1.0)

    if p.lobes or p.coat_eta is not None:  # where ci, co fall in the cos θ tables, shared by all terms
        at_i = _interp_index(ci)
        at_o = None if g.mirrored else _interp_index(co)

    def pair(table: Tensor) -> tuple[Tensor, Tensor]:
        """A cos θ table at θi and θo: looked up once and flipped where the geometry is mirrored."""
        fi = _lerp(table, at_i)
        return fi, (fi.flip(-1) if g.mirrored else _lerp(table, at_o))

    # Diffuse: Lambert, optionally Oren–Nayar, optionally through a dielectric coat.
    diffuse = None
    if p.oren_nayar_sigma > 0:
        s2 = p.oren_nayar_sigma**2
        A = 1 - 0.5 * s2 / (s2 + 0.33)
        B = 0.45 * s2 / (s2 + 0.09)
        lo = torch.minimum(ci, co)  # cosine of the larger angle
        hi = torch.maximum(ci, co)
        sin_alpha = torch.sqrt((1 - lo * lo).clamp_(min=0.0))
        tan_beta = torch.sqrt((1 - hi * hi).clamp_(min=0.0)).div_(hi)
        diffuse = sin_alpha.mul_(tan_beta).mul_(g.cos_dphi.clamp(min=0.0)).mul_(B).add_(A)
    if p.coat_eta is not None:
        ti, to = pair(_coat_transmission_ratio(p.coat_eta))  # (1 - F) / cos θ
        ti.mul_(to).mul_(ci).mul_(co)
        diffuse = ti if diffuse is None else diffuse.mul_(ti)
    albedo = _rgb(p.albedo, ci) / math.pi
    out = albedo.expand(3, *ci.shape).clone() if diffuse is None else albedo * diffuse[None]

    # Microfacet lobes: F D G2 / (4 cosθi cosθo), G2 the height-correlated Smith term of D.
    if p.lobes:
        inv_footprint = ((ci + APERTURE) * (co + APERTURE)).mul_(4 / (1 + APERTURE) ** 2).reciprocal_()
    for lobe in p.lobes:
        area_i, area_o = pair(_projected_area(lobe.kind, lobe.a, lobe.b))
        # 1 / (1 + Λi + Λo) with 1 + Λ = P / cos θ
        shadowed = area_i.div_(ci).add_(area_o.div_(co)).sub_(1.0).reciprocal_().mul_(inv_footprint)
        angular = distribution(lobe, g.cos_h)[None] * fresnel(lobe.fresnel, g.cos_d) * _rgb(lobe.weight, g.cos_d)
        out.addcmul_(angular, shadowed[None])

    # Fabric sheen (Charlie distribution, Neubelt visibility) and retro-reflection.
    if any(p.sheen):
        sin_h = torch.sqrt((1 - g.cos_h * g.cos_h).clamp(min=0.0))
        inv_r = 1 / p.sheen_r
        d = (2 + inv_r) * sin_h**inv_r / (2 * math.pi)
        v = (ci + co - ci * co).mul_(4).reciprocal_()
        out.addcmul_(_rgb(p.sheen, d) * d[None], v[None])
    if any(p.retro):
        hump = torch.exp(-(1 - g.cos_io) / (p.retro_width**2))
        out.add_(_rgb(p.retro, hump) / math.pi * hump[None])

    return out.masked_fill_(below[None], 0.0)


def sensor_response(v: Tensor) -> Tensor:
    """Compress values above SENSOR_KNEE logarithmically (C1), like a finite dynamic range; in place."""
    if v.numel() and float(v.max()) > SENSOR_KNEE:
        over = v > SENSOR_KNEE
        v[over] = SENSOR_KNEE * (1 + torch.log(v[over] / SENSOR_KNEE))
    return v


def generate_material(index: int, seed: int = 0) -> tuple[str, str, MerlTable]:
    """(name, category, MERL table) of synthetic material `index`; a pure function of (index, seed)."""
    p = material_params(index, seed)
    g, above, max_theta = grid_geometry()
    values = sensor_response(evaluate(p, g)).numpy()
    rng = np.random.default_rng([seed, index, 1])  # own stream: noise and dropouts don't shift parameters
    # Multiplicative noise, uniform with relative σ = p.noise (cheaper than Gaussian, stays positive).
    gain = rng.random(values.shape, dtype=np.float32)
    gain -= np.float32(0.5)
    gain *= np.float32(p.noise * math.sqrt(12.0))
    gain += np.float32(1.0)
    values *= gain

    # Invalid cells: below the horizon, and a small random fraction of grazing cells, more
    # likely the more grazing (as a real gonioreflectometer loses those samples).
    valid = above.copy()
    grazing = np.flatnonzero(above & (max_theta > GRAZING_DEG))
    excess = (max_theta.reshape(-1)[grazing] - GRAZING_DEG) / (90.0 - GRAZING_DEG)
    prob = np.clip(p.invalid_fraction * (0.25 + excess) / np.mean(0.25 + excess), 0.0, 1.0)
    valid.reshape(-1)[grazing[rng.random(grazing.size) < prob]] = False
    return p.name, p.category, MerlTable.from_values(values, valid)


# --------------------------------------------------------------------------- the dataset


def _check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"synthetic dataset seed must be a non-negative integer, got {seed!r}")


def _resolve_size(size) -> int:
    n = None
    if isinstance(size, str):
        n = SIZES.get(size)
        if n is None and size.strip().isdigit():
            n = int(size.strip())
    elif isinstance(size, (int, np.integer)) and not isinstance(size, bool):
        n = int(size)
    if n is None or not 1 <= n <= MAX_SIZE:
        raise ConfigError(
            f"synthetic dataset size must be 'default' (24), 'small' (6) or an integer 1..{MAX_SIZE}, got {size!r}"
        )
    return n


def material_names(size: str | int = "default", seed: int = 0) -> tuple[str, ...]:
    """Names of the first `size` materials (cheap: draws parameters only)."""
    _check_seed(seed)
    return tuple(material_params(i, seed).name for i in range(_resolve_size(size)))


def synthetic_dataset(size: str | int = "default", seed: int = 0, cache_dir: str | None = None) -> Dataset:
    """The embedded default dataset; each material's `.binary` file is generated on first load.

    Beside each cache file, `NAME.binary.sha256` records the digest of the file as generated.
    A cache file whose content no longer matches it (edited, replaced, damaged) is
    regenerated with a warning; one without a record (an older cache) is regenerated and
    compared. The fingerprint is the generator version, the seed and, for a set of other
    than the default 24 materials, its size (a set of 12 is other data than a set of 24:
    a report ranks each apart): the same data whatever the state of the cache.
    """
    n = _resolve_size(size)
    _check_seed(seed)
    seed = int(seed)
    params = [material_params(i, seed) for i in range(n)]
    index = {p.name: p.index for p in params}
    folder = cache_root(cache_dir) / "synthetic" / f"{GENERATOR_VERSION}-seed{seed}"
    digests = DigestCache(cache_dir)

    def cached(name: str, path: Path, record: Path) -> tuple[Material | None, str | None]:
        """The cached material if its content is as generated; else None and the file's digest."""
        if not path.exists():
            return None, None
        try:
            actual = digests.digest(path)
        except OSError:
            return None, None
        finally:
            digests.save()
        expected = recorded_digest(record)
        if expected is not None and actual != expected:
            log.warning("%s: content differs from the generated file (sha256 %s..., recorded %s...); regenerating it",
                        path, actual[:12], expected[:12])
            return None, None
        if expected is None:
            return None, actual  # no record: regenerate, then compare
        try:
            table = merl.read_binary(path)
        except DataError as exc:
            log.warning("%s; regenerating it", exc)
            return None, None
        return Material(name, table, params[index[name]].category, source=str(path)), None

    def load(name: str) -> Material:
        path = folder / f"{name}.binary"
        record = folder / f"{name}.binary.sha256"
        material, unrecorded = cached(name, path, record)
        if material is not None:
            return material
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DataError(f"{folder}: cannot create the synthetic dataset cache ({exc.strerror})") from None
        _, category, table = generate_material(index[name], seed)
        try:
            merl.write_binary(path, table)
            digest = sha256_file(path)
            with replacing(record) as tmp:
                tmp.write_text(digest + "\n", encoding="ascii")
        except OSError as exc:
            raise DataError(f"{path}: cannot write the synthetic material ({exc.strerror or exc})") from None
        if unrecorded is not None and unrecorded != digest:
            log.warning("%s: cached file differed from the generator's output; regenerated it", path)
        return Material(name, merl.read_binary(path), category, source=str(path))

    return Dataset(
        name="synthetic",
        materials=tuple(p.name for p in params),
        loader=load,
        fingerprint=f"synthetic-{GENERATOR_VERSION}-seed{seed}" + ("" if n == SIZES["default"] else f"-n{n}"),
        categories={p.name: p.category for p in params},
    )
