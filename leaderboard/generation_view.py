"""The generation section of a report: Zhou et al.'s Table 1, ours beside the published figures.

Rows are (set metric, distance) pairs in Table 1's order (FID; MMD, COV and 1-NNA over the
BRDF-space and image-space distances), columns the configurations of generators (the
training set first, then PCA-A, PCA-N, VAE-A, VAE-N, hyperdiffusion, then others). A figure
is the mean over the job's independent sample draws with a Student-t 95 % interval over
them (`distributional.draw_interval`: the variability of the sample draw). Costs (training
and sampling time, memory, excluded samples) and the seven categories' counts follow.

The published figures (Hu 2026, Table 4.5 = Zhou et al., Table 1, 120 test materials) are
shown in their printed display scale ("×1e2": the figure times 100), ours converted to it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from . import published_data, tables
from .tables import Failure
from brdfbench import citations

#: Table 1's column order, by generator plugin; others follow by label.
PLUGIN_ORDER = ("training_set", "pca_brdf", "pca_nbrdf", "vae_brdf", "vae_nbrdf", "hyperdiffusion")
#: The paper's column for each of our generators (Hu 2026, Table 4.5).
PAPER_MODELS = {"training_set": "training set", "pca_brdf": "PCA-A (PCA-brdf)", "pca_nbrdf": "PCA-N (PCA-mlp)",
                "vae_brdf": "VAE-A (VAE-brdf)", "vae_nbrdf": "VAE-N (VAE-mlp)",
                "hyperdiffusion": "hyperdiffusion (NeuMaDiff)"}
#: The paper's column of a generator trained without augmentation (`harness.augmented=false`).
PAPER_UNAUGMENTED = {"hyperdiffusion": "hyperdiffusion without augmentation"}
PAPER_TABLE = "Table 4.5"
PAPER_SOURCE = "Hu 2026"  # the paper of PAPER_TABLE, as `brdfbench.citations` cites it
DISTANCE_NAMES = {"l1": "BRDF-L1", "l1_log": "BRDF-L1-log", "l1_log_cos": "BRDF-L1-log-cos", "rmse": "RMSE",
                  "neg_psnr": "-PSNR", "neg_ssim": "-SSIM"}
#: Display scale of the paper's MMD rows (the printed figure is the value times this).
MMD_SCALE = {"l1": ("x1e-3", 1e-3), "rmse": ("x1e2", 1e2), "neg_ssim": ("x10", 10.0)}
METRIC_NAMES = {"mmd": "MMD", "cov": "COV %", "one_nna": "1-NNA %", "fid": "FID"}
SET_METRICS = ("fid", "mmd", "cov", "one_nna")
COSTS = {"train_time": "train time (s)", "sample_time": "sample time per draw (s)",
         "peak_rss_train": "peak memory, train (B)", "peak_rss_eval": "peak memory, scoring (B)",
         "model_bytes": "generator bytes", "non_finite_samples": "non-finite samples excluded per draw",
         "samples_scored": "samples scored per draw"}
CONFIDENCE = 0.95
PAPER_CAVEAT = ("Published: Hu 2026, Table 4.5 (= Zhou et al., Table 1; its VAE-N column differs), scored on a "
               "120-material test set of AugMERL from the 100 MERL measurements, FID on 64-dim Inception features; "
               "ours on this dataset's split and renders (standard 2048-dim Inception features), so compare "
               "orderings, not values.")


@dataclass(frozen=True)
class DrawCell:
    """A figure over sample draws: mean, t interval (None for one draw), draws."""

    value: float
    lo: float | None
    hi: float | None
    n: int


@dataclass(frozen=True)
class Column:
    config_hash: str
    label: str
    plugin: str
    augmented: bool = True  # False: trained on the unaugmented base materials only (harness.augmented)

    @property
    def paper_model(self) -> str | None:
        """The paper's column for this configuration (Hu 2026, Table 4.5), if it has one."""
        return (PAPER_MODELS if self.augmented else PAPER_UNAUGMENTED).get(self.plugin)


@dataclass(frozen=True)
class GenRow:
    metric: str
    distance: str
    label: str  # as Table 1 prints it, with the display scale
    unit: str
    higher_is_better: bool | None  # None: no direction (a count)
    ideal: float | None  # a figure best when closest to this (1-NNA: 50 %); None: by direction
    scale: float  # ours × scale is what is shown (the paper's display scale)
    cells: dict[str, DrawCell]  # config hash → our figure (unscaled)
    published: dict[str, float]  # config hash → the published figure as printed

    def best(self, exclude: frozenset[str] = frozenset()) -> str | None:
        """The config hash with the best figure (1-NNA: closest to 50 %) among those not in
        `exclude` (the training set's: a ceiling, not a contender); None for an undirected row."""
        cells = {h: c for h, c in self.cells.items() if h not in exclude}
        if not cells:
            return None
        if self.ideal is not None:
            return min(cells, key=lambda h: abs(cells[h].value - self.ideal))
        if self.higher_is_better is None:
            return None
        sign = -1 if self.higher_is_better else 1
        return min(cells, key=lambda h: sign * cells[h].value)


@dataclass(frozen=True)
class GenerationSection:
    dataset: str
    fingerprint: str
    caveat: str
    columns: list[Column]
    rows: list[GenRow]
    costs: list[GenRow]
    categories: list[GenRow]
    reference_size: int | None
    draws: int
    failures: list[Failure]
    paper_caveat: str = PAPER_CAVEAT
    kind: str = field(default="generation", init=False)

    @property
    def ceilings(self) -> frozenset[str]:
        """Config hashes of the training-set rows: shown as the ceiling, never marked best."""
        return frozenset(c.config_hash for c in self.columns if c.plugin == "training_set")


def draw_cell(values: np.ndarray) -> DrawCell:
    values = np.asarray(values, dtype=float)
    if values.size < 2 or np.all(values == values[0]):
        return DrawCell(float(values.mean()), None if values.size < 2 else float(values[0]),
                        None if values.size < 2 else float(values[0]), int(values.size))
    from scipy import stats

    mean, sem = float(values.mean()), float(values.std(ddof=1) / math.sqrt(values.size))
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, values.size - 1)) * sem
    return DrawCell(mean, mean - half, mean + half, int(values.size))


def _augmented(params: str | None) -> bool:
    """A stored configuration's `harness.augmented` (True where it was not recorded: the default)."""
    try:
        harness = json.loads(params or "null").get("harness") or {}
    except (ValueError, AttributeError):
        return True
    return harness.get("augmented", True) is not False


def _columns(df: pd.DataFrame) -> list[Column]:
    configs = df.drop_duplicates("config_hash")
    cols = []
    for c in configs.itertuples():
        augmented = _augmented(getattr(c, "params", None))
        label = c.representation if augmented else f"{c.representation} (without augmentation)"
        cols.append(Column(c.config_hash, label, getattr(c, "plugin", "") or "", augmented))
    order = {p: i for i, p in enumerate(PLUGIN_ORDER)}
    return sorted(cols, key=lambda c: (order.get(c.plugin, len(order)), c.label))


def _published() -> dict[tuple[str, str], float]:
    """(paper model, paper metric) → the printed figure of Hu 2026, Table 4.5."""
    out = {}
    for p in published_data.figures():
        if citations.source(p.source) == PAPER_SOURCE and p.table.startswith(PAPER_TABLE):
            out[(p.model, p.metric)] = p.value
    return out


def _paper_metric(metric: str, distance: str) -> tuple[str, float]:
    """The paper's row name for (metric, distance) and its display scale."""
    if metric == "fid":
        return "FID rendered images, Inception dims 64", 1.0
    name = f"{METRIC_NAMES.get(metric, metric)} {DISTANCE_NAMES.get(distance, distance)}".strip()
    if metric == "mmd" and distance in MMD_SCALE:
        suffix, scale = MMD_SCALE[distance]
        return f"{name} {suffix}", scale
    return name, 1.0


def _row(ok: pd.DataFrame, columns: list[Column], metric: str, distance: str, label: str, scale: float,
         higher: bool | None, papers: dict[tuple[str, str], float], paper_metric: str | None,
         category: str | None = None, ideal: float | None = None) -> GenRow | None:
    got = ok[(ok.metric == metric) & (ok.distance == distance)]
    if category is not None:
        got = got[got.category == category]
    cells, printed = {}, {}
    for c in columns:
        mine = got[got.config_hash == c.config_hash].drop_duplicates("material", keep="last")
        if not mine.empty:
            cells[c.config_hash] = draw_cell(mine["value"].to_numpy(dtype=float))
        model = c.paper_model
        if paper_metric and model and (model, paper_metric) in papers:
            printed[c.config_hash] = papers[(model, paper_metric)]
    if not cells:
        return None
    unit = str(got["unit"].iloc[0]) if not got.empty else ""
    return GenRow(metric, distance, label, unit, higher, ideal, scale, cells, printed)


def generation_section(key: tuple[str, str, str, str], df: pd.DataFrame) -> GenerationSection:
    """The generation section of one (dataset, fingerprint) from its set-scope rows (labels unique)."""
    dataset, fingerprint, _scene, _harness = key
    df = df.assign(distance=df["distance"] if "distance" in df.columns else "")
    ok = df[df.status == "ok"]
    columns = _columns(df)
    papers = _published()
    rows = []
    present = ok[["metric", "distance"]].drop_duplicates()
    for metric in SET_METRICS:
        distances = [d for d in DISTANCE_NAMES if ((present.metric == metric) & (present.distance == d)).any()]
        distances += sorted(set(present[present.metric == metric].distance) - set(distances))
        for distance in distances:
            paper_metric, scale = _paper_metric(metric, distance)
            label = f"{METRIC_NAMES.get(metric, metric)} {DISTANCE_NAMES.get(distance, distance)}".strip()
            if scale != 1.0:
                label += f" (×{scale:g})"
            higher = bool(ok[ok.metric == metric]["higher_is_better"].iloc[0])
            row = _row(ok, columns, metric, distance, label, scale, higher, papers, paper_metric,
                       ideal=50.0 if metric == "one_nna" else None)
            if row is not None:
                rows.append(row)
    costs = [r for m, label in COSTS.items()
             if (r := _row(ok, columns, m, "", label, 1.0, m == "samples_scored", {}, None)) is not None]
    cats = []
    counted = ok[ok.metric == "category_count"]
    for category in _category_order(set(counted.category)):
        row = _row(ok, columns, "category_count", "", category, 1.0, None, {}, None, category=category)
        if row is not None:
            cats.append(row)
    ref = ok[ok.metric == "reference_materials"]["value"]
    draws = int(ok.groupby("config_hash")["material"].nunique().max()) if not ok.empty else 0
    return GenerationSection(dataset, fingerprint, tables.dataset_caveat(dataset), columns, rows, costs, cats,
                             int(ref.iloc[0]) if not ref.empty else None, draws,
                             [Failure(f.representation, f.material, str(f.message))
                              for f in tables.failures(df).itertuples()])


def _category_order(present: set[str]) -> list[str]:
    try:
        from brdfbench.data.categories import CATEGORIES  # lazy: torch
    except ImportError:  # the metrics plugin package is optional for reading a store
        CATEGORIES = ()
    return [c for c in CATEGORIES if c in present] + sorted(present - set(CATEGORIES))
