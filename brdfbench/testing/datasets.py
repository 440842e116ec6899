"""Conformance checks for dataset plugins, in the style of `check_representation`.

    from brdfbench.testing import check_dataset
    check_dataset("my_dataset", params={"size": 2}).raise_on_failure()

The spec's target is called with `params` (checked as `dataset.params` are), as
`bb.datasets(name, **params)` calls it. Checks: it returns a `brdfbench.data.Dataset` with
a name; material names are non-empty strings, unique, and there is at least one; the
fingerprint is a non-empty string, the same from a second call; it changes where a
parameter changes what a material of the same name holds (each integer or float
parameter of the target in turn, up to MAX_VARIED: one step up, or halved; the store
keys cells by fingerprint and material name, so other content under an old fingerprint
would pass for finished work); `load(name)` of the first MAX_LOADS materials gives a
Material of that name whose table passes `Dataset.load`'s checks, in its declared
category; `load` of an unknown name is refused with an error naming it; declared
categories name only the dataset's materials; declared splits name only them, without
repeats, and are disjoint; declared weights are aligned with the names asked for
(`full=True` only: weight vectors may be fitted on first use).

A target that needs a parameter the call does not give, or raises a DataError (its data
is not on this machine, e.g. a release under ../shared), skips every check, saying why.
"""

from __future__ import annotations

import inspect
import unittest
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ..plugins import registry
from ..data import Dataset, check_table
from ..data.material_types import MERL_TYPES
from ..errors import BrdfbenchError, ConfigError, DataError
from ..protocols.representation import Material
from ..plugins.specs import DatasetSpec
from .checks import CheckSet
from .kit import Check, ConformanceReport
from ..pipeline.plan import check_params

#: Materials of the dataset the kit loads (tables are large: a MERL table is 35 MB).
MAX_LOADS = 2
#: Parameters the fingerprint check varies (each may load one more material).
MAX_VARIED = 3
UNKNOWN_NAME = "kit-no-such-material"


@dataclass
class Context:
    spec: DatasetSpec
    params: dict
    full: bool = False
    _dataset: Dataset | None = None
    _loaded: dict[str, Material] = field(default_factory=dict)

    def where(self, check: str) -> str:
        return f"dataset {self.spec.name!r}, {check}"

    def build(self, params: Mapping[str, Any] | None = None) -> Any:
        """The target's return value for `params` (the kit's own by default); SkipTest where
        it needs a parameter not given or its data is not here."""
        params = dict(self.params if params is None else params)
        factory = self.spec.load()
        missing = [p.name for p in _signature(factory) if p.default is p.empty and p.name not in params
                   and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        if missing:
            raise unittest.SkipTest(f"dataset {self.spec.name!r} needs dataset.params {', '.join(missing)}: "
                                    "pass them as params")
        check_params(factory, params, "dataset.params")
        try:
            return factory(**params)
        except DataError as exc:
            raise unittest.SkipTest(f"the data of dataset {self.spec.name!r} is not here: {exc}") from None

    @property
    def dataset(self) -> Dataset:
        if self._dataset is None:
            self._dataset = self.build()
        return self._dataset

    def load(self, name: str) -> Material:
        if name not in self._loaded:
            self._loaded[name] = self.dataset.load(name)
        return self._loaded[name]


def _signature(factory) -> list[inspect.Parameter]:
    try:
        return list(inspect.signature(factory).parameters.values())
    except (TypeError, ValueError):
        return []


CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


@check()
def check_builds(ctx: Context) -> None:
    w = ctx.where("builds")
    ds = ctx.dataset
    assert isinstance(ds, Dataset), f"{w}: {ctx.spec.target} returned a {type(ds).__name__}, not a brdfbench.data.Dataset"
    assert isinstance(ds.name, str) and ds.name, f"{w}: the dataset's name is {ds.name!r}"
    assert callable(ds.loader), f"{w}: loader is {ds.loader!r}, not a callable name -> Material"


@check()
def check_names_unique(ctx: Context) -> None:
    w = ctx.where("names_unique")
    names = ctx.dataset.materials
    assert isinstance(names, tuple), f"{w}: materials must be a tuple of names, not a {type(names).__name__}"
    assert names, f"{w}: the dataset has no material"
    bad = [n for n in names if not isinstance(n, str) or not n]
    assert not bad, f"{w}: material names must be non-empty strings, got {bad[:5]}"
    seen, repeated = set(), []
    for n in names:
        if n in seen:
            repeated.append(n)
        seen.add(n)
    assert not repeated, f"{w}: material names repeat: {sorted(set(repeated))[:5]}"


@check()
def check_fingerprint_stable(ctx: Context) -> None:
    """A non-empty string naming the content, the same from a second call with the same parameters."""
    w = ctx.where("fingerprint_stable")
    first = ctx.dataset.fingerprint
    assert isinstance(first, str) and first, f"{w}: fingerprint is {first!r}, not a non-empty string"
    again = ctx.build().fingerprint
    assert again == first, f"{w}: two calls with the same parameters give fingerprints {first!r} and {again!r}"


def _varied(ctx: Context) -> list[tuple[str, Any]]:
    """(parameter, other value) for the target's integer and float parameters, up to MAX_VARIED."""
    out = []
    for p in _signature(ctx.spec.load()):
        value = ctx.params.get(p.name, p.default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        out.append((p.name, value + 1 if isinstance(value, int) else (value / 2 if value else 0.5)))
    return out[:MAX_VARIED]


def _same_table(a: Material, b: Material) -> bool:
    return a.category == b.category and np.array_equal(a.table.raw, b.table.raw)


@check()
def check_fingerprint_tracks_params(ctx: Context) -> None:
    """Where a parameter changes what a material of the same name holds, the fingerprint changes."""
    w = ctx.where("fingerprint_tracks_params")
    ds = ctx.dataset
    compared = []
    for key, value in _varied(ctx):
        try:
            other = ctx.build({**ctx.params, key: value})
        except (ConfigError, DataError, unittest.SkipTest):
            continue  # not a value this dataset takes
        common = [n for n in ds.materials if n in set(other.materials)]
        if not common:
            continue  # other names altogether: no cell of one can pass for the other's
        name = common[0]
        compared.append(f"{key}={value!r}")
        if _same_table(ctx.load(name), other.load(name)):
            continue
        assert other.fingerprint != ds.fingerprint, (
            f"{w}: {key}={value!r} changes material {name!r}, but the fingerprint stays {ds.fingerprint!r}")
    if not compared:
        raise unittest.SkipTest(f"no numeric parameter of {ctx.spec.target} gives a material of the same name to compare")


@check()
def check_loads_materials(ctx: Context) -> None:
    """The first MAX_LOADS materials load as Materials of their names that pass `check_table`."""
    w = ctx.where("loads_materials")
    ds = ctx.dataset
    for name in ds.materials[:MAX_LOADS]:
        try:
            m = ctx.load(name)
        except BrdfbenchError as exc:
            raise AssertionError(f"{w}: load({name!r}) refused: {exc}") from None
        assert isinstance(m, Material), f"{w}: load({name!r}) returned a {type(m).__name__}, not a Material"
        assert m.name == name, f"{w}: load({name!r}) returned material {m.name!r}"
        try:
            check_table(m)
        except DataError as exc:  # a dataset that overrides load() may skip it
            raise AssertionError(f"{w}: {exc}") from None
        if ds.categories is not None and name in ds.categories:
            assert m.category == ds.categories[name], (
                f"{w}: {name!r} loads in category {m.category!r}, the dataset declares {ds.categories[name]!r}")


@check()
def check_unknown_name_refused(ctx: Context) -> None:
    w = ctx.where("unknown_name_refused")
    ds = ctx.dataset
    try:
        got = ds.load(UNKNOWN_NAME)
    except BrdfbenchError as exc:
        assert UNKNOWN_NAME in str(exc), f"{w}: the refusal of {UNKNOWN_NAME!r} does not name it: {exc}"
        return
    except Exception as exc:  # noqa: BLE001 - not the clear error asked for
        raise AssertionError(f"{w}: load({UNKNOWN_NAME!r}) raised {type(exc).__name__} ({exc}), not a DataError "
                             "naming it") from None
    raise AssertionError(f"{w}: load({UNKNOWN_NAME!r}) returned {getattr(got, 'name', got)!r}; an unknown name must be refused")


@check()
def check_categories_consistent(ctx: Context) -> None:
    w = ctx.where("categories_consistent")
    ds = ctx.dataset
    if ds.categories is None:
        raise unittest.SkipTest("the dataset declares no categories")
    assert isinstance(ds.categories, Mapping), f"{w}: categories must be a mapping name -> category"
    strangers = [n for n in ds.categories if n not in set(ds.materials)]
    assert not strangers, f"{w}: categories name materials the dataset does not have: {strangers[:5]}"
    bad = {n: c for n, c in ds.categories.items() if not isinstance(c, str) or not c}
    assert not bad, f"{w}: categories must be non-empty strings, got {dict(list(bad.items())[:5])}"


@check()
def check_types_and_descriptions(ctx: Context) -> None:
    """What conditional synthesis reads: each material's MERL types (none, one, or two for a
    mixture, each one of the 48) and a non-empty text description; declared ones name only
    the dataset's materials."""
    w = ctx.where("types_and_descriptions")
    ds = ctx.dataset
    members = set(ds.materials)
    for field_name in ("types", "descriptions"):
        declared = getattr(ds, field_name)
        strangers = [] if declared is None else [n for n in declared if n not in members]
        assert not strangers, f"{w}: {field_name} name materials the dataset does not have: {strangers[:5]}"
    for name in ds.materials:
        types = ds.material_types(name)
        assert isinstance(types, tuple) and len(types) <= 2, (
            f"{w}: material {name!r} has types {types!r}: a tuple of at most two (a mixture's two parents)")
        unknown = [t for t in types if t not in MERL_TYPES]
        assert not unknown, f"{w}: material {name!r} has types outside the MERL vocabulary: {unknown}"
        text = ds.description(name)
        assert isinstance(text, str) and text.strip(), f"{w}: material {name!r} has description {text!r}: not a text"


@check()
def check_splits_disjoint(ctx: Context) -> None:
    w = ctx.where("splits_disjoint")
    ds = ctx.dataset
    if ds.splits is None:
        raise unittest.SkipTest("the dataset declares no splits")
    assert isinstance(ds.splits, Mapping), f"{w}: splits must be a mapping split -> names"
    known = set(ds.materials)
    owner: dict[str, str] = {}
    for split, names in ds.splits.items():
        names = tuple(names)
        strangers = [n for n in names if n not in known]
        assert not strangers, f"{w}: split {split!r} names materials the dataset does not have: {strangers[:5]}"
        assert len(set(names)) == len(names), f"{w}: split {split!r} names a material twice"
        for n in names:
            assert n not in owner, f"{w}: material {n!r} is in split {owner[n]!r} and in split {split!r}"
            owner[n] = split


@check()
def check_weights_aligned(ctx: Context) -> None:
    """`weights(names)` gives one vector per name, in the order asked (full run only)."""
    w = ctx.where("weights_aligned")
    ds = ctx.dataset
    if ds.weights is None:
        raise unittest.SkipTest("the dataset provides no weight vectors")
    assert callable(ds.weights), f"{w}: weights must be a callable names -> WeightSet"
    if not ctx.full:
        raise unittest.SkipTest("weight vectors may be fitted on first use: full=True (brdfbench check --full) reads them")
    names = tuple(reversed(ds.materials[:MAX_LOADS]))
    ws = ds.weights(names)
    assert tuple(ws.names) == names, f"{w}: weights({list(names)}) returned vectors of {list(ws.names)}"
    vectors = np.asarray(ws.vectors)
    assert vectors.ndim == 2 and vectors.shape[0] == len(names), (
        f"{w}: weights({list(names)}) returned an array of shape {vectors.shape}")
    assert np.isfinite(vectors).all(), f"{w}: weights({list(names)}) holds non-finite values"


# --------------------------------------------------------------------------- running


def _resolve(spec_or_name: DatasetSpec | str) -> DatasetSpec:
    if isinstance(spec_or_name, DatasetSpec):
        return spec_or_name
    return registry.get("datasets", spec_or_name)


def dataset_checks(spec_or_name, params: dict | None = None, *, full: bool = False) -> list[Check]:
    """The checks of a dataset, sharing one built dataset (and the materials it loaded)."""
    spec = _resolve(spec_or_name)
    ctx = Context(spec, dict(params or {}), full)
    return [Check(spec.name, name, (lambda fn=fn: fn(ctx)), spec.xfail_checks.get(name))
            for name, (requires, fn) in CHECKS.items() if requires <= spec.tags]


def check_dataset(spec_or_name, params: dict | None = None, *, full: bool = False) -> ConformanceReport:
    """Run every check; failures are collected, not raised (see raise_on_failure)."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name, params=dict(params or {}))
    for c in dataset_checks(spec, params, full=full):
        report.run(c)
    return report
