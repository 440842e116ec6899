"""Material categories of constrained synthesis (Zhou et al., Sec. 4.5, C.3, F.1; Hu 2026, § 3.6).

A generation benchmark draws materials unconditionally and filters them into seven
categories by BRDF statistics over the MERL grid: diffuse, metallic, low-, mid- and
high-specular, plastic and mirror. A material may fall into several (a sharp white lobe
over a coloured base is high-specular, plastic and mirror) or none.

Where the statistics come from: the 90×90×180 cells of the MERL grid, of which 1,096,216
have both cell-centre directions above the horizon. Only those count, and for a table only
its valid ones (negative = invalid); a representation is evaluated (fp64) at the same cell
centres, where a negative value also counts as invalid, as in MERL (a fitted `merl`
representation reads an invalid cell as 0, which does count: only the mean and the
metallic test can tell it from its table). ‖f‖∞ is the largest of the three channels at
a cell. The rules, with `Thresholds` t and `MaterialStats` s:

- diffuse: fewer than t.exceptions (e = 8×10⁴) counted cells have ‖f‖∞ > f_diffuse. Below-
  horizon and invalid cells never exceed, so this is also the count over the whole grid.
- metallic: every counted cell has ‖f‖∞ > f_diffuse (no exception allowed, as C.3 states).
- low/mid/high-specular: the material's maximum reflectance m (max over cells of ‖f‖∞, or
  of one channel, `Thresholds.channel`) in [f_diffuse, f1), [f1, f2), [f2, ∞).
- plastic: the specular part is white: on every cell with ‖f‖∞ > f_diffuse, every pair of
  channels differs by less than δ = 5 % of max ‖f‖∞. The material must also have both a
  specular part (some cell exceeds) and a diffuse part (not every cell exceeds), as
  Hu 2026 defines plastic; otherwise a Lambertian surface would pass vacuously.
- mirror: lobe half-width w < 0.349 rad (see `lobe_half_width`), and the lobe's peak
  ‖f(0, 0, 0)‖∞ above f_diffuse: the rule measures a specular lobe, and a row that never
  leaves the diffuse range has none (without this, a dark felt whose diffuse row halves
  by θh = 0.25 would be a mirror).
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass
from functools import lru_cache
from typing import Iterable

import numpy as np
import torch

from .. import coords, merl
from ..harness.lobes import lobe_half_width, peak_row, theta_h_centres
from ..merl import MerlTable
from ..protocols.representation import Material, Representation

#: The seven categories, in Zhou et al.'s order.
CATEGORIES = ("diffuse", "metallic", "low-specular", "mid-specular", "high-specular", "plastic", "mirror")

#: Energy conservation bound of a constant BRDF (Zhou et al., eqs. 7–9), in 1/sr.
F_DIFFUSE = 1.0 / math.pi
#: The practical threshold of Hu 2026 for MERL data ("for MERL dataset, the threshold is 1").
F_DIFFUSE_HU2026 = 1.0
#: e: how many cells a diffuse material may have above f_diffuse (Zhou et al., eq. 24).
EXCEPTIONS = 80_000
#: δ_plastic as a fraction of the maximum reflectance (Zhou et al., C.3).
PLASTIC_TOLERANCE = 0.05
#: w_mirror, radians (Zhou et al., C.3; Hu 2026, § 3.6).
MIRROR_WIDTH = 0.349
#: Zhou et al.'s specular thresholds f1, f2 (1/sr).
PUBLISHED_SPECULAR = (100.0, 600.0)
#: Clusters of maximum reflectance: low, mid and high specular.
N_CLUSTERS = 3
#: Smallest reference set clustered: two members per cluster, else the published thresholds.
MIN_KMEANS_MEMBERS = 2 * N_CLUSTERS
#: Statistic the specular ranges use: "max" is ‖f‖∞, the others one channel.
CHANNELS = {"max": None, "red": 0, "green": 1, "blue": 2}
#: Direction pairs per representation evaluation (bounds memory: ~40 MB of fp64 temporaries).
CHUNK = 1 << 17


# --------------------------------------------------------------------------- thresholds


@dataclass(frozen=True)
class Thresholds:
    """Every constant the rules use; `source` says where f1 and f2 came from.

    `centres` are the sorted K-means cluster centres (empty for published values).
    """

    f_diffuse: float = F_DIFFUSE
    f_specular1: float = PUBLISHED_SPECULAR[0]
    f_specular2: float = PUBLISHED_SPECULAR[1]
    channel: str = "max"
    exceptions: int = EXCEPTIONS
    plastic_tolerance: float = PLASTIC_TOLERANCE
    mirror_width: float = MIRROR_WIDTH
    source: str = "published (Zhou et al., C.3)"
    centres: tuple[float, ...] = ()

    def __post_init__(self):
        for name in ("f_diffuse", "f_specular1", "f_specular2", "plastic_tolerance", "mirror_width"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, numbers.Real) and math.isfinite(value) and value > 0):
                raise ValueError(f"threshold {name} must be a finite positive number, got {value!r}")
        if not self.f_specular1 < self.f_specular2:
            raise ValueError(f"f_specular1 ({self.f_specular1}) must be below f_specular2 ({self.f_specular2})")
        if self.channel not in CHANNELS:
            raise ValueError(f"unknown channel {self.channel!r}; expected one of {', '.join(CHANNELS)}")
        if isinstance(self.exceptions, bool) or not isinstance(self.exceptions, numbers.Integral) or self.exceptions < 0:
            raise ValueError(f"exceptions must be a non-negative integer, got {self.exceptions!r}")


#: Zhou et al.'s thresholds: f_diffuse = 1/π, f1 = 100, f2 = 600 (its Fig. 21 clustered the red
#: channel; here they apply to ‖f‖∞, which is the same for a white specular lobe).
PUBLISHED = Thresholds()


def kmeans_boundaries(values, n_clusters: int = N_CLUSTERS, *, random_state: int = 0,
                      n_init: int = 10) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(boundaries, centres) of 1-D K-means on `values` (scikit-learn, deterministic).

    Boundaries are the midpoints between adjacent sorted centres: K-means' own decision
    boundary (each value belongs to its nearest centre), so a reference member falls on
    its own cluster's side, and a new value in a gap goes to the nearer cluster.
    """
    from sklearn.cluster import KMeans

    x = np.asarray(values, dtype=np.float64).reshape(-1)
    if not np.isfinite(x).all():
        raise ValueError(f"K-means values must be finite, got {x[~np.isfinite(x)][0]} at index "
                         f"{int(np.flatnonzero(~np.isfinite(x))[0])}")
    if np.unique(x).size < n_clusters:
        raise ValueError(f"K-means with {n_clusters} clusters needs at least {n_clusters} distinct values, "
                         f"got {np.unique(x).size}")
    km = KMeans(n_clusters=n_clusters, n_init=n_init, random_state=random_state).fit(x[:, None])
    centres = np.sort(km.cluster_centers_.reshape(-1))
    boundaries = (centres[:-1] + centres[1:]) / 2
    return tuple(float(b) for b in boundaries), tuple(float(c) for c in centres)


def thresholds(reference_members: Iterable, *, f_diffuse: float = F_DIFFUSE, channel: str = "max",
               random_state: int = 0) -> Thresholds:
    """Thresholds from a reference set (tables, Materials or fitted representations).

    f_diffuse is not learned: it is the energy conservation bound. A constant BRDF f in a
    channel reflects ∫ f cos θo dωo = π f of unit incident irradiance, which passivity
    caps at 1, so f ≤ 1/π: a Lambertian surface of albedo ρ ≤ 1 has f = ρ/π ≤ 1/π, and
    more than that in a cell is specular. Zhou et al. use 1/π; Hu 2026 derives the same
    but applies 1 to MERL data ("it could be pre-multiplied by π"); brdfbench's MERL
    values are in 1/sr, not pre-multiplied, so 1/π is the default and
    `F_DIFFUSE_HU2026` is there to reproduce Hu 2026.

    f1 < f2 are the boundaries of 3-means (low, mid, high), in linear units as Fig. 21,
    on each member's maximum reflectance: ‖f‖∞ by default, which an RGB permutation (how
    Zhou et al. augment MERL) leaves unchanged; channel="red" reproduces Fig. 21, which
    clusters the red channel. The rules then compare the same statistic. A set of fewer
    than `MIN_KMEANS_MEMBERS` members or 3 distinct maxima gets the published f1, f2
    with a warning, and `source` says so.
    """
    Thresholds(f_diffuse=f_diffuse, channel=channel)  # validates both before any work
    maxima = [statistics(m, f_diffuse, index=i).max_of(channel) for i, m in enumerate(reference_members)]
    if not maxima:
        raise ValueError("reference set is empty: thresholds need at least one reference member")
    n = len(maxima)
    if n < MIN_KMEANS_MEMBERS or np.unique(maxima).size < N_CLUSTERS:
        reason = (f"reference set of {n} members ({np.unique(maxima).size} distinct maxima) is too small for "
                  f"{N_CLUSTERS}-means (needs {MIN_KMEANS_MEMBERS} members, {N_CLUSTERS} distinct)")
        warnings.warn(f"{reason}: using the published specular thresholds {PUBLISHED_SPECULAR}", stacklevel=2)
        return Thresholds(f_diffuse=f_diffuse, channel=channel, source=f"published (Zhou et al., C.3): {reason}")
    (f1, f2), centres = kmeans_boundaries(maxima, random_state=random_state)
    if f1 <= f_diffuse:
        warnings.warn(f"K-means boundary f1 = {f1:.4g} is not above f_diffuse = {f_diffuse:.4g}: "
                      "no material can be low-specular", stacklevel=2)
    return Thresholds(f_diffuse=f_diffuse, f_specular1=f1, f_specular2=f2, channel=channel,
                      source=f"K-means (k={N_CLUSTERS}, midpoints) on the {channel} maximum reflectance "
                             f"of {n} reference members",
                      centres=centres)


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class MaterialStats:
    """Statistics of one material over the counted cells (valid, above the horizon), 1/sr.

    `n_exceeding` and `specular_spread` are taken at `f_diffuse`: the cells with
    ‖f‖∞ > f_diffuse, and the largest max-minus-min channel difference among them
    (0 when none). `half_width` in radians (see `lobe_half_width`), of the lobe whose
    peak ‖f(θh = 0, θd = 0, φd = 0)‖∞ is `lobe_peak` (NaN when that row has no valid cell).
    """

    max: tuple[float, float, float]
    mean: tuple[float, float, float]
    n_cells: int
    f_diffuse: float
    n_exceeding: int
    min_norm: float
    specular_spread: float
    half_width: float
    lobe_peak: float

    @property
    def max_norm(self) -> float:
        """The maximum reflectance: max over cells of ‖f‖∞."""
        return max(self.max)

    @property
    def all_exceed(self) -> bool:
        """Every counted cell has ‖f‖∞ > f_diffuse."""
        return self.min_norm > self.f_diffuse

    def max_of(self, channel: str) -> float:
        """Maximum reflectance of one channel ("red", "green", "blue") or of ‖f‖∞ ("max")."""
        if channel not in CHANNELS:
            raise ValueError(f"unknown channel {channel!r}; expected one of {', '.join(CHANNELS)}")
        c = CHANNELS[channel]
        return self.max_norm if c is None else self.max[c]


class _Accumulator:
    """Running per-channel max and sum, and the f_diffuse counts, over chunks of cells."""

    def __init__(self, f_diffuse: float):
        self.f_diffuse = f_diffuse
        self.max = np.full(3, -np.inf)
        self.sum = np.zeros(3)
        self.n = 0
        self.n_exceeding = 0
        self.min_norm = np.inf
        self.spread = 0.0

    def update(self, v: np.ndarray) -> None:
        """Add counted cells v (n, 3)."""
        if v.shape[0] == 0:
            return
        norm = v.max(axis=1)
        self.max = np.maximum(self.max, v.max(axis=0))
        self.sum += v.sum(axis=0)
        self.n += v.shape[0]
        self.min_norm = min(self.min_norm, float(norm.min()))
        spec = v[norm > self.f_diffuse]
        self.n_exceeding += spec.shape[0]
        if spec.shape[0]:
            self.spread = max(self.spread, float((spec.max(axis=1) - spec.min(axis=1)).max()))


def _label(index: int | None) -> str:
    return "member" if index is None else f"member {index}"


@lru_cache(maxsize=1)
def _counted_grid_cells() -> torch.Tensor:
    """Flat indices of the grid cells whose two centre directions are above the horizon."""
    return torch.from_numpy(np.flatnonzero(merl.grid_above_horizon().numpy()))


def _table_stats(table: MerlTable, acc: _Accumulator, label: str) -> np.ndarray:
    """Feed a table's counted cells to acc; return its θd = φd = 0 row (90, 3), NaN where invalid."""
    if not np.isfinite(table.raw).all():
        c, i, j, k = (int(x) for x in np.argwhere(~np.isfinite(table.raw))[0])
        raise ValueError(f"{label}: non-finite table value at channel {c}, cell ({i}, {j}, {k})")
    counted = (table.valid.reshape(-1) & merl.grid_above_horizon().numpy())
    acc.update(table.values.reshape(3, -1)[:, counted].T)
    return peak_row(table)


def _eval(rep: Representation, wi: torch.Tensor, wo: torch.Tensor, label: str) -> np.ndarray:
    """fp64 values (n, 3); non-finite ones raise, negative ones become NaN (invalid)."""
    v = rep.eval(wi, wo).detach().to("cpu", torch.float64).numpy()
    if v.shape != (wi.shape[0], 3):
        raise ValueError(f"{label}: eval returned shape {v.shape}, expected ({wi.shape[0]}, 3)")
    if not np.isfinite(v).all():
        raise ValueError(f"{label}: non-finite value {v[~np.isfinite(v)][0]} at "
                         f"{int(np.argwhere(~np.isfinite(v))[0, 0])} of {wi.shape[0]} directions")
    return np.where((v >= 0).all(axis=1, keepdims=True), v, np.nan)


def _representation_stats(rep: Representation, acc: _Accumulator, label: str) -> np.ndarray:
    """Feed a representation's values at the counted cell centres to acc, in chunks;
    return its values on the θd = φd = 0 row (90, 3), NaN where negative."""
    wi, wo = merl.grid_directions(torch.float64)
    cells = _counted_grid_cells()
    with torch.no_grad():
        for start in range(0, cells.shape[0], CHUNK):
            idx = cells[start:start + CHUNK]
            v = _eval(rep, wi[idx], wo[idx], label)
            acc.update(v[~np.isnan(v).any(axis=1)])
        theta_h = torch.from_numpy(theta_h_centres())
        td = torch.full_like(theta_h, (0.5 / merl.RES_THETA_D) * (math.pi / 2))
        pd = torch.full_like(theta_h, (0.5 / merl.RES_PHI_D) * math.pi)
        row_wi, row_wo = coords.from_half_diff(theta_h, torch.zeros_like(theta_h), td, pd)
        return _eval(rep, row_wi, row_wo, label)


def statistics(member, f_diffuse: float = F_DIFFUSE, *, index: int | None = None) -> MaterialStats:
    """Statistics of one member: a MerlTable, a Material (its table) or a fitted
    Representation. `index` names the member in errors."""
    label = _label(index)
    acc = _Accumulator(f_diffuse)
    if isinstance(member, Material):
        member = member.table
    if isinstance(member, MerlTable):
        row = _table_stats(member, acc, label)
    elif isinstance(member, Representation):
        row = _representation_stats(member, acc, label)
    else:
        raise TypeError(f"{label}: expected a MerlTable, Material or Representation, got {type(member).__name__}")
    if acc.n == 0:
        raise ValueError(f"{label}: no valid cell above the horizon")
    norm = np.max(row, axis=1)
    valid_row = norm[~np.isnan(norm)]
    return MaterialStats(
        max=tuple(float(x) for x in acc.max), mean=tuple(float(x) for x in acc.sum / acc.n), n_cells=acc.n,
        f_diffuse=f_diffuse, n_exceeding=acc.n_exceeding, min_norm=acc.min_norm,
        specular_spread=acc.spread, half_width=lobe_half_width(theta_h_centres(), norm),
        lobe_peak=float(valid_row[0]) if valid_row.size else math.nan,
    )


# --------------------------------------------------------------------------- rules


def classify(stats: MaterialStats, t: Thresholds = PUBLISHED) -> frozenset[str]:
    """The categories whose rules `stats` satisfy (see the module docstring)."""
    if stats.f_diffuse != t.f_diffuse:
        raise ValueError(f"statistics were taken at f_diffuse = {stats.f_diffuse}, thresholds use {t.f_diffuse}")
    found = set()
    if stats.n_exceeding < t.exceptions:
        found.add("diffuse")
    if stats.all_exceed:
        found.add("metallic")
    m = stats.max_of(t.channel)
    if m >= t.f_diffuse:
        found.add("low-specular" if m < t.f_specular1 else "mid-specular" if m < t.f_specular2 else "high-specular")
    if (stats.n_exceeding > 0 and not stats.all_exceed
            and stats.specular_spread < t.plastic_tolerance * stats.max_norm):
        found.add("plastic")
    if stats.half_width < t.mirror_width and stats.lobe_peak > t.f_diffuse:
        found.add("mirror")
    return frozenset(found)


def categories(member, thresholds: Thresholds = PUBLISHED, *, index: int | None = None) -> frozenset[str]:
    """The categories of one member (MerlTable, Material or fitted Representation)."""
    return classify(statistics(member, thresholds.f_diffuse, index=index), thresholds)


def count_categories(members: Iterable, thresholds: Thresholds = PUBLISHED) -> dict[str, int]:
    """How many members fall in each of the seven categories (zeros included), one at a time."""
    counts = dict.fromkeys(CATEGORIES, 0)
    for i, member in enumerate(members):
        for name in categories(member, thresholds, index=i):
            counts[name] += 1
    return counts
