"""Changes of variables that let a χ² histogram resolve narrow or grazing lobes.

A χ² test of a sampler may bin its samples in any chart y = W(ωo) of the sphere, provided
the density moves with them: p_y(y) = p(W⁻¹(y)) · dω/dω_y. The test stays a test of
`sample` against `pdf`; only the binning changes. Two charts are used:

- `HalfVectorChart`: y = h = (ωi + ωo)/|ωi + ωo|, the variable a microfacet sampler
  draws, with dω/dω_h = 4 (ωi·h) (for h·ωi > 0; other h have density 0). A reflected lobe
  at grazing ωi is 1/cos θi times thinner across the plane of incidence than along it
  (573× at 89.9°), and its pdf has a 1/|ωi + ωo| peak on the horizon; in h both are gone.
- `LobeZoom`: a rotation taking the lobe's centre c to +z, then a stereographic scaling
  by k about it, tan(θ'/2) = k tan(θ/2), a bijection of the sphere, with
  dω/dω_y = ((1 + t'²)/(k + t'²/k))², t' = tan(θ'/2). It spreads a lobe of width 1e-3 rad
  over thousands of cells instead of one. Both stereographic charts are used (from −z for
  the upper half, from +z for the lower), so nothing divides by a vanishing 1 ± z.
- `Equator`: a rotation that moves the lobe off the poles of Mitsuba's (φ, cos θ) cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, Sequence

import torch

Tensor = torch.Tensor


class Chart(Protocol):
    def forward(self, v: Tensor) -> Tensor: ...
    def inverse(self, y: Tensor) -> Tensor: ...
    def jacobian(self, y: Tensor) -> Tensor: ...
    def describe(self) -> str: ...


@dataclass(frozen=True)
class Identity:
    """y = ωo."""

    def forward(self, v):
        return v

    def inverse(self, y):
        return y

    def jacobian(self, y):
        return torch.ones(y.shape[0], dtype=y.dtype)

    def describe(self):
        return "ωo"


@dataclass(frozen=True)
class HalfVectorChart:
    """y = h = (ωi + ωo)/|ωi + ωo| for one ωi; inverse ωo = 2(ωi·h)h − ωi on h·ωi > 0."""

    wi: tuple[float, float, float]

    def _wi(self, like: Tensor) -> Tensor:
        return torch.tensor(self.wi, dtype=like.dtype)

    def forward(self, v):
        s = v + self._wi(v)
        n = s.norm(dim=-1, keepdim=True)
        # ωo = −ωi exactly has no half vector; it lies below the horizon (weight 0) anyway
        return torch.where(n > 0, s / n.clamp(min=torch.finfo(v.dtype).tiny), torch.tensor([0.0, 0.0, 1.0], dtype=v.dtype))

    def inverse(self, y):
        wi = self._wi(y)
        d = (y @ wi)[:, None]
        # h with h·ωi ≤ 0 is the image of no ωo: send it below the horizon, where pdf is 0
        wo = 2.0 * d * y - wi
        return torch.where(d > 0, wo, torch.tensor([0.0, 0.0, -1.0], dtype=y.dtype))

    def jacobian(self, y):
        return 4.0 * (y @ self._wi(y)).clamp(min=0.0)

    def describe(self):
        return "h"


@dataclass(frozen=True)
class Equator:
    """A rotation taking +z to +x: (x, y, z) ↦ (z, y, −x).

    Mitsuba's SphericalDomain bins (φ, cos θ), whose cells degenerate into thin wedges at
    its poles; a discontinuity passing within ~1e-3 rad of a pole (the horizon cut of a
    half-vector lobe at θi = 89.9° does) is then sampled by the integration points of a
    whole wedge. Lobe centres are moved to the equator, where cells are regular.
    """

    def forward(self, v):
        return torch.stack((v[:, 2], v[:, 1], -v[:, 0]), dim=-1)

    def inverse(self, y):
        return torch.stack((-y[:, 2], y[:, 1], y[:, 0]), dim=-1)

    def jacobian(self, y):
        return torch.ones(y.shape[0], dtype=y.dtype)

    def describe(self):
        return "on the equator"


@dataclass(frozen=True)
class LobeZoom:
    """Rotate `center` to +z, then scale stereographically by `k` (≥ 1)."""

    center: tuple[float, float, float]
    k: float

    def _frame(self, dtype) -> Tensor:
        """Rows (t, b, c): an orthonormal frame whose third axis is the centre."""
        c = torch.tensor(self.center, dtype=torch.float64)
        c = c / c.norm()
        e = torch.tensor([1.0, 0.0, 0.0] if abs(float(c[0])) < 0.9 else [0.0, 1.0, 0.0], dtype=torch.float64)
        t = e - (e @ c) * c
        t = t / t.norm()
        return torch.stack((t, torch.linalg.cross(c, t), c)).to(dtype)

    def forward(self, v):
        return _scale(v @ self._frame(v.dtype).T, self.k)

    def inverse(self, y):
        return _scale(y, 1.0 / self.k) @ self._frame(y.dtype)

    def jacobian(self, y):
        k = self.k
        z = y[:, 2]
        rho2 = y[:, 0] * y[:, 0] + y[:, 1] * y[:, 1]
        # upper half: t'² = ρ²/(1 + z)²; lower half: q = 1/t'² = ρ²/(1 − z)²
        t2 = rho2 / (1.0 + z.clamp(min=0.0)) ** 2
        q = rho2 / (1.0 - z.clamp(max=0.0)) ** 2
        j = torch.where(z >= 0, (1.0 + t2) / (k + t2 / k), (q + 1.0) / (k * q + 1.0 / k))
        return j * j

    def describe(self):
        return f"zoom k={self.k:.4g} about ({', '.join(f'{x:.4g}' for x in self.center)})"


def _scale(v: Tensor, k: float) -> Tensor:
    """Stereographic scaling about +z: tan(θ'/2) = k tan(θ/2), φ kept."""
    x, y, z = v.unbind(-1)
    upper = z >= 0
    # upper: P = (x, y)/(1 + z), |P| = tan(θ/2), P' = kP, v' = (2P', 1 − |P'|²)/(1 + |P'|²)
    # lower: Q = (x, y)/(1 − z), |Q| = cot(θ/2), Q' = Q/k, v' = (2Q', |Q'|² − 1)/(|Q'|² + 1)
    s = torch.where(upper, k / (1.0 + z.clamp(min=0.0)), 1.0 / (k * (1.0 - z.clamp(max=0.0))))
    a, b = s * x, s * y
    r2 = a * a + b * b
    z_new = torch.where(upper, (1.0 - r2) / (1.0 + r2), (r2 - 1.0) / (r2 + 1.0))
    return torch.stack((2.0 * a / (1.0 + r2), 2.0 * b / (1.0 + r2), z_new), dim=-1)


@dataclass(frozen=True)
class Composite:
    """y = second(first(ωo))."""

    first: Chart
    second: Chart

    def forward(self, v):
        return self.second.forward(self.first.forward(v))

    def inverse(self, y):
        return self.first.inverse(self.second.inverse(y))

    def jacobian(self, y):
        return self.second.jacobian(y) * self.first.jacobian(self.second.inverse(y))

    def describe(self):
        return f"{self.first.describe()}, {self.second.describe()}"


def lobe(points: Tensor) -> tuple[Tensor, float] | None:
    """(mean direction, median angle from it) of points (N, 3) on the sphere, or None."""
    if points.shape[0] == 0:
        return None
    points = points.to(torch.float64)
    mean = points.sum(0)
    if float(mean.norm()) == 0.0:
        return None
    c = mean / mean.norm()
    angle = torch.atan2(torch.linalg.cross(points, c.expand_as(points)).norm(dim=-1), points @ c)
    return c, float(angle.median())


@dataclass(frozen=True)
class ChartChoice:
    """The chart of one χ² test, the lobe's width in its base chart (rad), and how finely
    the sampler's dtype can place a sample there (rad: eps × the chart's magnification)."""

    chart: Chart
    width: float
    quantum: float

    @property
    def resolution(self) -> float:
        """quantum / width: the fraction of the lobe one representable step spans."""
        return self.quantum / self.width if self.width > 0 else math.inf


def chart_for(
    tags, wi: Sequence[float], pilot_wo: Tensor, dtype: torch.dtype = torch.float64, *, widest: float = 0.35, target: float = 1.0
) -> ChartChoice:
    """The chart a χ² test of a sampler with these tags uses at ωi, from pilot samples above the horizon.

    Half vectors for `microfacet` samplers, ωo otherwise. A lobe narrower than `widest`
    radians (median angle from the pilots' mean direction, w) is zoomed by k = target / w
    (its median angle then maps to about 2·atan(target/2) ≈ 53°). Anything but plain ωo is
    moved to the equator. The quantum is eps(dtype) for ωo, and eps(dtype)/|ωi + ωo| (the
    median over the pilots) for h, whose map from ωo magnifies by 1/|ωi + ωo|: 286× at
    θi = 89.9°.
    """
    eps = torch.finfo(dtype).eps
    pilot_wo = pilot_wo.to(torch.float64)
    if "microfacet" in tags:
        base: Chart = HalfVectorChart(tuple(float(x) for x in wi))
        s = torch.linalg.vector_norm(pilot_wo + torch.tensor(list(wi), dtype=torch.float64), dim=-1)
        quantum = eps / float(s.median()) if s.numel() else math.inf
    else:
        base, quantum = Identity(), eps
    found = lobe(base.forward(pilot_wo))
    if found is None:
        return ChartChoice(base, math.inf, quantum)
    c, w = found
    if not math.isfinite(w) or w >= widest:
        chart = Composite(base, Equator()) if isinstance(base, HalfVectorChart) else base
        return ChartChoice(chart, w, quantum)
    zoom = LobeZoom(center=tuple(float(x) for x in c), k=target / max(w, 1e-12))
    return ChartChoice(Composite(Composite(base, zoom), Equator()), w, quantum)
