"""The source papers' published figures beside ours for the same model and metric.

`data/seed_figures.csv` holds every table of the four source papers as printed (with
their sources); `data/published_matches.csv` says which of those rows measure what one of
our metrics measures: our representation (with the parameters a configuration must have,
where it names some: `published_fit(source=bagher_sgd)`), metric and scene ("*": any
rendered scene), the factor from the paper's unit to ours (`scale`), how the setups differ,
and, for figures that depend on them, the paper's materials and training recipe.

A verdict is given only where the two figures measure the same thing:
- a time or a rate (seconds, anything per second) measures the machine and its software as
  much as the method: "not comparable (hardware)", the ratio kept as information;
- an accuracy figure over other materials than the paper's (our synthetic set against MERL),
  or of a trained model on another recipe than the paper's: "not comparable (dataset)",
  "(recipe)" or "(dataset, recipe)", naming the mismatch;
- any other figure agrees when it is within a factor of two of the published one (for dB:
  within 3 dB; for SSIM: 1 − SSIM within a factor of two) for some value the printed
  figure stands for (it is rounded to its last printed digit), else does not reproduce.
A match with no figure of ours is listed as not measured.

Byte figures: each paper's "kB" is converted to bytes once, by its own convention
(`KILOBYTE`, read from its text); the report prints bytes with decimal prefixes (1 kB = 1000 B,
`units`).

The data key each row by an internal label of its paper; what a report shows is the
paper's citation (`brdfbench.citations`, `citation` here), e.g. "Sztrajman et al. 2021,
Table 2".
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from brdfbench import citations

from . import units
from .published_data import FIGURES_FILE, Match, Published, citation, figures, matches

if TYPE_CHECKING:  # the view's types, for annotations only (no import cycle through the view)
    from .view import Cell, Metric, Report, Row, TableSection

AGREEMENT_FACTOR = 2.0
#: Configurations (conf/) that train on a source paper's own recipe rather than this
#: project's CPU schedule: the report says which produced each of our figures.
PUBLISHED_RECIPES = ("nbrdf_reference", "triplane_gated_paper", "tripleplane_paper", "hyperdiffusion_paper")

AGREES = "agrees"
DIFFERS = "does not reproduce"
NOT_MEASURED = "not measured"
MISSING = "published figure missing"
INCOMPLETE = "incomplete"
HARDWARE = "hardware"
DATASET = "dataset"
RECIPE = "recipe"

#: Bytes in one "kB" of each paper, as its own text shows, and the evidence (the `scale` of
#: every byte match in published_matches.csv is this factor).
KILOBYTE: dict[str, tuple[int, str]] = {
    "seed 000": (1024, "its NBRDF's 675 fp32 weights, 2700 B, are printed 2.63672 kB and 8 fp32 parameters "
                       "0.03125 kB; its 35840 kB for a MERL table is ambiguous, the text calling it 35.84 MB"),
    "seed 001": (1000, "its 675-weight NBRDF, 2700 B in fp32, is printed 2.70 KB; its 0.03 KB, printed to two "
                       "decimals, stands for 25 to 35 B"),
    "seed 002": (1000, "its caption's raw MERL data, \"around 35 MB\", is 34.99 × 10⁶ B or 33.4 MiB; its "
                       "three-digit table alone does not decide"),
}
#: Our datasets that hold measured materials like the papers' (MERL tables; the published NBRDF
#: networks of MERL/RGL materials), with how a verdict names them. Any other set (the synthetic
#: default, AugMERL mixes) is not the papers' materials.
MEASURED_DATASETS = {"merl_folder": "MERL", "nbrdf_release": "NBRDF-release"}


@dataclass(frozen=True)
class Comparison:
    match: Match
    published: Published | None  # None: the match names a row the figures file lacks
    section: TableSection | None  # None: not measured in this store
    ours: Cell | None
    verdict: str  # AGREES | DIFFERS | "not comparable (…)" | NOT_MEASURED | MISSING | INCOMPLETE
    detail: str  # the notes below, in one line
    label: str = ""  # our configuration that produced `ours`
    notes: tuple[str, ...] = ()  # the ratio, then each mismatch, in words
    mismatch: tuple[str, ...] = ()  # HARDWARE | DATASET | RECIPE: why no verdict

    @property
    def theirs(self) -> float | None:
        """The published figure in our metric's unit."""
        return None if self.published is None else self.published.value * self.match.scale

    @property
    def comparable(self) -> bool:
        return self.verdict in (AGREES, DIFFERS)

    @property
    def metric(self) -> Metric | None:
        return None if self.section is None else self.section.metrics.get(self.match.our_metric)


def not_comparable(kinds: tuple[str, ...]) -> str:
    return f"not comparable ({', '.join(kinds)})"


def find(match: Match, published: list[Published]) -> Published | None:
    """The published figure a match names (its paper, table, model and metric), if any."""
    for p in published:
        if (p.source.startswith(match.seed + " ") and (p.table == match.table or p.table.startswith(match.table + " "))
                and p.model == match.model and p.metric == match.metric):
            return p
    return None


def param_text(value) -> str:
    """A stored parameter as a match names it: a string as is, anything else as JSON (null, true, 3)."""
    return value if isinstance(value, str) else json.dumps(value)


def selects(match: Match, row: Row) -> bool:
    """Whether `row` is a configuration the match names: its plugin (or label) is the match's
    representation, and it has every parameter the match names, with that value."""
    if row.plugin != match.representation and row.label != match.representation:
        return False
    inner = (row.params or {}).get("params")
    inner = inner if isinstance(inner, dict) else {}
    return all(key in inner and param_text(inner[key]) == value for key, value in match.params)


def hardware_bound(unit: str) -> bool:
    """Whether a figure in `unit` is a time or a rate (s, ms, min, h; anything per second):
    it measures the machine and its software as much as the method."""
    u = unit.strip()
    return u in ("s", "ms", "min", "h") or u.endswith("/s")


def _within(ours: float, theirs: float, metric: str, unit: str) -> bool:
    if unit == "dB":
        return abs(ours - theirs) <= 10 * math.log10(AGREEMENT_FACTOR)
    if metric.startswith("ssim"):
        a, b = 1 - ours, 1 - theirs
        return a <= 0 if b <= 0 else 1 / AGREEMENT_FACTOR <= a / b <= AGREEMENT_FACTOR
    if theirs == 0:
        return ours == 0
    return 1 / AGREEMENT_FACTOR <= ours / theirs <= AGREEMENT_FACTOR


def _words(ours: float, theirs: float, metric: str, unit: str) -> str:
    if unit == "dB":
        return f"ours {ours - theirs:+.3g} dB"
    if metric.startswith("ssim"):
        a, b = 1 - ours, 1 - theirs
        return "1 − SSIM: theirs 0" if b <= 0 else f"1 − SSIM: ours {a / b:.3g}× theirs"
    return "theirs 0" if theirs == 0 else f"ours {ours / theirs:.3g}× theirs"


def agreement(ours: float, theirs: float, metric: str, unit: str, spread: float = 0.0) -> tuple[bool, str]:
    """Whether `ours` is within the stated factor of some value in theirs ± `spread` (what a
    rounded published figure stands for), and the comparison with `theirs` in words."""
    nearest = min(max(ours, theirs - spread), theirs + spread)
    return _within(ours, nearest, metric, unit), _words(ours, theirs, metric, unit)


def show(value: float | None, metric: Metric | None) -> str:
    """A figure as this section prints it: a cost in its unit with a decimal prefix (`units.human`:
    "64 B", "161 ms"), anything else as a plain number."""
    unit = metric.unit if metric is not None and metric.kind == "cost" else ""
    return units.human(value, unit)


def _verdict(m: Match, p: Published, s: TableSection, label: str, cell: Cell) -> Comparison:
    """One comparable-or-not row: what keeps it from a verdict, else the factor-of-two rule."""
    metric = s.metrics[m.our_metric]
    theirs = p.value * m.scale
    ok, words = agreement(cell.value, theirs, m.our_metric, metric.unit, p.half_step * m.scale)
    notes = [words]
    config = label.split(" (")[0]
    if hardware_bound(metric.unit) or hardware_bound(p.unit):
        notes = [f"{words} ({show(cell.value, metric)} against {p.printed or p.value} {p.unit}".rstrip() + "), "
                 "as information: another machine and other software"]
        if m.paper_recipe and config not in m.recipe_configs:
            notes.append(f"also another recipe: theirs {m.paper_recipe}")
        return Comparison(m, p, s, cell, not_comparable((HARDWARE,)), "; ".join(notes), label, tuple(notes),
                          (HARDWARE,))
    mismatch = []
    if m.dataset or metric.kind == "accuracy":  # an accuracy figure depends on the materials, said or not
        ours_set = MEASURED_DATASETS.get(s.dataset, s.dataset)
        notes.append(f"materials: {len(s.materials)} {ours_set} here, the paper's {m.dataset or 'not recorded'}")
        if s.dataset not in MEASURED_DATASETS or not m.dataset:
            mismatch.append(DATASET)
    if m.paper_recipe and config not in m.recipe_configs:
        follows = (", ".join(m.recipe_configs) + " follows it") if m.recipe_configs else "no configuration here follows it"
        notes.append(f"recipe: {config} here, the paper's {m.paper_recipe} ({follows})")
        mismatch.append(RECIPE)
    if mismatch:
        return Comparison(m, p, s, cell, not_comparable(tuple(mismatch)), "; ".join(notes), label, tuple(notes),
                          tuple(mismatch))
    if ok and not _within(cell.value, theirs, m.our_metric, metric.unit):
        lo, hi = (p.value - p.half_step) * m.scale, (p.value + p.half_step) * m.scale
        notes.append(f"the printed {p.printed} {p.unit} stands for {show(lo, metric)} to {show(hi, metric)}: "
                     f"ours is within the factor of {AGREEMENT_FACTOR:g} of {show(min(max(cell.value, lo), hi), metric)}"
                     .replace("  ", " "))
    return Comparison(m, p, s, cell, AGREES if ok else DIFFERS, "; ".join(notes), label, tuple(notes))


def compare(report: Report) -> list[Comparison]:
    """Every match against every table section with our figure for it (else one row saying so)."""
    published = figures()
    tables_ = [s for s in report.sections if getattr(s, "kind", "") == "table"]
    out = []
    for m in matches():
        p = find(m, published)
        if p is None:
            out.append(Comparison(m, None, None, None, MISSING,
                                  f"{citation(m.seed, m.table)[0]}: no row for {m.model} / {m.metric} in {FIGURES_FILE}"))
            continue
        found = False
        for s in tables_:
            if m.scene == "*" and s.scene == "brdf_space" or m.scene not in ("*", s.scene):
                continue
            for row in s.rows:
                if not selects(m, row):
                    continue
                cell = row.cell(m.our_metric)
                if cell is None:
                    continue
                found = True
                if not cell.complete:
                    out.append(Comparison(m, p, s, cell, INCOMPLETE, f"{cell.missing} of {cell.expected} materials "
                                          "missing: no mean to compare", row.label))
                    continue
                out.append(_verdict(m, p, s, row.label, cell))
        if not found:
            out.append(Comparison(m, p, None, None, NOT_MEASURED, "no figure of ours for this model and metric "
                                  "in this store"))
    return out


def counts(rows: list[Comparison]) -> str:
    """The verdicts in one sentence, comparable ones first."""
    n = {v: sum(c.verdict == v for c in rows) for v in (AGREES, DIFFERS, NOT_MEASURED, INCOMPLETE)}
    hardware = sum(c.mismatch == (HARDWARE,) for c in rows)
    setup = sum(bool(c.mismatch) and HARDWARE not in c.mismatch for c in rows)
    parts = [f"{n[AGREES]} agree and {n[DIFFERS]} do not reproduce where the setups are comparable",
             f"{hardware} timings and throughputs are not comparable (hardware)",
             f"{setup} accuracy figures are not comparable (other materials or recipe)"]
    if n[INCOMPLETE]:
        parts.append(f"{n[INCOMPLETE]} incomplete")
    parts.append(f"{n[NOT_MEASURED]} not measured in this store")
    return "; ".join(parts) + "."


def kilobyte_note() -> str:
    """Which "kB" each paper prints, and the report's own: for the section's note."""
    parts = [f"{citations.source(seed)}: 1 kB = {size} B ({why})." for seed, (size, why) in KILOBYTE.items()]
    return ("This report prints bytes with decimal prefixes, 1 kB = 1000 B. Each paper's kB is converted to bytes "
            "once, by the paper's own convention. " + " ".join(parts))


def note() -> list[str]:
    """The section's caveat in paragraphs (configuration names in `backticks`, as Markdown code):
    when a verdict is given, the kB conventions, and which configurations follow a paper's recipe."""
    schedules = ", ".join(f"`{n}`" for n in ("nbrdf", "naive_mlp", "tripleplane", "triplane_gated", "hyperdiffusion"))
    papers = ", ".join(f"`{n}`" for n in PUBLISHED_RECIPES)
    return [("Figures as printed in the source papers, converted to our unit, beside our figure for the same model "
             "and metric. A verdict is given only where the setups are comparable: a figure within a factor of "
             f"{AGREEMENT_FACTOR:g} of the published one (within 3 dB for PSNR; 1 − SSIM within a factor of "
             f"{AGREEMENT_FACTOR:g} for SSIM), allowing for the rounding of the printed figure, agrees; any other "
             "does not reproduce. Timings and throughputs come from other machines and software: they are \"not "
             "comparable (hardware)\", their ratio shown as information. An accuracy figure over other materials "
             "than the paper's (our synthetic set against MERL or RGL measurements) is \"not comparable (dataset)\"; "
             "one of a trained model on another recipe than the paper's is \"not comparable (recipe)\"."),
            kilobyte_note(),
            (f"Our configurations {schedules} train on this project's schedules, sized for a CPU; {papers} on the "
             "papers' own recipes (see the README's GPUs section).")]
