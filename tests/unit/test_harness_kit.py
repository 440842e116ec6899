"""The harness conformance kit proves itself: the built-in harnesses and a small correct one
pass, each deliberately broken harness is caught by the check that names its fault, and
the kit runs isolated through `brdfbench check --kind harness`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import ClassVar

import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.harness import Harness, HarnessConfig, Measurement
from brdfbench.plugins.specs import HarnessSpec
from brdfbench.testing import check_harness, harness_checks
from brdfbench.testing.harnesses import KitDiffuse, kit_material

NAME = "kit_albedo"


@dataclass(frozen=True)
class AlbedoConfig(HarnessConfig):
    kind: str = NAME
    n_dirs: int = field(default=4096, metadata={"min": 1})


class Albedo(Harness):
    """The README's harness: the albedo error at normal incidence."""

    name = NAME
    Config = AlbedoConfig

    def directions(self, n: int) -> tuple[torch.Tensor, torch.Tensor]:
        g = torch.Generator().manual_seed(self.context.seed)
        u = torch.rand(n, 2, dtype=torch.float64, generator=g)
        r, phi = u[:, 0].sqrt(), 2 * math.pi * u[:, 1]
        wo = torch.stack((r * phi.cos(), r * phi.sin(), (1 - u[:, 0]).sqrt()), dim=1)
        return torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand_as(wo), wo

    def error(self, model, material, wi, wo) -> float:
        ref = material.table.lookup(wi, wo)
        keep = (ref >= 0).all(dim=1)
        return float(math.pi * (model.eval(wi, wo)[keep].double() - ref[keep]).mean(dim=0).abs().mean())

    def measure(self, model, material, label):
        wi, wo = self.directions(self.config.n_dirs)
        return [Measurement("albedo_error", self.error(model, material, wi, wo), "1", higher_is_better=False)]


# --------------------------------------------------------------------------- broken harnesses


@dataclass
class LooseConfig:
    """Looks like a HarnessConfig, but a plain (mutable) dataclass."""

    kind: str = NAME
    metrics: tuple[str, ...] = ()
    dtype: str = "float32"
    n_dirs: int = 4096
    RUN_CONTROL: ClassVar[tuple[str, ...]] = ()

    def hashed(self):
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, values):
        return cls(**values)


class NotFrozen(Albedo):
    Config = LooseConfig


@dataclass(frozen=True)
class KindOfAnother(AlbedoConfig):
    kind: str = "albedo"


class WrongKind(Albedo):
    Config = KindOfAnother


class NaNMeasure(Albedo):
    def measure(self, model, material, label):
        return [Measurement("albedo_error", float("nan"), "1", False)]


class UnseededMeasure(Albedo):
    def directions(self, n):
        u = torch.rand(n, 2, dtype=torch.float64)  # the global generator: another draw each call
        wo = torch.nn.functional.normalize(torch.cat((u - 0.5, torch.ones(n, 1, dtype=torch.float64)), dim=1), dim=1)
        return torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand_as(wo), wo


@dataclass(frozen=True)
class LeakyConfig(AlbedoConfig):
    def hashed(self):
        return dataclasses.asdict(self)  # timeout_s and memory_limit too


class LeakyHash(Albedo):
    Config = LeakyConfig


@dataclass(frozen=True)
class EmptyHashConfig(AlbedoConfig):
    def hashed(self):
        return {}


class HashesNothing(Albedo):
    Config = EmptyHashConfig


@dataclass(frozen=True)
class LenientConfig(AlbedoConfig):
    @classmethod
    def from_dict(cls, values):
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in values.items() if k in known})  # a typo is silently dropped


class IgnoresUnknownKeys(Albedo):
    Config = LenientConfig


@dataclass(frozen=True)
class UntypedErrorsConfig(AlbedoConfig):
    @classmethod
    def from_dict(cls, values):
        try:
            return super().from_dict(values)
        except ConfigError as exc:
            raise ValueError(str(exc)) from None  # a traceback, not a one-line exit-2 error


class RaisesValueError(Albedo):
    Config = UntypedErrorsConfig


class AcceptsAnyMetric(Albedo):
    @classmethod
    def validate(cls, config, scene, metric_specs):
        pass


class UnknownDomain(Albedo):
    domains = ("brdf_values",)


class MisnamedClass(Albedo):
    name = "albedo"


def spec(cls) -> HarnessSpec:
    return HarnessSpec(name=NAME, description="test harness", target=f"{__name__}:{cls.__name__}")


def test_a_correct_harness_passes_every_check():
    report = check_harness(spec(Albedo))
    assert report.passed, report.summary()
    assert set(report.outcomes.values()) == {"passed"}, report.summary()
    assert set(report.outcomes) == {"protocol", "config_frozen", "config_kind_is_name", "unknown_key_refused",
                                    "bad_values_refused", "hash_excludes_run_control", "hash_stable",
                                    "domains_known", "validate_refuses_foreign_metric", "measures",
                                    "measure_deterministic"}


@pytest.mark.parametrize("cls, check, words", [
    (NotFrozen, "config_frozen", "not a brdfbench.harness.HarnessConfig subclass"),
    (WrongKind, "config_kind_is_name", "kind defaults to 'albedo', not 'kit_albedo'"),
    (NaNMeasure, "measures", "albedo_error = nan"),
    (UnseededMeasure, "measure_deterministic", "different values: albedo_error"),
    (LeakyHash, "hash_excludes_run_control", "hashed() includes the run-control keys ['timeout_s', 'memory_limit']"),
    (HashesNothing, "hash_stable", "hashes as dtype=float32"),
    (IgnoresUnknownKeys, "unknown_key_refused", "accepted the unknown key"),
    (RaisesValueError, "bad_values_refused", "raised ValueError"),
    (AcceptsAnyMetric, "validate_refuses_foreign_metric", "validate accepted metric"),
    (UnknownDomain, "domains_known", "['brdf_values']"),
    (MisnamedClass, "protocol", "MisnamedClass.name is 'albedo'"),
])
def test_the_kit_catches_a_broken_harness(cls, check, words):
    report = check_harness(spec(cls))
    assert report.outcomes[check] == "failed", report.summary()
    detail = report.details[check]
    assert words in detail and f"harness {NAME!r}, {check}:" in detail, detail
    assert "\n" not in detail, detail
    with pytest.raises(AssertionError, match=check):
        report.raise_on_failure()


def test_quick_sizes_are_cut_and_params_override_them():
    from brdfbench.testing.harnesses import QUICK_INT, Context

    assert [c.name for c in harness_checks(spec(Albedo))][0] == "protocol"
    assert Context(spec(Albedo), {}).config().n_dirs == QUICK_INT
    assert Context(spec(Albedo), {}, full=True).config().n_dirs == 4096
    assert Context(spec(Albedo), {"n_dirs": 7}).config().n_dirs == 7


@pytest.mark.parametrize("name", registry.names("harnesses"))
def test_every_registered_harness_passes_the_quick_run(name):
    report = check_harness(name).raise_on_failure()
    cls = registry.get("harnesses", name).load()
    if cls.scope == "material" and not cls.rendered:
        assert report.outcomes["measures"] == "passed", report.summary()
    else:  # rendered or set scope: measured by --full or by the pipeline, and the report says so
        assert report.outcomes["measures"] == "skipped" and report.details["measures"], report.summary()
        if cls.rendered:
            assert "full=True" in report.details["measures"]


def test_the_kit_measures_a_fixed_model_on_a_table_with_a_lobe():
    material = kit_material()
    assert material.table.valid.mean() == pytest.approx(0.99, abs=0.001)
    assert material.table.values.max() > 10 * material.table.values[:, material.table.valid].min()  # a lobe
    value = KitDiffuse().eval(torch.tensor([[0.0, 0.0, 1.0]]), torch.tensor([[0.0, 0.0, 1.0]]))
    assert torch.allclose(value, torch.full((1, 3), 0.45 / math.pi))


def test_the_kit_runs_isolated_through_the_cli(capsys):
    from brdfbench.cli import main

    s = spec(NaNMeasure)
    registry.register("harnesses", s)
    try:
        status = main(["check", NAME, "--kind", "harness", "--timeout", "120"])
    finally:
        registry.unregister("harnesses", s.name)
    out = capsys.readouterr().out
    assert status == 1 and "failed   measures" in out and "passed   config_frozen" in out, out
    assert main(["check", "no_such_harness", "--kind", "harness"]) == 2
    assert "no_such_harness" in capsys.readouterr().err
