"""The core's metric protocols: every registered metric implements the one its domain names,
and streaming states merge as if one instance had seen every chunk."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench.protocols import metric as mp
from brdfbench.plugins import registry

PROTOCOL = {"merl_grid": mp.Metric, "random_pairs": mp.Metric, "image": mp.ImageMetric, "set": mp.SetMetric,
            "image_set": mp.ImageSetMetric}


@pytest.mark.parametrize("name", registry.names("metrics"))
def test_every_registered_metric_implements_its_domain_s_protocol(name):
    cls = registry.get("metrics", name).load()
    assert cls.domain in mp.DOMAINS, f"{name}: domain {cls.domain!r}"
    assert issubclass(cls, PROTOCOL[cls.domain]), f"{name} ({cls.domain}) is not a {PROTOCOL[cls.domain].__name__}"


class AbsError(mp.Metric):
    terms = staticmethod(lambda pred, target, cos_i=None: (pred - target).abs())
    unit = "1"


class SquaredRoot(mp.Metric):
    terms = staticmethod(lambda pred, target, cos_i=None: (pred - target) ** 2)
    unit = "1"

    def _finish(self, mean):
        return mean ** 0.5


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(min_value=1, max_value=50), min_size=1, max_size=6), st.integers(0, 2**31 - 1),
       st.sampled_from([AbsError, SquaredRoot]))
def test_merged_states_equal_one_stream(sizes, seed, cls):
    g = torch.Generator().manual_seed(seed)
    chunks = [(torch.rand(n, 3, generator=g, dtype=torch.float64), torch.rand(n, 3, generator=g, dtype=torch.float64))
              for n in sizes]
    one = cls()
    for pred, target in chunks:
        one.update(pred, target)
    parts = [cls() for _ in chunks]
    for part, (pred, target) in zip(parts, chunks):
        part.update(pred, target)
    merged = parts[0]
    for part in parts[1:]:
        merged.merge(part)
    assert merged.compute() == pytest.approx(one.compute(), rel=1e-12)


def test_merge_refuses_another_metric_and_compute_refuses_an_empty_state():
    with pytest.raises(TypeError, match="only the same metric merges"):
        AbsError().merge(SquaredRoot())
    with pytest.raises(ValueError, match="before any update"):
        AbsError().compute()
    metric = AbsError()
    metric.update(torch.ones(2, 3), torch.zeros(2, 3))
    metric.reset()
    with pytest.raises(ValueError, match="before any update"):
        metric.compute()


def test_an_image_metric_averages_its_per_image_values():
    class MeanAbs(mp.ImageMetric):
        def values(self, pred, target):
            return (pred - target).abs().mean(dim=(-3, -2, -1))

    metric = MeanAbs()
    metric.update(torch.full((2, 4, 4, 3), 1.0), torch.zeros(2, 4, 4, 3))
    metric.update(torch.full((4, 4, 3), 4.0), torch.zeros(4, 4, 3))
    assert metric.compute() == pytest.approx(2.0)
