"""The generator conformance kit proves itself: a small correct generator passes every check,
and each deliberately broken one is caught by the check that names its fault."""

from __future__ import annotations

import time

import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import Generator
from brdfbench.plugins.specs import GeneratorSpec
from brdfbench.testing import check_generator
from brdfbench_generators.samples import WeightSamples


class GaussianWeights(Generator):
    """Per-coordinate Gaussian over NBRDF weight vectors: the smallest correct generator."""

    learns_from = "nbrdf"

    def __init__(self, scale: float = 1.0):
        super().__init__(scale=scale)
        self.mean = self.std = None
        self.hidden = (21, 21)

    def fit(self, data, *, seed=0, progress=False):
        ws = data.weights()
        v = torch.from_numpy(ws.vectors).double()
        g = torch.Generator().manual_seed(seed)
        jitter = 1e-6 * torch.rand(v.shape[1], generator=g, dtype=torch.float64)
        self.mean, self.std, self.hidden = v.mean(0), v.std(0) + jitter, tuple(ws.hidden)
        return self

    def _draw(self, n, seed):
        g = torch.Generator().manual_seed(seed)
        return self.mean + self.params["scale"] * self.std * torch.randn(n, self.mean.numel(), generator=g,
                                                                         dtype=torch.float64)

    def _sample(self, n, condition, seed):
        return WeightSamples(self._draw(n, seed), self.hidden)

    def sample_nbytes(self, n):
        return 3 * 8 * n * 675

    def state_dict(self):
        return {} if self.mean is None else {"mean": self.mean, "std": self.std}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        if tensors:
            for name in ("mean", "std"):
                if tuple(tensors[name].shape) != (675,):
                    raise ModelFileError(f"tensor {name!r} has shape {tuple(tensors[name].shape)}")
            model.mean, model.std = tensors["mean"], tensors["std"]
        return model


class IgnoresSeed(GaussianWeights):
    def _sample(self, n, condition, seed):
        return super()._sample(n, condition, 0)


class GlobalRandomness(GaussianWeights):
    def _draw(self, n, seed):
        return self.mean + self.std * torch.randn(n, self.mean.numel(), dtype=torch.float64)


class NaNSamples(GaussianWeights):
    def _draw(self, n, seed):
        out = super()._draw(n, seed)
        out[0, 3] = float("nan")
        return out


class NegativeValues(GaussianWeights):
    """Its samples' networks output a negative BRDF (the NBRDF clamp removed)."""

    def _sample(self, n, condition, seed):
        samples = super()._sample(n, condition, seed)
        build = samples._build

        class Negated:
            def __init__(self, model):
                self.model = model

            def eval(self, wi, wo):
                return -self.model.eval(wi, wo) - 1.0

        samples._build = lambda i: Negated(build(i))
        return samples


class NoMemoryEstimate(GaussianWeights):
    def sample_nbytes(self, n):
        return 8

    def _sample(self, n, condition, seed):  # never allocates what it was asked: the check must still object
        return super()._sample(min(n, 4), condition, seed)


class AcceptsZero(GaussianWeights):
    def sample(self, n, condition=None, *, seed=0):
        return self._sample(n, condition, seed) if n == 0 else super().sample(n, condition, seed=seed)


class LossyFile(GaussianWeights):
    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = super().from_state(params, tensors, metadata)
        if model.mean is not None:
            model.mean = model.mean.float().double()  # rounds through fp32
        return model


class FitsByClock(GaussianWeights):
    def fit(self, data, *, seed=0, progress=False):
        return super().fit(data, seed=int(time.perf_counter_ns()) % 1000, progress=progress)


class NoCost(GaussianWeights):
    @property
    def nbytes(self):
        return 0


class FittedFromTheStart(GaussianWeights):
    def state_dict(self):
        return {"mean": torch.zeros(675)} if self.mean is None else super().state_dict()


@pytest.fixture
def spec():
    added = []

    def make(cls, learns_from="nbrdf"):
        s = GeneratorSpec(name=cls.__name__.lower(), description="test", target=f"{__name__}:{cls.__name__}",
                          learns_from=learns_from)
        registry.register("generators", s)
        added.append(s.name)
        return s

    yield make
    for name in added:
        registry.unregister("generators", name)


def test_a_correct_generator_passes_every_check(spec):
    report = check_generator(spec(GaussianWeights))
    assert report.passed, report.summary()
    assert set(report.outcomes) == {"protocol", "unfitted_sample_refused", "sample_shapes", "sample_deterministic",
                                    "samples_finite_nonnegative", "save_load_roundtrip", "bad_sizes_refused",
                                    "fit_deterministic", "cost_declared"}


@pytest.mark.parametrize("cls, check, words", [
    (IgnoresSeed, "sample_deterministic", "the seed is ignored"),
    (GlobalRandomness, "sample_deterministic", "with one seed differ"),
    (NaNSamples, "samples_finite_nonnegative", "non-finite parameters"),
    (NegativeValues, "samples_finite_nonnegative", "negative value"),
    (NoMemoryEstimate, "bad_sizes_refused", "was accepted"),
    (AcceptsZero, "bad_sizes_refused", "n=0"),
    (LossyFile, "save_load_roundtrip", "samples differently"),
    (FitsByClock, "fit_deterministic", "sample differently"),
    (NoCost, "cost_declared", "nbytes"),
    (FittedFromTheStart, "protocol", "fitted=False"),
])
def test_the_kit_catches_a_broken_generator(spec, cls, check, words):
    report = check_generator(spec(cls))
    assert report.outcomes[check] == "failed", report.summary()
    assert words in report.details[check], report.details[check]


def test_a_spec_that_misstates_what_it_learns_from_is_caught(spec):
    report = check_generator(spec(GaussianWeights, learns_from="tables"))
    assert report.outcomes["protocol"] == "failed" and "learns from" in report.details["protocol"]


def test_sample_refuses_bad_sizes_before_allocating():
    from brdfbench.testing.generators import training_data

    g = GaussianWeights().fit(training_data())
    for n in (0, -3, 1.5):
        with pytest.raises(ConfigError, match="n="):
            g.sample(n)
    with pytest.raises(ConfigError, match="more than"):
        g.sample(10**13)
