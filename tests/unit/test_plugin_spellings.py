"""A built-in plugin's name is written in three places and its defaults in two or three; these
tests prove the spellings agree, so a rename or a changed default made in one place fails here
instead of drifting.

The places: the entry point in pyproject.toml (`[project.entry-points."brdfbench.<group>"]`,
name = "module:SPEC"), the spec's `name`, and the Hydra option in conf/<group>/*.yaml
(`name:`; `kind:` for a harness); defaults in the constructor (or the Recipe / Config
dataclass behind its keyword defaults) and in the option's values.

What "agree" means, per group:

- entry points: every name equals the `name` of the spec it points to, the spec's attribute is
  the name in capitals, and the installed metadata lists the same entry points as pyproject.toml
  (the registry reads the installed metadata: reinstall with `pip install -e .` otherwise).
- representation, generator, dataset, scene options: the option whose file stem is the plugin's
  name is its *main* option; any other is a *variant* named `<name>_<what>` (merl_trilinear,
  nbrdf_brief, ...), which may take the main option through its defaults list. custom.yaml alone
  is a chooser for any plugin (`name: ???`). Every built-in plugin of these groups has a main
  option, save those CONFIG_LESS lists with a reason.
- params: every key under `params:` is a keyword of the plugin's constructor (the factory of a
  dataset or scene). A main option builds what the defaults build: for representations and
  generators the resolved `params` of `spec.create(**params)` equal those of `spec.create()`
  (so a `None` keyword that resolves to a Recipe default counts as that default); for datasets
  and scenes the values equal the factory's keyword defaults. MAIN_DIFFERENCES lists the
  deliberate exceptions, each with a reason and a check of the value it must hold.
- a variant differs from its main option in exactly the keys VARIANTS lists for it (compared on
  the resolved values): a variant that says "the rest as X.yaml" and drifted fails, and so
  does a stale entry.
- harness options: `kind:` names a registered harness and `harness_config(kind, **keys)`
  accepts every key (null `sampler_params` dropped first by `harness_defaults.unset_nulls`,
  as the CLI drops them). The option named after the kind (accuracy.yaml, render.yaml, ...)
  is the kind's main option, whose values equal its
  Config dataclass's defaults except HARNESS_DIFFERENCES; the other harness options are
  variants of a kind's main option, as above.
"""

from __future__ import annotations

import dataclasses
import inspect
import tomllib
from importlib.metadata import distribution
from pathlib import Path
from typing import Any, Callable

import pytest
from omegaconf import OmegaConf

from brdfbench.plugins import registry
from brdfbench.pipeline.config import harness_class, harness_config
from brdfbench.pipeline.harness_defaults import unset_nulls
from brdfbench.plugins.specs import import_target

REPO = Path(__file__).resolve().parents[2]
CONF = REPO / "conf"
#: conf group -> registry group, for the groups whose options name a plugin with `name:`
NAMED_GROUPS = {"representation": "representations", "generator": "generators", "dataset": "datasets",
                "scene": "scenes"}
#: the chooser options: any registered plugin, named on the command line
CHOOSERS = {("representation", "custom")}

#: Built-in plugins with no option in conf/, with the reason (none at present).
CONFIG_LESS: dict[tuple[str, str], str] = {}

#: Deliberate differences of a main option from the constructor's defaults:
#: (group, option, key) -> (reason, check of the option's value).
MAIN_DIFFERENCES: dict[tuple[str, str, str], tuple[str, Callable[[Any], bool]]] = {
    ("dataset", "merl_folder", "path"): (
        "required, no default: '???' makes Hydra ask for the folder", lambda v: v == "???"),
    ("dataset", "augmerl", "base_params"): (
        "None is the base's own defaults; the option lists the bases' keys, each null, to document them",
        lambda v: isinstance(v, dict) and all(x is None for x in v.values())),
    ("dataset", "neumerl", "base_params"): (
        "as augmerl's: every key null, the base's own default",
        lambda v: isinstance(v, dict) and all(x is None for x in v.values())),
    ("scene", "sphere_directional", "lights"): (
        "None means scenes.DEFAULT_LIGHTS; the option writes the two lights out", lambda v: v == _default_lights()),
}

#: Each variant option: the keys whose resolved values differ from its main option's, and why.
VARIANTS: dict[tuple[str, str], tuple[frozenset[str], str]] = {
    ("representation", "merl_downsampled"): (frozenset({"downsample"}), "the sparse-reconstruction baseline"),
    ("representation", "merl_trilinear"): (frozenset({"mode"}), "trilinear interpolation instead of the nearest cell"),
    **{("representation", f"{name}_brief"): (frozenset({"epochs", "n_samples"}), "the first look's brief recipe")
       for name in ("nbrdf", "naive_mlp", "tripleplane", "triplane_gated")},
    ("representation", "nbrdf_equal_flops"): (frozenset({"hidden"}), "Timonen et al.'s equal-FLOP budget"),
    ("representation", "naive_mlp_equal_flops"): (frozenset({"hidden"}), "Timonen et al.'s equal-FLOP budget"),
    ("representation", "nbrdf_reference"): (
        frozenset({"epochs", "batch_size", "lr", "schedule", "output", "patience", "batch_materials"}),
        "Sztrajman et al.'s published recipe (nbrdf_fit.REFERENCE_RECIPE), one material at a time"),
    **{("representation", f"{name}_paper"): (
        frozenset({"iterations", "resample", "sampling", "batch_size", "n_samples", "lr", "texture_lr", "schedule",
                   "loss", "beta1", "ema"}),
        "Timonen et al.'s training recipe (sized for a GPU); the model stays the default")
       for name in ("tripleplane", "triplane_gated")},
    ("generator", "hyperdiffusion_paper"): (
        frozenset({"chunk_size", "d_model", "layers", "heads", "epochs", "batch_size", "ddim_steps", "prior",
                   "max_cpu_hours"}),
        "NeuMaDiff at the published size and prior (sized for a GPU, refused on a slow CPU)"),
    ("dataset", "synthetic_first_look"): (frozenset({"size"}), "the first look's 12 materials"),
    ("harness", "first_look"): (frozenset({"n_random", "throughput_batch"}), "the first look's lighter harness"),
    ("harness", "quick"): (frozenset({"n_random", "throughput_batch"}), "a lighter harness for smoke runs"),
    ("harness", "default"): (frozenset(), "harness=default is the accuracy harness as shipped"),
}

#: Deliberate differences of a harness kind's main option from its Config dataclass's defaults:
#: (kind, key) -> (reason, check of the option's value).
HARNESS_DIFFERENCES: dict[tuple[str, str], tuple[str, Callable[[Any], bool]]] = {
    **{(kind, "metrics"): (
        "the Config's () is the fallback of a kind without an option; the option lists the metrics scored "
        "(the core names no metric)", lambda v: len(v) > 0)
       for kind in ("accuracy", "render", "convergence")},
    ("render", "display_spp"): (
        "the report's display renders are on as shipped (README: 256 by default); the Config's None is the "
        "fallback without an option", lambda v: v == 256),
}


# --------------------------------------------------------------------------- reading the sources


def _default_lights():
    from brdfbench.scenes import DEFAULT_LIGHTS

    return _plain(DEFAULT_LIGHTS)


def _plain(value: Any) -> Any:
    """Tuples as lists, recursively, so a dataclass or constructor value compares with YAML's."""
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _pyproject_entry_points() -> dict[str, dict[str, str]]:
    """registry group -> {name: "module:ATTR"} from pyproject.toml."""
    with open(REPO / "pyproject.toml", "rb") as f:
        tables = tomllib.load(f)["project"]["entry-points"]
    return {group.removeprefix("brdfbench."): dict(eps) for group, eps in tables.items()
            if group.startswith("brdfbench.")}


def _is_global(path: Path) -> bool:
    return any(line.strip() == "# @package _global_" for line in path.read_text(encoding="utf-8").splitlines()[:5])


def option(group: str, stem: str, seen: tuple[str, ...] = ()) -> dict[str, Any]:
    """An option of a conf group as Hydra composes it: its defaults list's options of the same
    group merged where `_self_` stands (at the end where it is absent); a `_global_` option
    gives its `<group>` mapping. Interpolations stay unresolved."""
    assert stem not in seen, f"conf/{group}/{stem}.yaml includes itself through its defaults list"
    path = CONF / group / f"{stem}.yaml"
    own = OmegaConf.to_container(OmegaConf.load(path), resolve=False) or {}
    defaults = own.pop("defaults", [])
    if _is_global(path):
        own = own.get(group) or {}
    parts = []
    for entry in defaults:
        if entry == "_self_":
            parts.append(own)
        elif isinstance(entry, str):
            parts.append(option(group, entry, (*seen, stem)))
        # mappings (`override /dataset: neumerl`) choose options of other groups
    if "_self_" not in defaults:
        parts.append(own)
    return OmegaConf.to_container(OmegaConf.merge(*parts), resolve=False) if parts else {}


def stems(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


BUILT_IN = _pyproject_entry_points()
NAMED_OPTIONS = [(g, s) for g in NAMED_GROUPS for s in stems(g) if (g, s) not in CHOOSERS]


def _resolved(group: str, name: str, params: dict[str, Any]) -> dict[str, Any]:
    """What the plugin makes of these params: the constructed model's `params` (representations,
    generators), else the factory's keyword defaults overlaid with them (nothing is built)."""
    spec = registry.get(NAMED_GROUPS[group], name)
    if group in ("representation", "generator"):
        return _plain(spec.create(**params).params)
    defaults = {k: p.default for k, p in inspect.signature(spec.load()).parameters.items()
                if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD}
    return _plain({**defaults, **params})


# --------------------------------------------------------------------------- entry points


def test_pyproject_groups_are_the_registrys():
    assert set(BUILT_IN) <= set(registry.GROUPS), f"unknown groups: {sorted(set(BUILT_IN) - set(registry.GROUPS))}"


@pytest.mark.parametrize("group", sorted(BUILT_IN))
def test_every_entry_point_name_is_its_specs_name(group):
    for name, value in BUILT_IN[group].items():
        spec = import_target(value)
        assert spec.name == name, f"entry point {group}:{name} = {value!r} names itself {spec.name!r}"
        assert value.rpartition(":")[2] == name.upper(), f"entry point {group}:{name}: the spec {value!r} is not {name.upper()}"
        assert registry.get(group, name) is spec


def test_installed_entry_points_are_pyprojects():
    installed = {(ep.group.removeprefix("brdfbench."), ep.name, ep.value) for ep in distribution("brdfbench").entry_points
                 if ep.group.startswith("brdfbench.") and ep.group.removeprefix("brdfbench.") in registry.GROUPS}
    declared = {(g, n, v) for g, eps in BUILT_IN.items() for n, v in eps.items()}
    assert installed == declared, (f"installed metadata differs from pyproject.toml (reinstall: pip install -e .): "
                                   f"only installed {sorted(installed - declared)}, only declared {sorted(declared - installed)}")


# --------------------------------------------------------------------------- named options


@pytest.mark.parametrize("group, stem", NAMED_OPTIONS, ids=[f"{g}/{s}" for g, s in NAMED_OPTIONS])
def test_an_option_names_a_built_in_plugin_and_its_keywords(group, stem):
    cfg = option(group, stem)
    name = cfg.get("name")
    where = f"conf/{group}/{stem}.yaml"
    assert name in BUILT_IN[NAMED_GROUPS[group]], f"{where}: name {name!r} is not a built-in {group}"
    assert stem == name or stem.startswith(f"{name}_"), f"{where}: a variant of {name!r} is named {name}_<what>"
    allowed = {"name", "params"} | ({"label"} if group in ("representation", "generator") else set())
    assert set(cfg) <= allowed, f"{where}: unknown keys {sorted(set(cfg) - allowed)}"
    params = cfg.get("params") or {}
    target = registry.get(NAMED_GROUPS[group], name).load()
    keywords = {k for k, p in inspect.signature(target).parameters.items()
                if p.kind is p.KEYWORD_ONLY or p.kind is p.POSITIONAL_OR_KEYWORD}
    unknown = sorted(set(params) - keywords)
    assert not unknown, f"{where}: params {unknown} are not keywords of {target.__qualname__} ({sorted(keywords)})"
    if group in ("representation", "generator"):
        assert set(params) <= set(_resolved(group, name, params)), f"{where}: a key is not kept in the model's params"


def test_custom_is_the_only_chooser():
    cfg = option("representation", "custom")
    assert cfg["name"] == "???" and cfg["params"] == {}


@pytest.mark.parametrize("group", sorted(NAMED_GROUPS))
def test_every_built_in_plugin_has_a_main_option(group):
    have = set(stems(group))
    for name in BUILT_IN[NAMED_GROUPS[group]]:
        if (group, name) in CONFIG_LESS:
            assert name not in have, f"conf/{group}/{name}.yaml exists: drop it from CONFIG_LESS"
            continue
        assert name in have, f"built-in {group} {name!r} has no conf/{group}/{name}.yaml (or a CONFIG_LESS entry)"


MAINS = [(g, s) for g, s in NAMED_OPTIONS if option(g, s).get("name") == s]


@pytest.mark.parametrize("group, stem", MAINS, ids=[f"{g}/{s}" for g, s in MAINS])
def test_a_main_option_is_the_plugins_defaults(group, stem):
    params = option(group, stem).get("params") or {}
    built = _resolved(group, stem, params)
    default = _resolved(group, stem, {})
    for key, value in params.items():
        listed = MAIN_DIFFERENCES.get((group, stem, key))
        if listed is not None:
            reason, holds = listed
            assert holds(_plain(value)), f"conf/{group}/{stem}.yaml: {key}={value!r} is not what MAIN_DIFFERENCES says ({reason})"
            continue
        assert built[key] == default[key], (f"conf/{group}/{stem}.yaml: {key}={value!r} builds {built[key]!r}, the "
                                            f"constructor's default builds {default[key]!r}")
    assert {k: v for k, v in built.items() if (group, stem, k) not in MAIN_DIFFERENCES} == \
        {k: v for k, v in default.items() if (group, stem, k) not in MAIN_DIFFERENCES}


def test_main_differences_are_main_option_keys():
    for group, stem, key in MAIN_DIFFERENCES:
        assert key in (option(group, stem).get("params") or {}), f"MAIN_DIFFERENCES: {group}/{stem} has no {key}"


VARIANT_OPTIONS = [(g, s) for g, s in NAMED_OPTIONS if (g, s) not in MAINS]


@pytest.mark.parametrize("group, stem", VARIANT_OPTIONS, ids=[f"{g}/{s}" for g, s in VARIANT_OPTIONS])
def test_a_variant_differs_from_its_main_option_where_listed(group, stem):
    assert (group, stem) in VARIANTS, f"conf/{group}/{stem}.yaml: a variant VARIANTS does not list"
    keys, reason = VARIANTS[(group, stem)]
    name = option(group, stem)["name"]
    variant = _resolved(group, name, option(group, stem).get("params") or {})
    main = _resolved(group, name, option(group, name).get("params") or {})
    differ = {k for k in set(variant) | set(main) if variant.get(k) != main.get(k)}
    assert differ == keys, (f"conf/{group}/{stem}.yaml ({reason}) differs from {name}.yaml in {sorted(differ)}, "
                            f"VARIANTS lists {sorted(keys)}")


def test_every_listed_variant_exists():
    for group, stem in VARIANTS:
        assert (CONF / group / f"{stem}.yaml").is_file(), f"VARIANTS lists conf/{group}/{stem}.yaml, which is gone"


def test_nbrdf_reference_is_the_published_recipe():
    from brdfbench_representations.nbrdf_fit import REFERENCE_RECIPE

    params = _resolved("representation", "nbrdf", option("representation", "nbrdf_reference")["params"])
    for f in dataclasses.fields(REFERENCE_RECIPE):
        if f.name in params:
            assert params[f.name] == _plain(getattr(REFERENCE_RECIPE, f.name)), f"nbrdf_reference.yaml: {f.name}"


# --------------------------------------------------------------------------- harness options


def _harness_values(stem: str) -> dict[str, Any]:
    """A harness option's keys as the pipeline hands them to harness_config (null sampler keys unset)."""
    return unset_nulls(option("harness", stem))


def _harness_main(kind: str) -> str:
    """A harness kind's main option: the one named after it (harness=accuracy, …)."""
    return kind


HARNESS_STEMS = stems("harness")


@pytest.mark.parametrize("stem", HARNESS_STEMS)
def test_a_harness_option_names_a_registered_kind_and_its_config_keys(stem):
    values = _harness_values(stem)
    kind = values.get("kind")
    assert kind in registry.names("harnesses"), f"conf/harness/{stem}.yaml: kind {kind!r} is not a registered harness"
    fields = {f.name for f in dataclasses.fields(harness_class(kind).Config)}
    assert set(values) <= fields, f"conf/harness/{stem}.yaml: {sorted(set(values) - fields)} are not {kind} config keys"
    harness_config(**values)  # every value valid too


def test_every_built_in_harness_has_a_main_option():
    for kind in BUILT_IN["harnesses"]:
        main = _harness_main(kind)
        assert (CONF / "harness" / f"{main}.yaml").is_file() and _harness_values(main).get("kind") == kind, (
            f"harness {kind!r} has no conf/harness/{kind}.yaml")


@pytest.mark.parametrize("kind", sorted(BUILT_IN["harnesses"]))
def test_a_harness_main_option_is_its_configs_defaults(kind):
    values = _harness_values(_harness_main(kind))
    config_cls = harness_class(kind).Config
    shipped = config_cls.from_dict(values)
    default = config_cls(kind=kind)
    for f in dataclasses.fields(config_cls):
        a, b = _plain(getattr(shipped, f.name)), _plain(getattr(default, f.name))
        listed = HARNESS_DIFFERENCES.get((kind, f.name))
        if listed is not None:
            reason, holds = listed
            assert holds(a), f"conf/harness/{kind}.yaml: {f.name}={a!r} is not what HARNESS_DIFFERENCES says ({reason})"
            continue
        assert a == b, f"conf/harness/{_harness_main(kind)}.yaml: {f.name}={a!r}, {config_cls.__name__} defaults to {b!r}"


@pytest.mark.parametrize("stem", HARNESS_STEMS)
def test_a_harness_variant_differs_from_its_main_option_where_listed(stem):
    kind = _harness_values(stem)["kind"]
    if stem == _harness_main(kind):
        return
    assert ("harness", stem) in VARIANTS, f"conf/harness/{stem}.yaml: a variant VARIANTS does not list"
    keys, reason = VARIANTS[("harness", stem)]
    variant = harness_config(**_harness_values(stem))
    main = harness_config(**_harness_values(_harness_main(kind)))
    differ = {f.name for f in dataclasses.fields(variant) if getattr(variant, f.name) != getattr(main, f.name)}
    assert differ == keys, (f"conf/harness/{stem}.yaml ({reason}) differs from {_harness_main(kind)}.yaml in "
                            f"{sorted(differ)}, VARIANTS lists {sorted(keys)}")
