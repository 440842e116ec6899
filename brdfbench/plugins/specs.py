"""Typed plugin specifications: the objects entry points resolve to.

A spec is light: it names its implementation by a dotted path ("module:attr") that is
imported only on `load()`, so listing plugins imports no heavy code. A spec carries what
a registry or a report needs without loading the plugin: name, one-line description,
capability tags, and the conformance checks it expects to fail (with reasons).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import PluginError


def import_target(target: str) -> Any:
    """Import "package.module:attr" and return the attribute."""
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise PluginError(f"plugin target {target!r} must look like 'package.module:attribute'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise PluginError(f"cannot import plugin module {module_name!r} for {target!r}: {exc}") from exc
    try:
        return getattr(module, attr)
    except AttributeError:
        raise PluginError(f"plugin module {module_name!r} has no attribute {attr!r}") from None


@dataclass(frozen=True)
class PluginSpec:
    name: str
    description: str
    target: str
    tags: frozenset[str] = frozenset()
    #: check name -> reason; the conformance kit reports these as expected failures.
    xfail_checks: Mapping[str, str] = field(default_factory=dict)

    def load(self) -> Any:
        return import_target(self.target)


@dataclass(frozen=True)
class RepresentationSpec(PluginSpec):
    """A BRDF representation; `target` is a `brdfbench.protocols.representation.Representation` subclass."""

    #: constructor arguments of the conformance kit's quick run (e.g. a short training recipe),
    #: so that it fits in seconds; the kit's full run uses the representation's defaults.
    kit_params: Mapping[str, Any] = field(default_factory=dict)
    #: the parameters under which this representation is the target itself (an oracle, e.g.
    #: a table read back cell by cell): reports show such a configuration apart, never ranked;
    #: a key a configuration leaves out takes the value given here. None: never the target.
    reference: Mapping[str, Any] | None = None
    #: the input encoding ("rusinkiewicz", "directions": `brdfbench.nbrdf.network.FEATURES`)
    #: of the NBRDF-layout networks this representation fits and saves: NBRDF weight files
    #: and datasets of fitted networks find their representation by it, never by name.
    network_features: str = ""

    def create(self, **params: Any):
        return self.load()(**params)

    def is_reference(self, params: Mapping[str, Any] | None) -> bool:
        """Whether a configuration with these constructor parameters is the target itself."""
        if self.reference is None:
            return False
        params = params or {}
        return all(params.get(k, v) == v for k, v in self.reference.items())


@dataclass(frozen=True)
class GeneratorSpec(PluginSpec):
    """A material generator (PCA, VAE, hyperdiffusion, ...); `target` is a
    `brdfbench.protocols.generator.Generator` subclass."""

    #: what it learns from: "tables" (MERL tables) or "nbrdf" (aligned NBRDF weight
    #: vectors): checked against the dataset before any work, without importing the plugin
    learns_from: str = "tables"
    #: constructor arguments of the conformance kit's quick run (a short training), so that
    #: `check_generator` takes seconds; the full run uses the generator's defaults
    kit_params: Mapping[str, Any] = field(default_factory=dict)

    def create(self, **params: Any):
        return self.load()(**params)


@dataclass(frozen=True)
class DatasetSpec(PluginSpec):
    """A source of target materials; `target` is a callable returning a `brdfbench.data.Dataset`."""

    #: what the dataset's figures do and do not show, printed under its heading in reports
    caveat: str = ""


@dataclass(frozen=True)
class MetricSpec(PluginSpec):
    """A metric; `target` is a class implementing one of `brdfbench.protocols.metric`'s
    protocols (`Metric`, `ImageMetric`, `SetMetric`, `ImageSetMetric`), by its `domain`."""

    unit: str = ""
    higher_is_better: bool = False
    #: reports rank representations by the present metric of lowest `rank` (None: shown, but
    #: chosen to rank only when no ranked metric is present)
    rank: int | None = None


@dataclass(frozen=True)
class SceneSpec(PluginSpec):
    """A scene: what it contains decides which simulator evaluates it."""


@dataclass(frozen=True)
class HarnessSpec(PluginSpec):
    """A harness; `target` is a `brdfbench.harness.Harness` subclass (typed config, validation, measuring)."""


@dataclass(frozen=True)
class ReportSpec(PluginSpec):
    """A report; `target` is a callable (results frame, results folder, store name) -> paths written."""

    #: reports are written lowest `order` first (then by name); the first path of the first
    #: report is the one the CLI prints as the leaderboard
    order: int = 100


@dataclass(frozen=True)
class StoreSpec(PluginSpec):
    """A results store backend; `target(results_dir, create=True, **params)` returns a
    `brdfbench.store.protocol.Store` (see that module for the contract)."""


@dataclass(frozen=True)
class SamplerSpec(PluginSpec):
    """An importance sampler; `target` is a `brdfbench.sampling.Sampler` subclass."""

    def create(self, **params: Any):
        return self.load()(**params)
