"""HDR environment maps in torch, evaluated exactly as Mitsuba 3's `envmap` emitter does.

A torch renderer lights an object with `Envmap.eval` and importance-samples it with
`Envmap.sample` / `Envmap.pdf`; its image is compared with Mitsuba's path tracer using
`Envmap.mitsuba_dict()`, the `envmap` emitter on the same bitmap, scale and rotation.

Conventions (Mitsuba 3.9.1 `envmap`, checked numerically in tests/unit/test_envmap.py):

- Local frame: **+Y is up**. A local unit direction d = (x, y, z) has the lat-long
  coordinates u = atan2(x, −z) / 2π (mod 1) and v = arccos(y) / π, the formula of
  Mitsuba's `envmap.cpp` (`direction_to_uv`). So the azimuth φ = 2πu is measured about +Y
  from −Z towards +X (u = 0: −Z, ¼: +X, ½: +Z, ¾: −X), θ = πv from +Y, and
  d = (sin φ sin θ, cos θ, −cos φ sin θ).
- Texels: row j (0 at the top) and column i (0 at the left) of an H × W image hold the
  radiance towards θ_j = π j / (H − 1) and φ_i = 2π (i + ½) / W: rows are *vertex*-centred
  (row 0 is the zenith +Y itself, row H − 1 the nadir), columns *cell*-centred. Between
  them radiance is bilinear, periodic in u, as Mitsuba interpolates (measured on impulse
  images: a tent of one texel in both directions). At the poles Mitsuba reads u = 0.
- World: ω = to_world · d for a rotation to_world (translation has no meaning at
  infinity); radiance = scale × the bilinear lookup, in linear RGB (Mitsuba's RGB
  variants; its spectral ones upsample the texels and differ).

Sampling (this module's own scheme, not Mitsuba's bilinear `Hierarchical2D` warp): the
sphere is cut into the (H − 1) × W bilinear cells between texel centres; a cell is chosen
with probability ∝ (mean luminance of its 4 corner texels) × (its solid angle), and a
direction uniformly in solid angle inside it (φ uniform, cos θ uniform). The density is
piecewise constant in solid angle, finite everywhere, exactly normalised, and positive
wherever `eval` is (eval > 0 inside a cell only if one of its corners is non-zero).
Mitsuba weights texels by luminance × sin θ_j, which vanishes on the pole rows, so a cap
lit only by a pole row gets no density there (3.9.1 returns NaN for a map lit only there);
on ordinary maps the two densities agree closely (median ratio 1.00002 on the default sky,
90% of samples within ±10%).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import torch

from ..errors import DataError
from ..images import read_exr

Tensor = torch.Tensor

#: Smallest accepted map height (width 2×): coarser maps are test patterns, not skies.
MIN_HEIGHT = 8
#: Mitsuba's `luminance()` of linear sRGB (Rec. 709 Y row), used for its sampling weights too.
LUMINANCE_RGB = (0.212671, 0.715160, 0.072169)
#: Largest |RᵀR − I| accepted for to_world.
ROTATION_TOLERANCE = 1e-5


# --------------------------------------------------------------------------- conventions


def direction_to_uv(d: Tensor) -> Tensor:
    """(N, 2) lat-long (u, v) in [0, 1]² of local directions (N, 3), Mitsuba's formula:
    u = atan2(x, −z)/2π mod 1, v = arccos(y)/π; u = 0 on the ±Y axis (as Mitsuba reads it)."""
    x, y, z = d.unbind(-1)
    u = torch.atan2(x, -z) / (2.0 * math.pi)
    u = torch.where((x == 0) & (z == 0), torch.zeros_like(u), u)
    u = u - torch.floor(u)
    v = torch.acos(y.clamp(-1.0, 1.0)) / math.pi
    return torch.stack((u, v), dim=-1)


def uv_to_direction(uv: Tensor) -> Tensor:
    """(N, 3) local unit directions of lat-long coordinates (N, 2): (sin φ sin θ, cos θ, −cos φ sin θ)."""
    phi, theta = 2.0 * math.pi * uv[..., 0], math.pi * uv[..., 1]
    s = torch.sin(theta)
    return torch.stack((torch.sin(phi) * s, torch.cos(theta), -torch.cos(phi) * s), dim=-1)


def texel_directions(height: int, width: int, dtype: torch.dtype = torch.float64) -> Tensor:
    """(H, W, 3) local directions at which `Envmap.eval` returns texel (j, i) exactly:
    θ_j = π j/(H − 1), φ_i = 2π (i + ½)/W."""
    v = torch.arange(height, dtype=torch.float64) / (height - 1)
    u = (torch.arange(width, dtype=torch.float64) + 0.5) / width
    vv, uu = torch.meshgrid(v, u, indexing="ij")
    return uv_to_direction(torch.stack((uu, vv), dim=-1)).to(dtype)


def luminance(rgb: Tensor) -> Tensor:
    """Luminance Y of linear-sRGB values (..., 3), with Mitsuba's coefficients."""
    w = torch.tensor(LUMINANCE_RGB, dtype=rgb.dtype, device=rgb.device)
    return (rgb * w).sum(-1)


# --------------------------------------------------------------------------- validation


def check_envmap_image(image, name: str = "environment map", error: type[Exception] = ValueError) -> Tensor:
    """The (H, W, 3) float32 RGB radiance of a lat-long map, or `error` naming `name` and the fault.

    Accepted: a float tensor or array (H, W, C ≥ 3; channels beyond RGB are dropped), W = 2H,
    H ≥ MIN_HEIGHT, every value finite and ≥ 0, not all zero."""
    if isinstance(image, np.ndarray):
        image = torch.from_numpy(image)
    if not isinstance(image, torch.Tensor):
        raise error(f"{name}: expected an image tensor (H, W, 3), got {type(image).__name__}")
    if not image.is_floating_point():
        raise error(f"{name}: expected float (linear HDR) radiance, got dtype {image.dtype}")
    if image.ndim != 3 or image.shape[-1] < 3:
        raise error(f"{name}: expected an RGB image of shape (H, W, ≥3), got {tuple(image.shape)}")
    h, w = int(image.shape[0]), int(image.shape[1])
    if w != 2 * h:
        raise error(f"{name}: {w}×{h} is not a lat-long environment map (width must be twice the height)")
    if h < MIN_HEIGHT:
        raise error(f"{name}: {w}×{h} is too small for an environment map (at least {2 * MIN_HEIGHT}×{MIN_HEIGHT})")
    rgb = image[..., :3].detach().to("cpu", torch.float64)
    bad = ~torch.isfinite(rgb).all(-1)
    if bad.any():
        y, x = (int(c) for c in torch.nonzero(bad)[0])
        raise error(f"{name}: {int(bad.sum())} texels are not finite (NaN/Inf), first at (row {y}, column {x})")
    neg = (rgb < 0).any(-1)
    if neg.any():
        y, x = (int(c) for c in torch.nonzero(neg)[0])
        raise error(f"{name}: {int(neg.sum())} texels have negative radiance, first at (row {y}, column {x}): "
                    f"{rgb[y, x].tolist()}")
    out = rgb.to(torch.float32)
    if not torch.isfinite(out).all():
        raise error(f"{name}: radiance overflows float32 (max {float(rgb.max()):.3g})")
    if not (out > 0).any():
        raise error(f"{name}: every texel is zero (an environment map must emit somewhere)")
    return out.contiguous()


def _rotation(to_world) -> Tensor:
    """(3, 3) float64 rotation from None, a 3×3 or a 4×4 (affine; translation ignored) matrix."""
    if to_world is None:
        return torch.eye(3, dtype=torch.float64)
    m = torch.as_tensor(np.asarray(to_world, dtype=np.float64))
    if m.shape == (4, 4):
        m = m[:3, :3]
    if m.shape != (3, 3):
        raise ValueError(f"to_world must be a 3×3 rotation (or 4×4 transform), got shape {tuple(m.shape)}")
    err = float((m.T @ m - torch.eye(3, dtype=torch.float64)).abs().max())
    if not math.isfinite(err) or err > ROTATION_TOLERANCE or float(torch.linalg.det(m)) <= 0:
        raise ValueError(f"to_world must be a rotation (orthonormal, det +1): |RᵀR − I| = {err:.3g}, "
                         f"det = {float(torch.linalg.det(m)):.6g}. Mitsuba's envmap does not renormalise "
                         f"directions, so a scaled map would not be a radiance map.")
    return m.clone()


# --------------------------------------------------------------------------- the map


class Envmap:
    """A lat-long HDR environment map: radiance lookup as Mitsuba's `envmap`, plus importance sampling.

    `image` (H, W, ≥3) linear RGB radiance (validated by `check_envmap_image`); `to_world`
    a rotation (3×3, or 4×4 whose translation is ignored) from the map's +Y-up frame to
    the world; `scale` multiplies the radiance. Directions are world unit vectors (N, 3)
    pointing from the scene towards the environment. Computations run in float64 and
    results come back in the dtype (and device) of the argument.
    """

    def __init__(self, image, to_world=None, scale: float = 1.0, *, name: str = "environment map"):
        self.name = name
        self.image = check_envmap_image(image, name)
        self.height, self.width = int(self.image.shape[0]), int(self.image.shape[1])
        self.to_world = _rotation(to_world)
        self._texels = self.image.to(torch.float64).reshape(-1, 3)  # eval's lookup table
        self.scale = float(scale)
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"{name}: scale must be finite and > 0, got {scale!r}")
        self._build_distribution()

    @classmethod
    def from_file(cls, path: str | os.PathLike, to_world=None, scale: float = 1.0) -> "Envmap":
        """Read and validate an OpenEXR lat-long map; a bad file raises DataError naming it."""
        return cls(_read_envmap_exr(path), to_world, scale, name=str(path))

    def __repr__(self) -> str:
        return f"Envmap({self.name!r}, {self.width}×{self.height}, scale={self.scale:g})"

    # ------------------------------------------------------------------ radiance

    def eval(self, d: Tensor) -> Tensor:
        """(N, 3) radiance arriving from world directions d (N, 3): Mitsuba's `envmap` lookup."""
        uv = direction_to_uv(self._to_local(d))
        h, w = self.height, self.width
        x = uv[:, 0] * w - 0.5  # column coordinate: texel i sits at x = i
        x = x - torch.floor(x / w) * w
        i0 = torch.floor(x).clamp(0, w - 1)
        fx = (x - i0).unsqueeze(-1)
        y = uv[:, 1] * (h - 1)  # row coordinate: texel j sits at y = j
        j0 = torch.floor(y).clamp(0, h - 2)
        fy = (y - j0).unsqueeze(-1)
        i0, j0 = i0.long(), j0.long()
        i1 = (i0 + 1) % w
        img = self._texels if d.device == self._texels.device else self._texels.to(d.device)
        row0, row1 = j0 * w, (j0 + 1) * w
        top = (1 - fx) * img[row0 + i0] + fx * img[row0 + i1]
        bottom = (1 - fx) * img[row1 + i0] + fx * img[row1 + i1]
        return (self.scale * ((1 - fy) * top + fy * bottom)).to(d.dtype)

    # ------------------------------------------------------------------ sampling

    def _build_distribution(self) -> None:
        """Cell probabilities and the row-marginal / per-row conditional CDFs of the sampling scheme."""
        h, w = self.height, self.width
        lum = luminance(self.image.to(torch.float64)).clamp_min(0.0)  # (H, W)
        right = torch.roll(lum, shifts=-1, dims=1)  # texel i + 1 (periodic)
        corners = 0.25 * (lum[:-1] + right[:-1] + lum[1:] + right[1:])  # (H−1, W): cell (j, i)
        cos_theta = torch.cos(torch.arange(h, dtype=torch.float64) * (math.pi / (h - 1)))
        self._cos_theta = cos_theta
        band = (cos_theta[:-1] - cos_theta[1:]) * (2.0 * math.pi / w)  # (H−1,) solid angle of one cell
        mass = corners * band[:, None]
        prob = mass / mass.sum()  # (H−1, W)
        self._density = prob / band[:, None]  # pdf in solid angle inside each cell
        row = prob.sum(1)
        self._row_cdf = _cdf(row[None])[0]
        cond = torch.where(row[:, None] > 0, prob / row.clamp_min(1e-300)[:, None], torch.full_like(prob, 1.0 / w))
        self._cond_prob = cond
        # Row j's conditional CDF, shifted by j, so one sorted table serves every row.
        self._cond_cdf = (_cdf(cond) + torch.arange(h - 1, dtype=torch.float64)[:, None]).reshape(-1)

    def sample(self, u: Tensor) -> tuple[Tensor, Tensor]:
        """World directions (N, 3) and their solid-angle density (N,) for u (N, 2) in [0, 1)².

        u[:, 1] picks the row of cells (θ band) and then cos θ inside it; u[:, 0] the cell
        along the row and then φ inside it (both by reusing the remainder of the inversion)."""
        if u.ndim != 2 or u.shape[-1] != 2:
            raise ValueError(f"expected samples of shape (N, 2), got {tuple(u.shape)}")
        w = self.width
        uu = u.detach().to(torch.float64).cpu().clamp(0.0, 1.0 - 2.0**-53)
        j, r1 = _invert(self._row_cdf, uu[:, 1].contiguous())
        flat = torch.searchsorted(self._cond_cdf, j.to(torch.float64) + uu[:, 0], right=True)
        flat = torch.minimum(flat, j * w + (w - 1))
        i = flat - j * w
        p_cell = self._cond_prob[j, i]
        start = torch.where(i > 0, self._cond_cdf[(flat - 1).clamp_min(0)] - j.to(torch.float64), torch.zeros_like(p_cell))
        r0 = ((uu[:, 0] - start) / p_cell.clamp_min(1e-300)).clamp(0.0, 1.0)
        phi = (2.0 * math.pi / w) * (i.to(torch.float64) + 0.5 + r0)
        c0, c1 = self._cos_theta[j], self._cos_theta[j + 1]
        cos_t = (c0 - r1 * (c0 - c1)).clamp(-1.0, 1.0)
        sin_t = torch.sqrt((1.0 - cos_t * cos_t).clamp_min(0.0))
        local = torch.stack((torch.sin(phi) * sin_t, cos_t, -torch.cos(phi) * sin_t), dim=-1)
        world = local @ self.to_world.T
        pdf = self._density[j, i]
        return world.to(device=u.device, dtype=u.dtype), pdf.to(device=u.device, dtype=u.dtype)

    def pdf(self, d: Tensor) -> Tensor:
        """(N,) solid-angle density with which `sample` draws the world directions d (N, 3)."""
        uv = direction_to_uv(self._to_local(d).cpu())
        h, w = self.height, self.width
        x = uv[:, 0] * w - 0.5
        i = torch.floor(x - torch.floor(x / w) * w).clamp(0, w - 1).long()
        j = torch.floor(uv[:, 1] * (h - 1)).clamp(0, h - 2).long()
        return self._density[j, i].to(device=d.device, dtype=d.dtype)

    def _to_local(self, d: Tensor) -> Tensor:
        if d.ndim != 2 or d.shape[-1] != 3:
            raise ValueError(f"expected directions of shape (N, 3), got {tuple(d.shape)}")
        return d.to(torch.float64) @ self.to_world.to(d.device)  # rows: Rᵀ d

    # ------------------------------------------------------------------ Mitsuba

    def mitsuba_dict(self) -> dict:
        """The same map as a Mitsuba 3 emitter for `mi.load_dict` (call with an RGB variant set)."""
        import mitsuba as mi

        if mi.variant() is None:
            raise RuntimeError("Envmap.mitsuba_dict needs a Mitsuba variant "
                               "(use brdfbench.mitsuba_env.mitsuba_variant(...))")
        m = np.eye(4)
        m[:3, :3] = self.to_world.numpy()
        return {
            "type": "envmap",
            "bitmap": mi.Bitmap(np.ascontiguousarray(self.image.numpy())),
            "scale": self.scale,
            "to_world": mi.ScalarTransform4f(m),
        }


def _cdf(p: Tensor) -> Tensor:
    """Inclusive CDFs of the rows of non-negative weights p (M, K), each with a positive entry:
    exactly 1 from a row's last positive entry on, so that inversion never lands past it."""
    cdf = torch.cumsum(p, 1)
    cdf = cdf / cdf[:, -1:]
    k = p.shape[1]
    last = (k - 1) - torch.argmax(torch.flip(p > 0, dims=[1]).to(torch.int8), dim=1)
    cdf[torch.arange(k) >= last[:, None]] = 1.0
    return cdf


def _invert(cdf: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
    """Index k with cdf[k−1] ≤ u < cdf[k] (never a zero-probability entry) and the remainder in [0, 1]."""
    k = torch.searchsorted(cdf, u, right=True).clamp(max=cdf.numel() - 1)
    start = torch.where(k > 0, cdf[(k - 1).clamp_min(0)], torch.zeros_like(u))
    width = cdf[k] - start
    return k, ((u - start) / width.clamp_min(1e-300)).clamp(0.0, 1.0)


# --------------------------------------------------------------------------- files


def _read_envmap_exr(path: str | os.PathLike) -> Tensor:
    """(H, W, 3) float32 radiance of an OpenEXR lat-long map, or DataError naming the file and fault."""
    path = Path(path)
    return check_envmap_image(read_exr(path), str(path), DataError)


def load_envmap(path: str | os.PathLike, to_world=None, scale: float = 1.0) -> Envmap:
    """`Envmap.from_file`: an OpenEXR lat-long map, validated (DataError naming the file)."""
    return Envmap.from_file(path, to_world, scale)


# --------------------------------------------------------------------------- a sky


def procedural_sky(
    width: int = 512,
    height: int = 256,
    *,
    sun_elevation_deg: float = 35.0,
    sun_azimuth_deg: float = 135.0,
    sun_radius_deg: float = 2.0,
    sun_radiance: float = 500.0,
    sun_color: tuple[float, float, float] = (1.0, 0.95, 0.85),
    zenith_color: tuple[float, float, float] = (0.20, 0.35, 0.80),
    horizon_color: tuple[float, float, float] = (0.85, 0.92, 1.00),
    ground_color: tuple[float, float, float] = (0.20, 0.17, 0.13),
    glow: float = 1.0,
    glow_width_deg: float = 8.0,
) -> Tensor:
    """A deterministic clear-sky HDR lat-long map (H, W, 3) float32, in `Envmap`'s conventions.

    Texel (j, i) is the radiance towards its `texel_directions` (θ_j = πj/(H−1) from +Y,
    φ_i = 2π(i + ½)/W from −Z towards +X), so `Envmap(sky).eval` returns it exactly there.
    Above the horizon (local y > 0): a gradient from `horizon_color` to `zenith_color` in
    √(sin elevation), plus a circumsolar glow `glow`·horizon_color·exp(−γ/glow_width),
    γ the angle to the sun. Below: `ground_color`, blended over the 1° under the horizon.
    The sun: a disk of angular radius `sun_radius_deg` towards
    (sin φs cos e, sin e, −cos φs cos e), e = `sun_elevation_deg`, φs = `sun_azimuth_deg`
    (Mitsuba's u = φs/360; the default 135° puts it above, right of and in front of a
    camera on +Z looking at the origin), with peak radiance `sun_radiance`·`sun_color`
    (by default ~700× the sky's mean luminance and ~1350× the zenith's; the disk carries
    about a quarter of the map's power), linear limb darkening (0.6), and an
    edge ramped over one texel so that its power varies little with the resolution. The
    sun is drawn wherever it is, also below the horizon.
    """
    if width != 2 * height or height < MIN_HEIGHT:
        raise ValueError(f"procedural_sky: {width}×{height} must be a lat-long size (width = 2 × height ≥ {2 * MIN_HEIGHT})")
    if not -90.0 <= sun_elevation_deg <= 90.0:
        raise ValueError(f"procedural_sky: sun_elevation_deg must be in [-90, 90], got {sun_elevation_deg}")
    if not (sun_radius_deg > 0 and sun_radiance >= 0 and glow >= 0 and glow_width_deg > 0):
        raise ValueError("procedural_sky: sun_radius_deg and glow_width_deg must be > 0, sun_radiance and glow ≥ 0")
    d = texel_directions(height, width)  # (H, W, 3) float64
    up = d[..., 1]
    col = lambda c: torch.tensor(c, dtype=torch.float64)  # noqa: E731

    t = up.clamp(0.0, 1.0).sqrt()[..., None]
    sky = col(horizon_color) * (1 - t) + col(zenith_color) * t
    e, a = math.radians(sun_elevation_deg), math.radians(sun_azimuth_deg)
    sun_dir = torch.tensor([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)], dtype=torch.float64)
    gamma = torch.acos((d @ sun_dir).clamp(-1.0, 1.0))  # angle to the sun
    sky = sky + glow * col(horizon_color) * torch.exp(-gamma / math.radians(glow_width_deg))[..., None]

    below = ((-up) / math.sin(math.radians(1.0))).clamp(0.0, 1.0)
    blend = (below * below * (3 - 2 * below))[..., None]  # smoothstep
    env = sky * (1 - blend) + col(ground_color) * blend

    radius, texel = math.radians(sun_radius_deg), math.pi / (height - 1)
    coverage = ((radius - gamma) / texel + 0.5).clamp(0.0, 1.0)
    mu = torch.sqrt((1.0 - (gamma / radius).clamp(max=1.0) ** 2).clamp_min(0.0))
    limb = 1.0 - 0.6 * (1.0 - mu)
    env = env + sun_radiance * col(sun_color) * (coverage * limb)[..., None]
    return env.to(torch.float32).contiguous()
