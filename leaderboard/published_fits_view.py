"""The section "Published fits against our fits" as a typed view, from the results DataFrame.

For each report section (dataset, fingerprint, scene, harness) with `published_fit` rows,
and each published-fit configuration in it (one per `source`): the published fit's figures
beside those of every configuration of the model its fits are evaluated with
(`source_model(source)`; each fitting loss its own row), both over the same materials (the
ones where both cells are ok), per accuracy metric (the ranking one first), with ours −
published. Failed cells are excluded and counted. No rendering here
(`published_fits_render` draws it).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import pandas as pd

from brdfbench.errors import BrdfbenchError
from brdfbench.pipeline import calibration

from . import tables

PLUGIN = "published_fit"
DEFAULT_LOSS = "l1_log_cos"  # the analytic fits' default loss, left out of stored params
#: The paper of each source (by the file's prefix), cited by authors and title.
PAPERS = (
    ("ngan_", "Ngan, Durand and Matusik, \"Experimental Analysis of BRDF Models\" (EGSR 2005)"),
    ("low_", "Löw, Kronander, Ynnerman and Unger, \"BRDF Models for Accurate and Efficient Rendering of Glossy "
             "Surfaces\" (ACM TOG 2012)"),
    ("bagher_", "Bagher, Soler and Holzschuch, \"Accurate Fitting of Measured Reflectances Using a Shifted Gamma "
                "Micro-facet Distribution\" (CGF 2012)"),
)
#: The fitting loss of ours that is the one the source's authors fitted with, where we have it.
AUTHORS_LOSS = (("ngan_", "", "ngan_l2"), ("low_", "_e1", "low_e1"), ("low_", "_e2", "low_e2"))
MADE_AGAINST = ("The published fits are the parameters their authors printed, fitted by them to the measured MERL "
                "data under their own error measure, and evaluated here as printed, with no fitting. Ours are the "
                "same model fitted here to this dataset's materials, one row per fitting loss (`l1_log_cos`, this "
                "project's default, or the authors' own where we have it). Each pair is compared over the materials "
                "where both have a figure; a failed cell (a material without a published fit, a fit that failed) "
                "is left out and counted. Difference: ours − published. The unweighted errors (`l1` over the "
                "grid, `hdr_rmse` and `hdr_mae` over random pairs) are dominated by pairs next to the horizon, "
                "where the models with a 1/(cos θi cos θo) factor (Cook-Torrance, Ward-Dür, SGD, Löw et al.'s "
                "microfacet model) grow without bound; `l1_log_cos` weighs by cos θi in logs and is the figure "
                "to compare them on.")


@dataclass(frozen=True)
class MetricPair:
    """One metric's means over a pair's common materials."""

    metric: str
    unit: str
    higher_is_better: bool
    n: int  # materials with both figures
    published: float | None
    ours: float | None

    @property
    def difference(self) -> float | None:
        return None if self.published is None or self.ours is None else self.ours - self.published

    @property
    def better(self) -> str:
        """"ours", "published" or "equal" (by the metric's direction); "" without both figures."""
        d = self.difference
        if d is None:
            return ""
        if d == 0:
            return "equal"
        return "ours" if (d > 0) == self.higher_is_better else "published"


@dataclass(frozen=True)
class OurFit:
    """One configuration of the source's model, beside the published fit."""

    config_hash: str
    label: str
    loss: str
    authors_loss: bool  # fitted with the loss the source's authors used
    materials: int  # materials where both cells are ok
    failed: int  # of ours, left out
    metrics: list[MetricPair]


@dataclass(frozen=True)
class SourceFits:
    """A published-fit configuration (one source) and our fits of its model."""

    source: str
    paper: str  # the source's paper, by authors and title ("" for a file of another origin)
    label: str  # the published-fit configuration's display label
    config_hash: str
    model: str | None  # the registered model its fits are evaluated with; None: none evaluates them
    ok: int  # materials where the published fit has a figure
    failed: tuple[str, ...]  # materials where it failed (left out)
    ours: list[OurFit]
    note: str = ""  # why there is no pair, where there is none


@dataclass(frozen=True)
class FitsSection:
    dataset: str
    fingerprint: str
    scene: str
    harness: str
    materials: int
    caveat: str  # what the dataset is against the data the fits were made against
    metrics: list[str]  # accuracy metrics, the ranking one first
    sources: list[SourceFits]


@dataclass(frozen=True)
class PublishedFits:
    note: str
    sections: list[FitsSection]


def dataset_caveat(dataset: str) -> str:
    """The dataset against the measured MERL data the published fits were made against."""
    if dataset == "nbrdf_release":
        return ("Dataset `nbrdf_release`: its 100 MERL materials are the published NBRDF networks approximating the "
                "MERL measurements, close stand-ins, not the data the published fits were made against; our fits "
                "were made against these networks.")
    if dataset == "merl_folder":
        return "Dataset `merl_folder`: the measured MERL tables, the data the published fits were made against."
    if dataset.startswith("synthetic"):
        return ("A synthetic set has no published fits: its materials are not MERL's, so every published-fit cell "
                "fails.")
    return (f"Dataset `{dataset}`: not the measured MERL data the published fits were made against; a material "
            "without a published fit of its name fails.")


def paper(source: str) -> str:
    return next((text for prefix, text in PAPERS if source.lower().startswith(prefix)), "")


def authors_loss(source: str) -> str | None:
    s = source.lower()
    return next((loss for prefix, suffix, loss in AUTHORS_LOSS if s.startswith(prefix) and s.endswith(suffix)), None)


def model_of(source: str) -> tuple[str | None, str]:
    """(the model a source's fits are evaluated with, or None, and why not)."""
    try:
        from brdfbench_representations.published import source_model  # lazy: torch

        name = source_model(source)
    except (ImportError, OSError, ValueError, LookupError, BrdfbenchError) as exc:  # the report goes on
        return None, f"the source could not be read ({exc})"
    return name, "" if name else "no brdfbench model evaluates these fits"


def _inner(text) -> dict:
    params = tables._params(text) or {}
    inner = params.get("params")
    return inner if isinstance(inner, dict) else {}


def _states(group: pd.DataFrame) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """config hash → materials with an ok figure; config hash → materials that failed (and not ok since)."""
    ok = {h: set(g["material"]) for h, g in group[group.status == "ok"].groupby("config_hash")}
    failed = {h: set(g["material"]) - ok.get(h, set()) for h, g in group[group.status == "failed"].groupby("config_hash")}
    return ok, failed


def _values(ok_rows: pd.DataFrame) -> dict[tuple[str, str], dict[str, float]]:
    """(config hash, metric) → material → value (the last written)."""
    rows = ok_rows.dropna(subset=["value"]).drop_duplicates(["config_hash", "metric", "material"], keep="last")
    return {(str(h), str(m)): dict(zip(g["material"], g["value"].astype(float)))
            for (h, m), g in rows.groupby(["config_hash", "metric"])}


def _mean(values: list[float]) -> float | None:
    return math.fsum(values) / len(values) if values else None


def _pair(pub: str, mine: str, common: set[str], metrics: list[tuple[str, str, bool]], values) -> list[MetricPair]:
    out = []
    for name, unit, hib in metrics:
        theirs, ours = values.get((pub, name), {}), values.get((mine, name), {})
        both = sorted(m for m in common if m in theirs and m in ours)
        out.append(MetricPair(name, unit, hib, len(both), _mean([theirs[m] for m in both]),
                              _mean([ours[m] for m in both])))
    return out


def _labels(mine: pd.DataFrame, raw: dict[str, str], losses: dict[str, str]) -> dict[str, str]:
    """config hash → our fit's label: its own where its loss tells it apart (the loss is shown
    beside it), else the section's unique display label."""
    seen = Counter((raw.get(h, label), losses[h]) for h, label in zip(mine.config_hash, mine.representation))
    return {str(h): raw.get(h, label) if seen[(raw.get(h, label), losses[h])] == 1 else str(label)
            for h, label in zip(mine.config_hash, mine.representation)}


def _section(key: tuple[str, str, str, str], group: pd.DataFrame, raw: dict[str, str]) -> FitsSection:
    dataset, fingerprint, scene, harness = key
    ok_rows = group[(group.status == "ok") & (group.spp == 0)]
    meta = ok_rows.groupby("metric")[["unit", "higher_is_better"]].first()
    names = tables.accuracy_metrics(pd.DataFrame({"metric": sorted(meta.index)}))
    metrics = [(m, str(meta.loc[m, "unit"] or ""), bool(meta.loc[m, "higher_is_better"])) for m in names]
    ok, failed = _states(group)
    values = _values(ok_rows)
    configs = group.drop_duplicates("config_hash")
    sources = []
    for conf in configs[configs.plugin == PLUGIN].itertuples():
        source = str(_inner(conf.params).get("source", "bagher_sgd"))
        chosen = _inner(conf.params).get("model")  # another reading of the source's fits
        model, why = (str(chosen), "") if chosen else model_of(source)
        mine = configs[configs.plugin == model] if model else configs.iloc[0:0]
        losses = {h: str(_inner(p).get("loss") or DEFAULT_LOSS) for h, p in zip(mine.config_hash, mine.params)}
        labels = _labels(mine, raw, losses)
        ours = []
        for other in mine.itertuples():
            loss = losses[other.config_hash]
            common = ok.get(conf.config_hash, set()) & ok.get(other.config_hash, set())
            ours.append(OurFit(str(other.config_hash), labels[other.config_hash], loss, loss == authors_loss(source),
                               len(common), len(failed.get(other.config_hash, set())),
                               _pair(conf.config_hash, other.config_hash, common, metrics, values)))
        ours.sort(key=lambda f: (f.loss != DEFAULT_LOSS, f.loss, f.label))
        if model and not ours:
            why = f"no fit of ours of `{model}` in this section: run `representation={model}` beside it"
        sources.append(SourceFits(source, paper(source), str(conf.representation), str(conf.config_hash), model,
                                  len(ok.get(conf.config_hash, set())),
                                  tuple(sorted(failed.get(conf.config_hash, set()))), ours, why))
    sources.sort(key=lambda s: (s.source, s.label))
    return FitsSection(dataset, fingerprint, scene, harness, int(group["material"].nunique()), dataset_caveat(dataset),
                       names, sources)


def build(df: pd.DataFrame) -> PublishedFits | None:
    """The section's view of a store's rows (`Store.frame()`); None where no row is a published fit's."""
    if df.empty:
        return None
    if "plugin" not in df.columns:
        df = df.assign(plugin=df["representation"])
    df = df.assign(plugin=df["plugin"].where(df["plugin"].fillna("") != "", df["representation"]))
    if not (df["plugin"] == PLUGIN).any():
        return None
    df = df[(df.metric != calibration.METRIC) & ~df.metric.isin(tables.TARGET_PROPERTIES)]
    raw = dict(zip(tables.normalise(df)["config_hash"], df["representation"]))  # labels before disambiguation
    sections = []
    for (dataset, fingerprint, scene, harness, _sampler), group in tables.sections(df):
        if harness == "convergence" or (group["scope"] == "set").all() or not (group["plugin"] == PLUGIN).any():
            continue
        sections.append(_section((str(dataset), str(fingerprint), str(scene), str(harness)), group, raw))
    return PublishedFits(MADE_AGAINST, sections) if sections else None
