"""The source papers' published figures beside ours for the same model and metric.

`data/seed_figures.csv` holds every table of the four source papers as printed (with
their sources); `data/published_matches.csv` says which of those rows measure what one of
our metrics measures: our representation, metric and scene ("*": any rendered scene), the
factor from the paper's unit to ours, and how the setups differ. Each match is compared
with every report section that has our figure; a figure within a factor of two of the
published one (for dB: within 3 dB; for SSIM: 1 − SSIM within a factor of two) is said to
agree, any other is said not to reproduce, and a match with no figure of ours is listed
as not measured.

The data key each row by an internal label of its paper; what a report shows is the
paper's citation (`brdfbench.citations`, `citation` here), e.g. "Sztrajman et al. 2021,
Table 2".
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from importlib import resources

from brdfbench import citations

from .view import Cell, Report, TableSection

AGREEMENT_FACTOR = 2.0
#: Configurations (conf/) that train on a source paper's own recipe rather than this
#: project's CPU schedule: the report says which produced each of our figures.
PUBLISHED_RECIPES = ("nbrdf_reference", "triplane_gated_paper", "tripleplane_paper", "hyperdiffusion_paper")
FIGURES_FILE = "seed_figures.csv"
MATCHES_FILE = "published_matches.csv"


@dataclass(frozen=True)
class Published:
    source: str
    table: str
    model: str
    metric: str
    value: float
    std: float | None
    unit: str
    note: str


@dataclass(frozen=True)
class Match:
    seed: str
    table: str
    model: str
    metric: str
    representation: str
    our_metric: str
    scene: str
    scale: float
    setup: str


@dataclass(frozen=True)
class Comparison:
    match: Match
    published: Published | None  # None: the match names a row the figures file lacks
    section: TableSection | None  # None: not measured in this store
    ours: Cell | None
    verdict: str  # "agrees" | "does not reproduce" | "not measured" | "published figure missing" | "incomplete"
    detail: str

    @property
    def theirs(self) -> float | None:
        """The published figure in our metric's unit."""
        return None if self.published is None else self.published.value * self.match.scale


def _rows(name: str) -> list[dict[str, str]]:
    text = resources.files("brdfbench_leaderboard").joinpath("data", name).read_text(encoding="utf-8")
    return list(csv.DictReader(text.splitlines()))


#: Where in its paper a figure is printed: "Table 4.1 image quality ..." → ("Table 4.1", "image
#: quality ..."); "section 3.1" and "text 4.3.2.2 efficiency" → "§3.1", "§4.3.2.2".
_WHERE = re.compile(r"(Table|Figure|section|text)\s+(\d+(?:\.\d+)*)\s*(.*)", re.DOTALL)


def citation(source: str, table: str) -> tuple[str, str]:
    """(where, what): a figure's source and table as a report shows them: the paper's citation
    and the place in it ("Sztrajman et al. 2021, Table 2"), and the table's description
    (any internal label in it cited too)."""
    m = _WHERE.fullmatch(table.strip())
    if m is None:
        return citations.source(source), citations.cite(table)
    kind, number, rest = m.groups()
    place = f"§{number}" if kind in ("section", "text") else f"{kind} {number}"
    return f"{citations.source(source)}, {place}", citations.cite(rest)


def _float(text: str | None) -> float | None:
    try:
        value = float(text) if text not in (None, "") else None
    except ValueError:
        return None
    return value if value is None or math.isfinite(value) else None


def figures() -> list[Published]:
    """The numeric published figures (a range printed as text, e.g. "10 to 180", is left out)."""
    out = []
    for r in _rows(FIGURES_FILE):
        value = _float(r.get("value"))
        if value is None:
            continue
        out.append(Published(r["source"], r["table"], r["model"], r["metric"], value, _float(r.get("std")),
                             r.get("unit") or "", r.get("note") or ""))
    return out


def matches() -> list[Match]:
    return [Match(r["seed"], r["table"], r["model"], r["metric"], r["representation"], r["our_metric"], r["scene"],
                  float(r["scale"]), r["setup"]) for r in _rows(MATCHES_FILE)]


def _find(match: Match, published: list[Published]) -> Published | None:
    for p in published:
        if (p.source.startswith(match.seed + " ") and (p.table == match.table or p.table.startswith(match.table + " "))
                and p.model == match.model and p.metric == match.metric):
            return p
    return None


def agreement(ours: float, theirs: float, metric: str, unit: str) -> tuple[bool, str]:
    """Whether two figures agree within the stated factor, and the comparison in words."""
    if unit == "dB":
        diff = ours - theirs
        return abs(diff) <= 10 * math.log10(AGREEMENT_FACTOR), f"ours {diff:+.3g} dB"
    if metric.startswith("ssim"):
        a, b = 1 - ours, 1 - theirs
        if b <= 0:
            return a <= 0, "1 − SSIM: theirs 0"
        return 1 / AGREEMENT_FACTOR <= a / b <= AGREEMENT_FACTOR, f"1 − SSIM: ours {a / b:.3g}× theirs"
    if theirs == 0:
        return ours == 0, "theirs 0"
    ratio = ours / theirs
    return 1 / AGREEMENT_FACTOR <= ratio <= AGREEMENT_FACTOR, f"ours {ratio:.3g}× theirs"


def compare(report: Report) -> list[Comparison]:
    """Every match against every table section with our figure for it (else one row saying so)."""
    published = figures()
    tables_ = [s for s in report.sections if isinstance(s, TableSection)]
    out = []
    for m in matches():
        p = _find(m, published)
        if p is None:
            out.append(Comparison(m, None, None, None, "published figure missing",
                                  f"{citation(m.seed, m.table)[0]}: no row for {m.model} / {m.metric} in {FIGURES_FILE}"))
            continue
        found = False
        for s in tables_:
            if m.scene == "*" and s.scene == "brdf_space" or m.scene not in ("*", s.scene):
                continue
            for row in s.rows:
                if row.plugin != m.representation and row.label != m.representation:
                    continue
                cell = row.cell(m.our_metric)
                if cell is None:
                    continue
                found = True
                if not cell.complete:
                    out.append(Comparison(m, p, s, cell, "incomplete", f"{cell.missing} of {cell.expected} materials "
                                          "missing: no mean to compare"))
                    continue
                metric = s.metrics[m.our_metric]
                ok, words = agreement(cell.value, p.value * m.scale, m.our_metric, metric.unit)
                out.append(Comparison(m, p, s, cell, "agrees" if ok else "does not reproduce", words))
        if not found:
            out.append(Comparison(m, p, None, None, "not measured", "no figure of ours for this model and metric "
                                  "in this store"))
    return out
