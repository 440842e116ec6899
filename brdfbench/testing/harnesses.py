"""Conformance checks for harness plugins, in the style of `check_representation`.

    from brdfbench.testing import check_harness
    check_harness("my_harness").raise_on_failure()

The kit builds the harness's config as `harness=<name>` does (its shipped option's values,
then the Config's defaults), with integer sizes above QUICK_INT that have a range (`min`)
cut to QUICK_INT in the quick run (`n_random`, batch sizes: the smallest settings that
still measure something); `params` override keys; `full=True` keeps the sizes.

Checks: the spec loads a `Harness` subclass of a known scope and plugin group, named as
the spec; `Config` is a frozen `HarnessConfig` dataclass whose `kind` defaults to the
spec's name; `from_dict` refuses an unknown key and a bad value (wrong type, out of range,
not a choice) with a ConfigError naming the key; `hashed()` leaves out every RUN_CONTROL
key (changing one leaves the configuration hash as it is) and is stable (two configs from
the same keys hash alike; another dtype hashes apart); `domains` are metric domains a
harness feeds; `validate` accepts the harness's own config on a registered scene of the
kind it needs and refuses a metric of a foreign domain, naming it.

A material-scope harness of representations is then built from a `HarnessContext` and
measures `KitDiffuse` (a Lambertian of fixed albedo) on `kit_material()` (a MERL table made
in memory: Lambertian plus a lobe in θh, 1 % of its cells invalid): a list of `Measurement`
with finite values, a unit and a bool `higher_is_better`, the same for the same seed
(timings, in seconds or per second, exempt). A harness that renders (`rendered`) measures
with `full=True` only; a set-scope harness (trained generators, `plan_sets` / `train` /
`measure_set`) is measured by the pipeline, not the kit: both are reported skipped, saying
why.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import typing
import unittest
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..plugins import registry
from ..data import Dataset
from ..errors import ConfigError
from ..harness import DTYPES, Harness, HarnessConfig, HarnessContext, Measurement
from ..merl import SHAPE, MerlTable
from ..protocols.metric import DOMAINS
from ..protocols.representation import Material, Representation
from ..provenance import config_hash
from ..plugins.specs import HarnessSpec
from .checks import CheckSet
from .kit import Check, ConformanceReport
from ..pipeline.harness_defaults import shipped_defaults

#: Quick run: integer sizes with a `min` range are cut to this (never below their minimum).
QUICK_INT = 1024
SCOPES = ("material", "set")
PLUGIN_GROUPS = ("representations", "generators")
#: Seed of the kit's harness context (both sides of the determinism check use it).
SEED = 0
#: A key no harness config has, for the unknown-key check.
UNKNOWN_KEY = "kit_unknown_key"


class KitDiffuse(Representation):
    """A Lambertian of fixed albedo: the model the kit measures (nothing to fit, nothing random)."""

    tags = frozenset({"fittable", "reciprocal", "isotropic"})

    def __init__(self, albedo: float = 0.45):
        super().__init__(albedo=albedo)
        self.value = torch.full((3,), albedo / math.pi, dtype=torch.float64)

    def _eval(self, wi, wo):
        return self.value.to(wi.dtype).expand(wi.shape[0], 3).clone()

    def fit(self, target, *, seed=0):
        return self

    def state_dict(self):
        return {"value": self.value}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        model.value = tensors["value"].double()
        return model


@lru_cache(maxsize=1)
def kit_material() -> Material:
    """A MERL table made in memory: a Lambertian base (albedo 0.5, 0.4, 0.3) and a lobe in θh,
    so that what a harness measures depends on the directions it draws; a seeded 1 % of the
    cells invalid."""
    theta_h = ((np.arange(SHAPE[0]) + 0.5) / SHAPE[0]) ** 2 * (np.pi / 2)  # MERL's θh cell centres
    lobe = 2.0 * np.exp(-((theta_h / 0.15) ** 2))
    values = np.array([0.5, 0.4, 0.3]).reshape(3, 1, 1, 1) / np.pi + lobe.reshape(1, -1, 1, 1)
    valid = np.random.default_rng(0).random(SHAPE) >= 0.01
    table = MerlTable.from_values(np.broadcast_to(values, (3, *SHAPE)), valid)
    return Material("kit-glossy", table, "plastic", source="brdfbench.testing.harnesses")


def kit_dataset() -> Dataset:
    material = kit_material()
    return Dataset("kit", (material.name,), lambda name: material, "brdfbench-testing-kit-v1",
                   {material.name: material.category})


@dataclass
class Context:
    spec: HarnessSpec
    params: dict
    full: bool = False
    _tmp: Any = field(default=None, repr=False)
    _measured: list | None = None

    @property
    def cls(self) -> type:
        return self.spec.load()

    def where(self, check: str) -> str:
        return f"harness {self.spec.name!r}, {check}"

    def values(self) -> dict[str, Any]:
        """The keys of the kit's config: shipped option, quick sizes, `params`, and `kind`."""
        shipped = shipped_defaults(self.spec.name)
        quick = {} if self.full else _quick_sizes(self.cls.Config, shipped)
        return {**shipped, **quick, **self.params, "kind": self.spec.name}

    def config(self, **changes: Any) -> HarnessConfig:
        return self.cls.Config.from_dict({**self.values(), **changes})

    def metric_specs(self, config) -> list:
        specs = []
        for name in config.metrics:
            try:
                specs.append(registry.get("metrics", name))
            except Exception as exc:  # noqa: BLE001 - named in the check's message
                raise AssertionError(f"{self.where('config')}: the config's metric {name!r} does not resolve: {exc}") from None
        return specs

    def scene(self, validated: bool = True):
        """The first registered scene the harness's kind needs (rendered or not) on which
        `validate` accepts its own config (or, not `validated`, the first of that kind)."""
        cls, config = self.cls, self.config()
        specs = self.metric_specs(config)
        refusals = []
        for name in registry.names("scenes"):
            try:
                scene = registry.get("scenes", name).load()()
            except Exception:  # noqa: BLE001 - a scene that needs parameters is not for the kit
                continue
            if scene.needs_rendering != bool(cls.rendered):
                continue
            if not validated:
                return scene
            try:
                cls.validate(config, scene, specs)
            except ConfigError as exc:
                refusals.append(f"{name}: {exc}")
                continue
            return scene
        kind = "rendered" if cls.rendered else "unrendered"
        raise AssertionError(f"{self.where('validate')}: validate refuses the harness's own config on every registered "
                             f"{kind} scene" + (f" ({'; '.join(refusals)})" if refusals else " (there is none)"))

    def build(self) -> Harness:
        """The harness built as a worker builds it, from its config and a context of the kit's data."""
        config = self.config()
        scene = self.scene()
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="brdfbench-harness-kit-")
        data = kit_dataset()
        context = HarnessContext(
            scene=scene, metric_specs=self.metric_specs(config), seed=SEED, results_dir=Path(self._tmp.name),
            dataset_fingerprint=data.fingerprint, representation="kit_diffuse", representation_params={},
            scene_name=scene.name, scene_params={}, dataset=data, label="kit",
        )
        return self.cls(config, context)

    def measure(self) -> list:
        return self.build().measure(KitDiffuse(), kit_material(), "kit")

    def hash_of(self, config) -> str:
        return config_hash(self.cls.key(config, self.scene(validated=False).name, {}))


def _quick_sizes(config_cls: type, shipped: dict[str, Any]) -> dict[str, Any]:
    """Integer keys with a `min` range whose value exceeds QUICK_INT, cut to QUICK_INT."""
    if not dataclasses.is_dataclass(config_cls):
        return {}
    out = {}
    for f in dataclasses.fields(config_cls):
        value = shipped.get(f.name, f.default)
        if "min" in f.metadata and isinstance(value, int) and not isinstance(value, bool) and value > QUICK_INT:
            out[f.name] = max(QUICK_INT, f.metadata["min"])
    return out


CHECKS: CheckSet[Context] = CheckSet()
check = CHECKS.register


@check()
def check_protocol(ctx: Context) -> None:
    w = ctx.where("protocol")
    cls = ctx.cls
    assert isinstance(cls, type) and issubclass(cls, Harness), f"{w}: {ctx.spec.target} is not a brdfbench.harness.Harness subclass"
    assert getattr(cls, "name", None) == ctx.spec.name, f"{w}: {cls.__name__}.name is {getattr(cls, 'name', None)!r}, the spec's name {ctx.spec.name!r}"
    assert cls.scope in SCOPES, f"{w}: scope {cls.scope!r} is not one of {', '.join(SCOPES)}"
    assert cls.plugin_group in PLUGIN_GROUPS, f"{w}: plugin_group {cls.plugin_group!r} is not one of {', '.join(PLUGIN_GROUPS)}"
    needed = ("measure",) if cls.scope == "material" else ("plan_sets", "train", "measure_set")
    missing = [m for m in needed if getattr(cls, m) is getattr(Harness, m)]
    assert not missing, f"{w}: a {cls.scope}-scope harness implements {', '.join(needed)}; {cls.__name__} lacks {', '.join(missing)}"


@check()
def check_config_frozen(ctx: Context) -> None:
    """A frozen HarnessConfig dataclass: a job's config cannot change under its hash."""
    w = ctx.where("config_frozen")
    config_cls = ctx.cls.Config
    assert isinstance(config_cls, type) and issubclass(config_cls, HarnessConfig), (
        f"{w}: Config {config_cls!r} is not a brdfbench.harness.HarnessConfig subclass")
    assert dataclasses.is_dataclass(config_cls) and config_cls.__dataclass_params__.frozen, (
        f"{w}: {config_cls.__name__} must be a @dataclass(frozen=True)")
    config = ctx.config()
    try:
        setattr(config, "kind", "changed")
    except dataclasses.FrozenInstanceError:
        return
    raise AssertionError(f"{w}: assigning {config_cls.__name__}().kind was accepted: the config is not frozen")


@check()
def check_config_kind_is_name(ctx: Context) -> None:
    """`kind` defaults to the spec's name: `harness.kind` selects the harness by it."""
    w = ctx.where("config_kind_is_name")
    config_cls = ctx.cls.Config
    fields = {f.name: f for f in dataclasses.fields(config_cls)} if dataclasses.is_dataclass(config_cls) else {}
    assert "kind" in fields, f"{w}: {getattr(config_cls, '__name__', config_cls)} has no field 'kind'"
    default = fields["kind"].default
    assert default == ctx.spec.name, f"{w}: {config_cls.__name__}.kind defaults to {default!r}, not {ctx.spec.name!r}"
    config = ctx.config()
    assert config.kind == ctx.spec.name, f"{w}: from_dict(kind={ctx.spec.name!r}) built kind={config.kind!r}"


@check()
def check_unknown_key_refused(ctx: Context) -> None:
    w = ctx.where("unknown_key_refused")
    try:
        ctx.config(**{UNKNOWN_KEY: 1})
    except ConfigError as exc:
        assert UNKNOWN_KEY in str(exc), f"{w}: the refusal of harness.{UNKNOWN_KEY} does not name it: {exc}"
        return
    except Exception as exc:  # noqa: BLE001 - not the one-line, exit-2 error asked for
        raise AssertionError(f"{w}: harness.{UNKNOWN_KEY} raised {type(exc).__name__} ({exc}), not a ConfigError") from None
    raise AssertionError(f"{w}: from_dict accepted the unknown key harness.{UNKNOWN_KEY}")


def _bad_values(config_cls: type) -> list[tuple[str, Any, str]]:
    """(key, value, what) a typed config must refuse: a wrong type for each key whose type
    the config checks, a value below each `min` (or at a `min_exclusive`), one outside each
    `choices`."""
    hints = typing.get_type_hints(config_cls)
    out = []
    for f in dataclasses.fields(config_cls):
        hint = hints.get(f.name)
        args = typing.get_args(hint)
        if type(None) in args:
            rest = [a for a in args if a is not type(None)]
            hint = rest[0] if len(rest) == 1 else None
        origin = typing.get_origin(hint) or hint
        if origin in (bool, int, float, str, tuple, list):
            out.append((f.name, {"kit": "bad"}, "a mapping"))
        elif origin is dict:
            out.append((f.name, 7, "a number"))
        if "min" in f.metadata and origin in (int, float):
            out.append((f.name, f.metadata["min"] - 1, "below its minimum"))
        if "min_exclusive" in f.metadata and origin in (int, float):
            out.append((f.name, f.metadata["min_exclusive"], "at its exclusive minimum"))
        if "choices" in f.metadata:
            out.append((f.name, "kit-not-a-choice", "not one of its choices"))
    return out


@check()
def check_bad_values_refused(ctx: Context) -> None:
    """A bad value fails before any work, as a ConfigError (one line, exit 2) naming the key."""
    w = ctx.where("bad_values_refused")
    for key, value, what in _bad_values(ctx.cls.Config):
        try:
            ctx.config(**{key: value})
        except ConfigError as exc:
            assert key in str(exc), f"{w}: harness.{key}={value!r} ({what}) refused without naming the key: {exc}"
            continue
        except Exception as exc:  # noqa: BLE001
            raise AssertionError(f"{w}: harness.{key}={value!r} ({what}) raised {type(exc).__name__} ({exc}), "
                                 "not a ConfigError naming the key") from None
        raise AssertionError(f"{w}: harness.{key}={value!r} ({what}) was accepted")


def _other_value(value: Any) -> Any:
    """Another valid-looking value of the same type (None where the kit cannot tell one)."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return 2 * value if value else 1.0
    return None


@check()
def check_hash_excludes_run_control(ctx: Context) -> None:
    """RUN_CONTROL keys (time limits, memory, what is saved beside the figures) never enter
    the configuration hash: changing one must not make finished cells look new."""
    w = ctx.where("hash_excludes_run_control")
    config = ctx.config()
    run_control = tuple(type(config).RUN_CONTROL)
    names = {f.name for f in dataclasses.fields(config)}
    stray = [k for k in run_control if k not in names]
    assert not stray, f"{w}: RUN_CONTROL names {stray}, which are not config keys"
    hashed = config.hashed()
    leaked = [k for k in run_control if k in hashed]
    assert not leaked, f"{w}: hashed() includes the run-control keys {leaked}"
    base = ctx.hash_of(config)
    for key in run_control:
        other = _other_value(getattr(config, key))
        if other is None:
            continue
        try:
            changed = ctx.config(**{key: other})
        except ConfigError:
            continue
        assert ctx.hash_of(changed) == base, f"{w}: changing the run-control key {key} to {other!r} changes the configuration hash"


@check()
def check_hash_stable(ctx: Context) -> None:
    """Two configs from the same keys hash alike; a config of another dtype hashes apart."""
    w = ctx.where("hash_stable")
    a, b = ctx.config(), ctx.config()
    assert a.hashed() == b.hashed(), f"{w}: two configs from the same keys give hashed() {a.hashed()} and {b.hashed()}"
    ha, hb = ctx.hash_of(a), ctx.hash_of(b)
    assert ha == hb, f"{w}: two configs from the same keys hash to {ha} and {hb}"
    other = next(d for d in DTYPES if d != a.dtype)
    try:
        c = ctx.config(dtype=other)
    except ConfigError:
        return  # the harness takes one dtype only
    assert ctx.hash_of(c) != ha, f"{w}: dtype={other} hashes as dtype={a.dtype}: hashed() leaves out what is measured"


@check()
def check_domains_known(ctx: Context) -> None:
    w = ctx.where("domains_known")
    domains = ctx.cls.domains
    assert isinstance(domains, tuple), f"{w}: domains must be a tuple of metric domains, got {domains!r}"
    unknown = [d for d in domains if d not in DOMAINS]
    assert not unknown, f"{w}: domains {unknown} are none a metric declares; known: {', '.join(DOMAINS)}"


@check()
def check_validate_refuses_foreign_metric(ctx: Context) -> None:
    """`validate` accepts the harness's own config and refuses a metric of a domain it does
    not measure on, naming the metric (before any work, not mid-run)."""
    w = ctx.where("validate_refuses_foreign_metric")
    cls, config = ctx.cls, ctx.config()
    scene = ctx.scene()  # one on which validate accepts the config as it is
    foreign = None
    for name in registry.names("metrics"):
        spec = registry.get("metrics", name)
        try:
            domain = getattr(spec.load(), "domain", None)
        except Exception:  # noqa: BLE001 - a broken metric is its own kit's business
            continue
        if domain in DOMAINS and domain not in cls.domains:
            foreign = spec
            break
    if foreign is None:
        raise unittest.SkipTest(f"every registered metric is of a domain {cls.__name__} measures on")
    try:
        cls.validate(config, scene, ctx.metric_specs(config) + [foreign])
    except ConfigError as exc:
        assert foreign.name in str(exc), f"{w}: the refusal of metric {foreign.name!r} does not name it: {exc}"
        return
    raise AssertionError(f"{w}: validate accepted metric {foreign.name!r} (domain {domain!r}) on scene {scene.name!r}; "
                         f"the harness measures on {', '.join(cls.domains) or 'no metric domain'}")


def _measured_here(ctx: Context) -> None:
    """Skip, saying why, where the kit does not measure the harness."""
    cls = ctx.cls
    if cls.scope != "material":
        raise unittest.SkipTest(f"{cls.__name__} scores sets of a trained generator (plan_sets, train, measure_set): "
                                "the pipeline measures it, not the kit")
    if cls.plugin_group != "representations":
        raise unittest.SkipTest(f"{cls.__name__} measures {cls.plugin_group}, the kit measures a representation")
    if cls.rendered and not ctx.full:
        raise unittest.SkipTest(f"{cls.__name__} renders a scene: full=True (brdfbench check --full) measures it")


def _timing(m: Measurement) -> bool:
    return m.unit == "s" or m.unit.endswith("/s")


@check()
def check_measures(ctx: Context) -> None:
    """A list of Measurement: a named metric, a finite value, a unit and a bool direction."""
    _measured_here(ctx)
    w = ctx.where("measures")
    out = ctx.measure()
    assert isinstance(out, list) and out, f"{w}: measure returned {out!r}, not a non-empty list of Measurement"
    for m in out:
        assert isinstance(m, Measurement), f"{w}: measure returned a {type(m).__name__}, not a Measurement"
        assert isinstance(m.metric, str) and m.metric, f"{w}: a measurement has metric name {m.metric!r}"
        value_ok = isinstance(m.value, (int, float)) and not isinstance(m.value, bool)
        assert value_ok and math.isfinite(m.value), f"{w}: {m.metric} = {m.value!r}, not a finite number"
        assert isinstance(m.unit, str) and m.unit, f"{w}: {m.metric} has unit {m.unit!r}"
        assert isinstance(m.higher_is_better, bool), f"{w}: {m.metric}.higher_is_better is {m.higher_is_better!r}, not a bool"
    ctx._measured = out


@check()
def check_measure_deterministic(ctx: Context) -> None:
    """A second harness built with the same seed measures the same values (timings exempt)."""
    _measured_here(ctx)
    w = ctx.where("measure_deterministic")
    first = ctx._measured if ctx._measured is not None else ctx.measure()
    second = ctx.measure()
    a = {m.metric: m.value for m in first if not _timing(m)}
    b = {m.metric: m.value for m in second if not _timing(m)}
    assert set(a) == set(b), f"{w}: the same seed measured {sorted(a)} then {sorted(b)}"
    differ = {k: (a[k], b[k]) for k in a if a[k] != b[k]}
    assert not differ, f"{w}: the same seed measured different values: " + ", ".join(
        f"{k} {x!r} then {y!r}" for k, (x, y) in differ.items())


# --------------------------------------------------------------------------- running


def _resolve(spec_or_name: HarnessSpec | str) -> HarnessSpec:
    if isinstance(spec_or_name, HarnessSpec):
        return spec_or_name
    return registry.get("harnesses", spec_or_name)


def harness_checks(spec_or_name, *, params: dict | None = None, full: bool = False) -> list[Check]:
    """The checks of a harness, sharing one context; `params` override config keys."""
    spec = _resolve(spec_or_name)
    ctx = Context(spec, dict(params or {}), full)
    return [Check(spec.name, name, (lambda fn=fn: fn(ctx)), spec.xfail_checks.get(name))
            for name, (requires, fn) in CHECKS.items() if requires <= spec.tags]


def check_harness(spec_or_name, *, params: dict | None = None, full: bool = False) -> ConformanceReport:
    """Run every check; failures are collected, not raised (see raise_on_failure)."""
    spec = _resolve(spec_or_name)
    report = ConformanceReport(spec.name, params=dict(params or {}))
    for c in harness_checks(spec, params=params, full=full):
        report.run(c)
    return report
