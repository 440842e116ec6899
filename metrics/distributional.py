"""Distributional metrics of a synthesized set S against a reference set R, from distances
(Zhou et al., eqs. 3–5, after the point-cloud metrics of Achlioptas et al. 2018 and Yang et
al. 2019):

- MMD (minimum matching distance): the mean over R of the distance to the nearest member
  of S (lower is better: fidelity);
- COV (coverage): the share of R that is the nearest member of R to at least one member of
  S (higher is better: diversity);
- 1-NNA: the leave-one-out accuracy of a 1-nearest-neighbour classifier telling R from S
  over R ∪ S (50 % is ideal, 100 % means the sets are told apart every time; lower is
  better down to 50 %, so it is reported with `higher_is_better = False`).

Inputs are distance matrices: `d_rs` (|R|, |S|), and for 1-NNA also `d_rr` (|R|, |R|) and
`d_ss` (|S|, |S|). Ties go to the lowest index, and in 1-NNA to R before S (the order of
R ∪ S), so a sample identical to a reference member is classified as R's: a set scored
against itself gets 1-NNA 0 %, not 50 % (the paper's training-set row scores a training
subset, distinct from the reference). Non-finite distances are refused: a sample whose
distances are not finite must be excluded and counted by the caller, never ranked.

Intervals: `draw_interval` over independent sample draws of a generator (the variability
of the sample draw; every metric here depends on the number of distinct samples, so
resampling one draw with replacement would bias them all), and `reference_bootstrap` over
the reference members for MMD and COV (means over R of a per-member figure given S).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _matrix(d, name: str, shape: tuple[int | None, int | None] = (None, None)) -> np.ndarray:
    a = np.asarray(d.detach().cpu().numpy() if hasattr(d, "detach") else d, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D distance matrix, got shape {a.shape}")
    for axis, want in enumerate(shape):
        if want is not None and a.shape[axis] != want:
            raise ValueError(f"{name} has shape {a.shape}: axis {axis} must be {want}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"{name} is empty (shape {a.shape}): both sets need at least one member")
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{name} has a non-finite distance at {tuple(int(i) for i in bad)}: exclude that sample "
                         "(and count it) before scoring the set")
    return a


def mmd(d_rs) -> float:
    """Mean over the reference members (rows) of the distance to the nearest sample (columns)."""
    d = _matrix(d_rs, "d_rs")
    return float(d.min(axis=1).mean())


def cov(d_rs) -> float:
    """Share of reference members (rows) that are the nearest reference member of some sample."""
    d = _matrix(d_rs, "d_rs")
    return float(np.unique(d.argmin(axis=0)).size / d.shape[0])


def one_nna(d_rr, d_ss, d_rs) -> float:
    """Leave-one-out 1-NN accuracy over R ∪ S, each member labelled by its nearest neighbour's set."""
    rs = _matrix(d_rs, "d_rs")
    nr, ns = rs.shape
    if nr + ns < 2:
        raise ValueError("1-NNA needs at least two members in R ∪ S")
    full = np.block([[_matrix(d_rr, "d_rr", (nr, nr)), rs], [rs.T, _matrix(d_ss, "d_ss", (ns, ns))]])
    np.fill_diagonal(full, np.inf)
    nearest = full.argmin(axis=1)  # the first of equal distances: R before S
    is_s = np.arange(nr + ns) >= nr
    return float((is_s[nearest] == is_s).mean())


@dataclass(frozen=True)
class Interval:
    """A figure with a confidence interval, and how the interval was made."""

    value: float
    lo: float
    hi: float
    level: float
    method: str  # "reference bootstrap (n resamples)" or "t over k sample draws"


def reference_bootstrap(metric: str, d_rs, *, n_boot: int = 1000, level: float = 0.95, seed: int = 0) -> Interval:
    """MMD or COV with a percentile interval over the reference draw: both are means over the
    reference members of a per-member figure given S (distance to the nearest sample; covered
    or not), so resampling the rows with replacement is a sound bootstrap. Seeded: one store
    gives one report."""
    if n_boot < 1:
        raise ValueError(f"n_boot must be at least 1, got {n_boot}")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    rs = _matrix(d_rs, "d_rs")
    nr = rs.shape[0]
    if metric == "mmd":
        per_member = rs.min(axis=1)
    elif metric == "cov":
        per_member = np.zeros(nr)
        per_member[np.unique(rs.argmin(axis=0))] = 1.0
    elif metric == "1nna":
        raise ValueError("1-NNA is not a mean over the reference members: resampling either set changes its "
                         "neighbour structure; give it an interval over independent sample draws (draw_interval)")
    else:
        raise ValueError(f"unknown distributional metric {metric!r}: one of 'mmd', 'cov', '1nna'")
    rng = np.random.default_rng(seed)
    draws = per_member[rng.integers(0, nr, (n_boot, nr))].mean(axis=1)
    tail = (1 - level) / 2
    return Interval(float(per_member.mean()), float(np.quantile(draws, tail)), float(np.quantile(draws, 1 - tail)),
                    level, f"reference bootstrap ({n_boot} resamples)")


def draw_interval(figures, level: float = 0.95) -> Interval:
    """A figure's mean over k ≥ 2 independent sample draws of a generator (each scored
    against the same reference) with a Student-t interval: the variability of the sample
    draw itself. Resampling one draw with replacement would not do: every metric here
    depends on how many distinct samples there are, which resampling cuts to about 63 %."""
    x = np.asarray(figures, dtype=np.float64).reshape(-1)
    if x.size < 2:
        raise ValueError(f"an interval over sample draws needs at least 2 draws, got {x.size}")
    if not np.isfinite(x).all():
        raise ValueError("a draw's figure is not finite")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    from scipy import stats

    mean, sem = float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size))
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1)) * sem
    return Interval(mean, mean - half, mean + half, level, f"t over {x.size} sample draws")


#: Name → (unit, higher_is_better) of the metrics above, as stored with their rows.
DECLARED = {"mmd": ("distance", False), "cov": ("fraction", True), "1nna": ("fraction (ideal 0.5)", False)}
