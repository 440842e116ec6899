"""Lazy plugin registry over Python entry points.

Groups: brdfbench.representations, .generators, .metrics, .datasets, .scenes, .samplers,
.harnesses, .reports, .stores. Built-ins
register through the same groups a third party uses; the core imports no plugin by name.
Entry points are listed without importing anything; a spec is imported on first use.
"""

from __future__ import annotations

import difflib
from functools import lru_cache
from importlib.metadata import EntryPoint, entry_points

from ..errors import PluginError
from .specs import (DatasetSpec, GeneratorSpec, HarnessSpec, MetricSpec, PluginSpec, ReportSpec, RepresentationSpec,
                    SamplerSpec, SceneSpec, StoreSpec)

GROUPS: dict[str, type[PluginSpec]] = {
    "representations": RepresentationSpec,
    "generators": GeneratorSpec,
    "metrics": MetricSpec,
    "datasets": DatasetSpec,
    "scenes": SceneSpec,
    "samplers": SamplerSpec,
    "harnesses": HarnessSpec,
    "reports": ReportSpec,
    "stores": StoreSpec,
}

SINGULAR = {"harnesses": "harness"}

_extra: dict[str, dict[str, PluginSpec]] = {g: {} for g in GROUPS}


def _check_group(group: str) -> None:
    if group not in GROUPS:
        raise PluginError(f"unknown plugin group {group!r}; groups are {', '.join(GROUPS)}")


@lru_cache(maxsize=None)
def _entry_points(group: str) -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=f"brdfbench.{group}")}


def names(group: str) -> list[str]:
    """Registered plugin names in a group, sorted; imports nothing."""
    _check_group(group)
    return sorted(set(_entry_points(group)) | set(_extra[group]))


def register(group: str, spec: PluginSpec) -> None:
    """Register a spec in-process (for tests and notebooks); entry points are the normal way."""
    _check_group(group)
    if not isinstance(spec, GROUPS[group]):
        raise PluginError(f"a {group} plugin must be a {GROUPS[group].__name__}, got {type(spec).__name__}")
    _extra[group][spec.name] = spec
    get.cache_clear()


def unregister(group: str, name: str) -> None:
    _extra[group].pop(name, None)
    get.cache_clear()


@lru_cache(maxsize=None)
def get(group: str, name: str) -> PluginSpec:
    """The spec registered as `name` in `group`; an unknown name gets "did you mean"."""
    _check_group(group)
    if name in _extra[group]:
        return _extra[group][name]
    eps = _entry_points(group)
    if name not in eps:
        known = names(group)
        close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise PluginError(f"unknown {SINGULAR.get(group, group[:-1])} {name!r}.{hint} "
                          f"Registered: {', '.join(known) or 'none'}.")
    try:
        spec = eps[name].load()
    except Exception as exc:  # a broken third-party plugin must not look like a core bug
        raise PluginError(f"{group} plugin {name!r} ({eps[name].value}) failed to load: {exc}") from exc
    expected = GROUPS[group]
    if not isinstance(spec, expected):
        raise PluginError(f"{group} plugin {name!r} ({eps[name].value}) is a {type(spec).__name__}, expected a {expected.__name__}")
    if spec.name != name:
        raise PluginError(f"{group} plugin registered as {name!r} names itself {spec.name!r}")
    return spec


def all_specs(group: str) -> list[PluginSpec]:
    return [get(group, n) for n in names(group)]


def version(group: str, name: str) -> str:
    """The version of the distribution that registers `name` ("in-process" for `register`ed specs)."""
    _check_group(group)
    if name in _extra[group]:
        return "in-process"
    ep = _entry_points(group).get(name)
    dist = getattr(ep, "dist", None)
    return str(getattr(dist, "version", "") or "unknown")


def snapshot() -> dict[str, dict[str, PluginSpec]]:
    """The in-process registrations, to hand to a worker process (entry points it finds itself)."""
    return {g: dict(specs) for g, specs in _extra.items() if specs}


def restore(extra: dict[str, dict[str, PluginSpec]]) -> None:
    """Re-register a `snapshot()` in this process (a worker's start)."""
    for group, specs in extra.items():
        for spec in specs.values():
            register(group, spec)
