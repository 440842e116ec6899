"""The report's view model: the store's rows as typed sections that every renderer draws.

What a reader is shown is decided here once, so Markdown and HTML stay thin:
- sections by (dataset, fingerprint, scene, harness[, sampler]); one row per configuration;
- per metric: the mean over materials with a bootstrap 95 % interval, the median and the
  worst case; costs beside accuracy, each with the aggregate that suits it;
- a per-category breakdown of the ranking metric, and the failures still unresolved.

An average never skips a material: a configuration that lacks a figure for any of its
section's materials gets no mean (the cell says how many are missing) and is listed
after the ranked ones. Intervals come from a seeded resampling, so a report is
reproducible from its store.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from brdfbench.pipeline import calibration

from . import tables, units
from .machines import hosts, machine_speeds
from .tables import Failure
from .generation_view import generation_section

BOOTSTRAP_RESAMPLES = 2000
CONFIDENCE = 0.95
BOOTSTRAP_SEED = 0
#: Fewer materials than this get no interval: a bootstrap of two or three values says
#: little about the spread of a mean and would read as more certain than it is.
MIN_INTERVAL_N = 5

COST_LABELS = {
    "fit_loss": "own fit loss",
    "fit_time": "fit time (s)",
    "fit_batch": "materials per fit",
    "fit_workers": "fits side by side",
    "train_time": "train time (s)",
    "evals_per_s": "evals/s",
    "model_bytes": "bytes/material",
    "shared_bytes": "shared bytes",
    "flops_per_eval": "FLOP/eval",
    "render_time": "render time (s)",
    "render_samples_per_s": "render samples/s",
    "peak_rss_fit": "peak memory, fit (B)",
    "peak_rss_eval": "peak memory, eval (B)",
    "peak_rss_train": "peak memory, train (B)",
}
#: Costs without a better direction of their own (a count, a family's own objective).
UNDIRECTED = ("fit_loss", "fit_batch", "fit_workers")


@dataclass(frozen=True)
class Metric:
    """A column: what it measures, in which unit, which way is better, how it aggregates."""

    name: str
    unit: str
    higher_is_better: bool
    kind: str  # "accuracy" | "cost"
    aggregate: str = "mean"  # over materials: mean | median | max

    @property
    def label(self) -> str:
        return COST_LABELS.get(self.name, self.name)

    @property
    def short_label(self) -> str:
        """The label without the unit where cells print their own ("fit time (s)" → "fit time")."""
        text = self.label
        if self.kind == "cost" and units.scales(self.unit) and text.endswith(")") and " (" in text:
            text = text[:text.rindex(" (")]
        return text

    def show(self, value: float | None) -> str:
        """A figure as printed: costs in readable units (12.3 ms, 1.27 kB), the rest as measured."""
        if self.kind == "cost" and units.scales(self.unit):
            return units.human(value, self.unit)
        return units.fmt(value)

    @property
    def directed(self) -> bool:
        return self.name not in UNDIRECTED

    @property
    def arrow(self) -> str:
        return "" if not self.directed else ("↑" if self.higher_is_better else "↓")

    @property
    def timed(self) -> bool:
        return self.name in tables.TIMED


@dataclass(frozen=True)
class Cell:
    """One configuration's figure for one metric over its section's materials."""

    value: float | None  # the aggregate over every material; None where any is missing
    n: int  # materials with a figure
    expected: int  # materials in the section
    lo: float | None = None  # bootstrap interval of the mean (accuracy metrics)
    hi: float | None = None
    median: float | None = None
    worst: float | None = None
    partial: float | None = None  # the aggregate over the materials that have one (shown as such, never ranked)
    contended: bool = False  # measured while other brdfbench jobs ran on the host
    accelerator: str = ""  # the GPU (model) its figures were computed on; "" for the CPU

    @property
    def missing(self) -> int:
        return self.expected - self.n

    @property
    def complete(self) -> bool:
        return self.value is not None


@dataclass(frozen=True)
class Row:
    """A configuration: its display label, plugin and parameters, rank, and cells by metric."""

    config_hash: str
    label: str
    plugin: str
    params: dict[str, Any] | None
    rank: int | None
    cells: dict[str, Cell]
    #: the target itself (`RepresentationSpec.reference`): shown above the ranking, never
    #: ranked, never best, off the cost plots' axes by default
    reference: bool = False

    def cell(self, metric: str) -> Cell | None:
        return self.cells.get(metric)


@dataclass(frozen=True)
class Category:
    """The ranking metric's cells over the materials of one category."""

    name: str
    materials: int
    cells: dict[str, Cell]  # config hash → cell


@dataclass(frozen=True)
class Split:
    """A table section's materials split by the width of their target's specular lobe: the
    sharpest tenth (at least one) against the rest, with each configuration's mean of
    `metrics` over each part. Timonen et al. claim the learned warps help most on sharp highlights."""

    sharpest: tuple[str, ...]  # by ascending half-width
    widths: dict[str, float]  # material → lobe half-width (rad) of the sharpest
    rest: int
    metrics: list[Metric]
    cells: dict[tuple[str, str, bool], Cell]  # (config hash, metric, sharpest?) → cell


@dataclass(frozen=True)
class TableSection:
    """Accuracy (BRDF space) or image metrics of a rendered scene, with their cost."""

    dataset: str
    fingerprint: str
    scene: str
    harness: str
    materials: tuple[str, ...]
    caveat: str
    primary: Metric | None
    accuracy: list[Metric]
    costs: list[Metric]
    rows: list[Row]  # ranked by the primary metric; incomplete configurations last
    categories: list[Category]
    failures: list[Failure]
    material_categories: dict[str, str] = field(default_factory=dict)
    sharpness: Split | None = None
    #: accuracy metric → (config hash, material) → that material's figure (the drill-down)
    per_material: dict[str, dict[tuple[str, str], float]] = field(default_factory=dict)
    #: material → its target's lobe half-width (rad), where the cells recorded one
    lobe_widths: dict[str, float] = field(default_factory=dict)
    kind: str = field(default="table", init=False)

    @property
    def metrics(self) -> dict[str, Metric]:
        return {m.name: m for m in [*self.accuracy, *self.costs]}

    def ranking(self, metric: str) -> list[Row]:
        """Rows by one metric's complete cells (better first), then the incomplete ones."""
        m = self.metrics[metric]
        return _ranked(self.rows, metric, m.higher_is_better)

    @property
    def contended(self) -> bool:
        return any(c.contended for r in self.rows for name, c in r.cells.items() if self.metrics[name].timed)

    @property
    def brief(self) -> list[str]:
        """Labels of configurations on a first look's brief recipe (`*_brief` configs)."""
        return [r.label for r in self.rows if r.label.split(" (")[0].endswith(BRIEF_SUFFIX)]

    @property
    def accelerators(self) -> list[str]:
        """The GPUs that computed some timed figure of the section (their cells are marked)."""
        return sorted({c.accelerator for r in self.rows for name, c in r.cells.items()
                       if self.metrics[name].timed and c.accelerator})

    @property
    def references(self) -> list[Row]:
        """The configurations that are the target itself (shown apart, never ranked)."""
        return [r for r in self.rows if r.reference]

    def timing_peers(self, metric: str) -> list[Row]:
        """The rows a metric's best is chosen among: never a reference; for a timed metric
        whose column mixes GPU and CPU timings, only the CPU ones (GPU cells are marked)."""
        rows = [r for r in self.ranking(metric) if not r.reference]
        if not self.metrics[metric].timed:
            return rows
        on_cpu = [r for r in rows if r.cell(metric) is None or not r.cell(metric).accelerator]
        return on_cpu if len(on_cpu) < len(rows) and on_cpu else rows


@dataclass(frozen=True)
class ConvergenceRow:
    label: str
    rmse: dict[int, Cell]  # spp → mean RMSE of HDR radiance over materials
    render_time: dict[int, Cell]
    slope: Cell | None
    rmse_1spp: Cell | None


@dataclass(frozen=True)
class ConvergenceSection:
    """Monte Carlo error against spp and time for one (dataset, base scene, sampler)."""

    dataset: str
    fingerprint: str
    scene: str
    sampler: str
    materials: tuple[str, ...]
    ladder: list[int]
    rows: list[ConvergenceRow]
    failures: list[Failure]
    kind: str = field(default="convergence", init=False)


@dataclass(frozen=True)
class Report:
    source: str
    generated: str
    versions: list[str]
    git_shas: list[str]
    sections: list  # TableSection | ConvergenceSection | generation_view.GenerationSection
    empty: bool
    machines: list = field(default_factory=list)  # MachineSpeed of every host and thread count
    hosts: list = field(default_factory=list)  # Host: every machine that produced a figure


#: The suffix of the first look's brief-recipe configurations (conf/representation/*_brief.yaml).
BRIEF_SUFFIX = "_brief"
#: What a section with brief-recipe rows says of them.
BRIEF_NOTE = ("the first look's brief training recipes (a plain `brdfbench`, profile=first_look: 12 materials, "
              "a few epochs): quicker and less accurate than the full recipes; `brdfbench profile=full` fits every "
              "model with its full recipe on the 24 materials of the synthetic set")


# --------------------------------------------------------------------------- statistics


def bootstrap_interval(values: np.ndarray, resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE,
                       seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of `values` (seeded: the same store gives the same report)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        raise ValueError("bootstrap of no values")
    if values.size == 1 or np.all(values == values[0]):
        return float(values[0]), float(values[0])
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, values.size, size=(resamples, values.size))].mean(axis=1)
    tail = (1 - confidence) / 2
    lo, hi = np.quantile(means, [tail, 1 - tail])
    return float(lo), float(hi)


def _aggregate(values: np.ndarray, how: str) -> float:
    return float({"mean": np.mean, "median": np.median, "max": np.max}[how](values))


def _cell(values: np.ndarray, metric: Metric, expected: int, contended: bool, accelerator: str = "") -> Cell:
    n = int(values.size)
    if n == 0:
        return Cell(None, 0, expected, contended=contended, accelerator=accelerator)
    agg = _aggregate(values, metric.aggregate)
    worst = float(values.min() if metric.higher_is_better else values.max())
    lo = hi = None
    if metric.kind == "accuracy" and n >= MIN_INTERVAL_N:
        lo, hi = bootstrap_interval(values)
    complete = n >= expected
    return Cell(agg if complete else None, n, expected, lo if complete else None, hi if complete else None,
                float(np.median(values)), worst, None if complete else agg, contended, accelerator)


def shown(cell: Cell | None) -> float | None:
    """The figure a cell shows: its aggregate, else the partial one (marked as such by renderers)."""
    if cell is None:
        return None
    return cell.value if cell.value is not None else cell.partial


def _ranked(rows: list[Row], metric: str, higher_is_better: bool) -> list[Row]:
    """References first (never ranked), then complete figures better first, then the rest."""
    def key(row: Row):
        c = row.cells.get(metric)
        if row.reference:
            return (0, 0.0, row.label)
        if c is None or not c.complete:
            return (2, 0.0, row.label)
        return (1, -c.value if higher_is_better else c.value, row.label)

    return sorted(rows, key=key)


# --------------------------------------------------------------------------- sections


def _metrics(df: pd.DataFrame) -> tuple[list[Metric], list[Metric]]:
    ok = df[(df.status == "ok") & (df.spp == 0)]
    meta = ok.groupby("metric")[["unit", "higher_is_better"]].first()
    present = set(meta.index)
    summary_like = pd.DataFrame({"metric": sorted(present)})
    accuracy = [Metric(m, str(meta.loc[m, "unit"] or ""), bool(meta.loc[m, "higher_is_better"]), "accuracy")
                for m in tables.accuracy_metrics(summary_like)]
    costs = [Metric(m, str(meta.loc[m, "unit"] or ""), bool(meta.loc[m, "higher_is_better"]), "cost", how)
             for m, how in tables.COST_METRICS.items() if m in present]
    return accuracy, costs


def _failures(df: pd.DataFrame) -> list[Failure]:
    return [Failure(f.representation, f.material, str(f.message)) for f in tables.failures(df).itertuples()]


def table_section(key: tuple[str, str, str, str], df: pd.DataFrame, widths: dict[str, float] | None = None) -> TableSection:
    """One table section from its rows (labels already unique within it); `widths` (material →
    target lobe half-width, rad) splits off the sharpest tenth where every material has one."""
    dataset, fingerprint, scene, harness = key
    df = df[~df.metric.isin(tables.TARGET_PROPERTIES)]
    materials = tuple(sorted(df["material"].unique()))
    accuracy, costs = _metrics(df)
    ok = df[(df.status == "ok") & (df.spp == 0)]
    configs = df.drop_duplicates("config_hash")
    rows = []
    for conf in configs.itertuples():
        mine = ok[ok.config_hash == conf.config_hash]
        cells = {}
        for metric in [*accuracy, *costs]:
            got = mine[mine.metric == metric.name]
            if got.empty:
                continue
            values = got.drop_duplicates("material", keep="last")["value"].to_numpy(dtype=float)
            contended = bool((got["concurrent_jobs"] > 1).any())
            gpus = sorted({tables.accelerator(d) for d in got.get("device_detail", pd.Series(["cpu"]))} - {""})
            cells[metric.name] = _cell(values, metric, len(materials), contended, " and ".join(gpus))
        params = tables._params(conf.params)
        plugin = getattr(conf, "plugin", "") or ""
        rows.append(Row(conf.config_hash, conf.representation, plugin, params, None, cells,
                        tables.is_reference(plugin, params)))
    primary = accuracy[0] if accuracy else None
    if primary is not None:
        ordered = _ranked(rows, primary.name, primary.higher_is_better)
        rank = 0
        ranked = []
        for row in ordered:
            c = row.cells.get(primary.name)
            if c is not None and c.complete and not row.reference:
                rank += 1
                ranked.append(Row(**{**row.__dict__, "rank": rank}))
            else:
                ranked.append(row)
        rows = ranked
    cats = {}
    if "category" in df.columns:
        cats = {str(m): str(c) for m, c in df.drop_duplicates("material")[["material", "category"]].itertuples(index=False)}
    widths = widths or {}
    return TableSection(dataset, fingerprint, scene, harness, materials, tables.dataset_caveat(dataset), primary,
                        accuracy, costs, rows, _categories(ok, primary, rows), _failures(df), cats,
                        _sharpness(ok, accuracy, rows, materials, widths), _per_material(ok, accuracy),
                        {m: widths[m] for m in materials if m in widths})


def _per_material(ok: pd.DataFrame, accuracy: list[Metric]) -> dict[str, dict[tuple[str, str], float]]:
    out: dict[str, dict[tuple[str, str], float]] = {}
    for metric in accuracy:
        got = ok[ok.metric == metric.name].drop_duplicates(["config_hash", "material"], keep="last")
        out[metric.name] = {(str(h), str(m)): float(v) for h, m, v in
                            got[["config_hash", "material", "value"]].itertuples(index=False)}
    return out


#: Accuracy metrics the sharpest-decile split shows, where present (else the ranking one).
SPLIT_METRICS = ("l1_log_cos", "hdr_rmse", "ssim_ldr", "flip_ldr")
#: The split needs this many materials: below it the "tenth" is one material.
SPLIT_MIN_MATERIALS = 10


def lobe_widths(df: pd.DataFrame) -> dict[str, dict[str, float]]:
    """Dataset fingerprint → material → its target's lobe half-width (rad), from any cell."""
    got = df[(df.metric == tables.TARGET_HALF_WIDTH) & (df.status == "ok")].dropna(subset=["value"])
    out: dict[str, dict[str, float]] = {}
    for (fingerprint, material), value in got.groupby(["dataset_fingerprint", "material"])["value"].first().items():
        out.setdefault(str(fingerprint), {})[str(material)] = float(value)
    return out


def _sharpness(ok: pd.DataFrame, accuracy: list[Metric], rows: list[Row], materials: tuple[str, ...],
               widths: dict[str, float]) -> Split | None:
    if len(materials) < SPLIT_MIN_MATERIALS or not accuracy or any(m not in widths for m in materials):
        return None
    ordered = sorted(materials, key=lambda m: (widths[m], m))
    sharpest = tuple(ordered[:len(ordered) // 10])
    shown_metrics = [m for m in accuracy if m.name in SPLIT_METRICS] or accuracy[:1]
    cells = {}
    for metric in shown_metrics:
        got = ok[ok.metric == metric.name].drop_duplicates(["config_hash", "material"], keep="last")
        for row in rows:
            mine = got[got.config_hash == row.config_hash]
            for part, members in ((True, set(sharpest)), (False, set(materials) - set(sharpest))):
                values = mine[mine.material.isin(members)]["value"].to_numpy(dtype=float)
                cells[(row.config_hash, metric.name, part)] = _cell(values, metric, len(members), False)
    return Split(sharpest, {m: widths[m] for m in sharpest}, len(materials) - len(sharpest), shown_metrics, cells)


def _categories(ok: pd.DataFrame, primary: Metric | None, rows: list[Row]) -> list[Category]:
    if primary is None or "category" not in ok.columns:
        return []
    cats = ok[ok.metric == primary.name].drop_duplicates(["config_hash", "material"], keep="last")
    by_material = cats.drop_duplicates("material").set_index("material")["category"]
    out = []
    for name in sorted(set(by_material)):
        members = set(by_material[by_material == name].index)
        cells = {}
        for row in rows:
            got = cats[(cats.config_hash == row.config_hash) & cats.material.isin(members)]
            cells[row.config_hash] = _cell(got["value"].to_numpy(dtype=float), primary, len(members), False)
        out.append(Category(str(name), len(members), cells))
    return out if len(out) > 1 else []


#: the per-rung RMSE of a convergence cell, then what cells stored before it was recorded hold
RUNG_RMSE = ("convergence_rmse", "rmse_hdr")


def convergence_section(key: tuple[str, str, str, str, str], df: pd.DataFrame) -> ConvergenceSection:
    dataset, fingerprint, scene, _harness, sampler = key
    materials = tuple(sorted(df["material"].unique()))
    ok = df[df.status == "ok"]
    # the harness's own RMSE of HDR radiance per rung; cells stored before it was recorded
    # have the rmse_hdr metric's rows, the same figure
    rmse_rows = ok[ok.metric.isin(RUNG_RMSE) & (ok.spp > 0)]
    ladder = sorted(set(int(s) for s in rmse_rows.spp))
    err = Metric("convergence_rmse", "", False, "accuracy")
    timed = Metric("render_time", "s", False, "cost")
    scalar = Metric("convergence", "", False, "cost")
    rows = []
    for label, mine in ok.groupby("representation", sort=True):
        def cells(metric: str, spec: Metric) -> dict[int, Cell]:
            got = mine[(mine.metric == metric) & (mine.spp > 0)]
            return {int(spp): _cell(g["value"].to_numpy(dtype=float), spec, g["material"].nunique(), False)
                    for spp, g in got.groupby("spp")}

        def one(metric: str) -> Cell | None:
            got = mine[(mine.metric == metric) & (mine.spp == 0)]
            return None if got.empty else _cell(got["value"].to_numpy(dtype=float), scalar, len(got), False)

        rmse = cells(next((m for m in RUNG_RMSE if (mine.metric == m).any()), RUNG_RMSE[0]), err)
        if not rmse:
            continue
        rows.append(ConvergenceRow(label, rmse, cells("render_time", timed), one("convergence_slope"),
                                   one("convergence_rmse_1spp")))
    rows.sort(key=lambda r: shown(r.rmse_1spp) if shown(r.rmse_1spp) is not None else math.inf)
    return ConvergenceSection(dataset, fingerprint, scene, sampler, materials, ladder, rows, _failures(df))


def build(df: pd.DataFrame, source: str) -> Report:
    """The report of a store's rows (`Store.frame()`), `source` naming where they came from."""
    generated = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    if df.empty:
        return Report(source, generated, [], [], [], True)

    machines = machine_speeds(df)
    used = hosts(df)
    df = df[df.metric != calibration.METRIC]  # the machine's figure, not a model's
    sections: list = []
    widths = lobe_widths(df)
    for (name, fingerprint, scene, harness, sampler), group in tables.sections(df):
        if (group["scope"] == "set").all():
            sections.append(generation_section((name, fingerprint, scene, harness), group))
        elif harness == "convergence":
            sections.append(convergence_section((name, fingerprint, scene, harness, sampler), group))
        else:
            sections.append(table_section((name, fingerprint, scene, harness), group, widths.get(str(fingerprint))))
    return Report(source, generated, sorted(set(map(str, df.package_version))),
                  sorted({str(s)[:10] for s in df.git_sha}), sections, False, machines, used)
