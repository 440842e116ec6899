"""Per-material drill-down of a table section: which materials are hard, for whom, and why.

A section's ranking metric for every (material, configuration), with each material's
difficulty: its mean percentile rank among the section's materials over the ranked
configurations (0 the easiest for every model, 1 the hardest for every model). Ranks,
not figures, so that no single model's scale dominates and the direction of the metric
does not matter. The hardest materials are then named by category, and the difficulty is
set against the sharpness of the target's specular lobe (Spearman's rank correlation with
its half-width, and its two-sided p-value), since sharp highlights are where compact
representations are expected to fail.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .view import Metric, Row, TableSection

#: How many of the hardest materials a summary names.
HARDEST = 3
#: Significance level at which the lobe-sharpness correlation is called a trend.
ALPHA = 0.05


@dataclass(frozen=True)
class CategoryDifficulty:
    name: str
    materials: int
    difficulty: float  # the mean difficulty of its materials


@dataclass(frozen=True)
class Sharpness:
    rho: float  # Spearman's rank correlation of lobe half-width with difficulty
    p: float  # two-sided p-value of rho = 0
    materials: int


@dataclass(frozen=True)
class Drilldown:
    metric: Metric
    configs: list[Row]  # the columns: ranked and incomplete configurations, references last
    materials: list[str]  # the rows: hardest first
    values: dict[tuple[str, str], float]  # (config hash, material) → figure
    difficulty: dict[str, float]  # material → mean percentile rank (0 easiest … 1 hardest)
    categories: dict[str, str]  # material → category ("" where unknown)
    widths: dict[str, float]  # material → lobe half-width (rad), where recorded
    by_category: list[CategoryDifficulty]  # hardest first; empty with fewer than two categories
    sharpness: Sharpness | None  # None without a width for at least four materials

    @property
    def hardest(self) -> list[str]:
        return self.materials[:HARDEST]


def _percentile_ranks(values: dict[str, float], higher_is_better: bool) -> dict[str, float]:
    """Material → its rank among `values` scaled to [0, 1] (1 the worst), ties averaged."""
    names = sorted(values)
    if len(names) < 2:
        return {n: 0.5 for n in names}
    x = np.array([values[n] for n in names], dtype=float)
    x = -x if higher_is_better else x
    from scipy.stats import rankdata

    ranks = (rankdata(x) - 1) / (len(names) - 1)
    return dict(zip(names, ranks.tolist()))


def build(section: TableSection) -> Drilldown | None:
    """The drill-down of a section's ranking metric, or None with fewer than two materials
    or no ranked configuration with figures."""
    metric = section.primary
    if metric is None or len(section.materials) < 2:
        return None
    values = section.per_material.get(metric.name, {})
    ranked = [r for r in section.rows if not r.reference and any((r.config_hash, m) in values for m in section.materials)]
    if not ranked:
        return None
    scores: dict[str, list[float]] = {m: [] for m in section.materials}
    for row in ranked:
        mine = {m: values[(row.config_hash, m)] for m in section.materials if (row.config_hash, m) in values}
        for m, q in _percentile_ranks(mine, metric.higher_is_better).items():
            scores[m].append(q)
    difficulty = {m: float(np.mean(q)) for m, q in scores.items() if q}
    materials = sorted(difficulty, key=lambda m: (-difficulty[m], m))
    categories = {m: section.material_categories.get(m, "") for m in materials}
    references = [r for r in section.rows if r.reference and any((r.config_hash, m) in values for m in materials)]
    return Drilldown(metric, ranked + references, materials, values, difficulty, categories,
                     {m: section.lobe_widths[m] for m in materials if m in section.lobe_widths},
                     _by_category(difficulty, categories), _sharpness(difficulty, section.lobe_widths))


def _by_category(difficulty: dict[str, float], categories: dict[str, str]) -> list[CategoryDifficulty]:
    groups: dict[str, list[float]] = {}
    for m, d in difficulty.items():
        if categories.get(m):
            groups.setdefault(categories[m], []).append(d)
    if len(groups) < 2:
        return []
    out = [CategoryDifficulty(name, len(v), float(np.mean(v))) for name, v in groups.items()]
    return sorted(out, key=lambda c: (-c.difficulty, c.name))


def _sharpness(difficulty: dict[str, float], widths: dict[str, float]) -> Sharpness | None:
    names = [m for m in difficulty if m in widths]
    if len(names) < 4:
        return None
    from scipy.stats import spearmanr

    w = np.array([widths[m] for m in names])
    d = np.array([difficulty[m] for m in names])
    if np.all(w == w[0]) or np.all(d == d[0]):
        return None
    rho, p = spearmanr(w, d)
    return Sharpness(float(rho), float(p), len(names))


def summary(d: Drilldown) -> str:
    """One paragraph a reader can act on: the hardest materials, categories and the lobe trend."""
    def named(m: str) -> str:
        extra = [x for x in (d.categories.get(m), f"lobe half-width {d.widths[m]:.3g} rad" if m in d.widths else "") if x]
        return f"{m} ({', '.join(extra)})" if extra else m

    parts = [f"Hardest for the ranked configurations (mean percentile rank of {d.metric.name} among the "
             f"{len(d.materials)} materials): " + "; ".join(named(m) for m in d.hardest) + "."]
    if d.by_category:
        parts.append("By category, hardest first: " + ", ".join(
            f"{c.name} {c.difficulty:.2f} ({c.materials})" for c in d.by_category) + ".")
    if d.sharpness is not None:
        s = d.sharpness
        if s.p < ALPHA:
            trend = "sharper lobes are harder" if s.rho < 0 else "wider lobes are harder"
        else:
            trend = f"no trend at the {ALPHA:g} level"
        parts.append(f"Against the target's lobe half-width: Spearman ρ = {s.rho:+.2f}, p = {s.p:.2g} over "
                     f"{s.materials} materials ({trend}).")
    return " ".join(parts)
