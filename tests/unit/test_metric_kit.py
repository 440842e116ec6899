"""The metric conformance kit proves itself: small correct metrics of each domain pass every
check, each deliberately broken one is caught by the check that names its fault, and the
kit runs isolated through `brdfbench check --kind metric`."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.cli import main
from brdfbench.protocols.metric import ImageMetric, Metric, SetMetric
from brdfbench.plugins.specs import MetricSpec
from brdfbench.testing import check_metric, metric_checks


def abs_terms(pred, target, cos_i=None):
    return (pred.double() - target.double()).abs()


class AbsError(Metric):
    """The smallest correct BRDF-space metric."""

    terms = staticmethod(abs_terms)
    unit = "1"


class MeanAbsImage(ImageMetric):
    """The smallest correct image metric (takes `exposure=` as the render harness passes it)."""

    unit = "radiance"

    def __init__(self, exposure: float = 0.0):
        self.exposure = exposure
        super().__init__()

    def values(self, pred, target):
        return (pred - target).abs().mean(dim=(-3, -2, -1))


class NearestDistance(SetMetric):
    """The smallest correct set metric: mean over R of the distance to the nearest sample."""

    unit = "distance"

    def compute(self, d_rr, d_ss, d_rs) -> float:
        return float(np.min(d_rs, axis=1).mean())


# --------------------------------------------------------------------------- broken metrics


class WrongUnit(AbsError):
    unit = "1/sr"  # the spec says "1"


class NaNOnZero(AbsError):
    """Relative error without a floor: 0/0 where a table and a model both read 0."""

    terms = staticmethod(lambda pred, target, cos_i=None: (pred - target).abs() / target.abs())


class MeanOfChunkMeans(AbsError):
    """Averages each update's mean: the figure depends on how the harness chunks the cells."""

    def reset(self):
        super().reset()
        self.means = []

    def update(self, pred, target, cos_i=None):
        super().update(pred, target, cos_i)
        self.means.append(float(abs_terms(pred, target).mean()))

    def compute(self):
        super().compute()
        return sum(self.means) / len(self.means)


class OffsetOnIdentical(AbsError):
    terms = staticmethod(lambda pred, target, cos_i=None: abs_terms(pred, target) + 0.01)


class ZeroBeforeUpdate(AbsError):
    def compute(self):
        return 0.0 if self._count == 0 else super().compute()


class DividesByZero(AbsError):
    def compute(self):
        return self._sum / self._count


class ResetForgetsNothing(AbsError):
    def reset(self):
        if not hasattr(self, "_sum"):
            super().reset()


class GlobalNoise(AbsError):
    terms = staticmethod(lambda pred, target, cos_i=None: abs_terms(pred, target) * (1 + 1e-6 * torch.rand(pred.shape)))


class NoExposure(MeanAbsImage):
    def __init__(self):  # the render harness builds image metrics with exposure=
        super().__init__()


class SortsItsInput(NearestDistance):
    def compute(self, d_rr, d_ss, d_rs) -> float:
        d_rs.sort(axis=1)  # in place: the next set metric of the draw reads sorted rows
        return float(d_rs[:, 0].mean())


def spec(cls, unit="1", higher_is_better=False) -> MetricSpec:
    return MetricSpec(name=cls.__name__.lower(), description="test metric", target=f"{__name__}:{cls.__name__}",
                      unit=unit, higher_is_better=higher_is_better)


STREAMING_CHECKS = {"spec_agrees", "domain_known", "constructs", "ideal_on_identical", "monotone_in_error",
                    "finite_on_finite_inputs", "chunking_invariant", "merge_invariant", "reset_forgets",
                    "compute_before_update_refused", "deterministic"}
SET_CHECKS = {"spec_agrees", "domain_known", "constructs", "ideal_on_identical", "ranks_near_above_far",
              "finite_on_finite_inputs", "deterministic", "set_shapes_contract"}


@pytest.mark.parametrize("cls, unit, checks", [(AbsError, "1", STREAMING_CHECKS),
                                               (MeanAbsImage, "radiance", STREAMING_CHECKS),
                                               (NearestDistance, "distance", SET_CHECKS)])
def test_a_correct_metric_passes_every_check_of_its_domain(cls, unit, checks):
    report = check_metric(spec(cls, unit))
    assert report.passed, report.summary()
    assert set(report.outcomes) == checks and set(report.outcomes.values()) == {"passed"}, report.summary()
    assert report.raise_on_failure() is report


@pytest.mark.parametrize("cls, unit, check, words", [
    (WrongUnit, "1", "spec_agrees", "class unit '1/sr' != spec unit '1'"),
    (NaNOnZero, "1", "finite_on_finite_inputs", "scores nan"),
    (MeanOfChunkMeans, "1", "chunking_invariant", "7 chunks score"),
    (OffsetOnIdentical, "1", "ideal_on_identical", "not 0"),
    (ZeroBeforeUpdate, "1", "compute_before_update_refused", "before any update returned 0.0"),
    (DividesByZero, "1", "compute_before_update_refused", "ZeroDivisionError"),
    (ResetForgetsNothing, "1", "reset_forgets", "after reset()"),
    (GlobalNoise, "1", "deterministic", "the same inputs scored"),
    (NoExposure, "radiance", "constructs", "exposure=0.0"),
    (SortsItsInput, "distance", "set_shapes_contract", "changed its input d_rs"),
])
def test_the_kit_catches_a_broken_metric(cls, unit, check, words):
    s = spec(cls, unit)
    report = check_metric(s)
    assert report.outcomes[check] == "failed", report.summary()
    detail = report.details[check]
    assert words in detail and f"metric {s.name!r}, {check}:" in detail, detail
    assert "\n" not in detail, detail  # one line: plugin, check, fault
    with pytest.raises(AssertionError, match=check):
        report.raise_on_failure()


def test_a_spec_that_misstates_the_direction_is_caught():
    report = check_metric(spec(AbsError, higher_is_better=True))
    assert report.outcomes["spec_agrees"] == "failed" and "higher_is_better" in report.details["spec_agrees"]


def test_a_declared_expected_failure_is_xfailed():
    s = MetricSpec(name="xfail_metric", description="test", target=f"{__name__}:OffsetOnIdentical", unit="1",
                   xfail_checks={"ideal_on_identical": "known: a floor of 0.01"})
    report = check_metric(s)
    assert report.outcomes["ideal_on_identical"] == "xfailed" and report.passed, report.summary()


def test_image_set_scoring_runs_in_the_full_run_only():
    fid = next(n for n in registry.names("metrics") if getattr(registry.get("metrics", n).load(), "domain", "") == "image_set")
    report = check_metric(fid)
    assert report.outcomes["image_set_scores"] == "skipped" and "full=True" in report.details["image_set_scores"]
    assert [c.name for c in metric_checks(fid, full=True)][-1] == "image_set_scores"


def test_the_kit_runs_isolated_and_an_unknown_metric_is_one_line(capsys):
    from brdfbench.testing.isolated import check_isolated

    s = spec(NaNOnZero)
    registry.register("metrics", s)
    try:
        report = check_isolated("metric", s.name, timeout_s=120)
    finally:
        registry.unregister("metrics", s.name)
    assert report.outcomes["finite_on_finite_inputs"] == "failed" and report.outcomes["spec_agrees"] == "passed"
    assert main(["check", "no_such_metric", "--kind", "metric"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no_such_metric" in err[0], err
