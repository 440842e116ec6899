import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench.plugins import registry
from brdfbench_metrics import functional as F

FUNCTIONAL = {"l1": F.l1, "l1_log": F.l1_log, "l1_log_cos": F.l1_log_cos, "hdr_rmse": F.hdr_rmse, "hdr_mae": F.hdr_mae}


def _data(n=1000, seed=0):
    g = torch.Generator().manual_seed(seed)
    pred = torch.rand(n, 3, generator=g) * 5
    target = torch.rand(n, 3, generator=g) * 5
    cos_i = torch.rand(n, generator=g)
    return pred, target, cos_i


@pytest.mark.parametrize("name", sorted(FUNCTIONAL))
def test_class_and_functional_twins_agree_under_chunking(name):
    spec = registry.get("metrics", name)
    pred, target, cos_i = _data()
    metric = spec.load()()
    for s in (slice(0, 137), slice(137, 600), slice(600, 1000)):
        metric.update(pred[s], target[s], cos_i[s])
    assert metric.compute() == pytest.approx(float(FUNCTIONAL[name](pred, target, cos_i)), rel=1e-12)
    assert metric.unit == spec.unit and metric.higher_is_better == spec.higher_is_better
    metric.reset()
    with pytest.raises(ValueError, match="before any update"):
        metric.compute()


@pytest.mark.parametrize("name", sorted(FUNCTIONAL))
def test_perfect_prediction_is_best(name):
    pred, _, cos_i = _data()
    assert float(FUNCTIONAL[name](pred, pred, cos_i)) == 0.0


def test_known_values():
    pred = torch.tensor([[1.0, 1.0, 1.0]])
    target = torch.tensor([[3.0, 3.0, 3.0]])
    cos_i = torch.tensor([0.5])
    assert float(F.l1(pred, target)) == pytest.approx(2.0)
    assert float(F.l1_log(pred, target)) == pytest.approx(math.log(4) - math.log(2))
    assert float(F.l1_log_cos(pred, target, cos_i)) == pytest.approx(math.log(2.5) - math.log(1.5))
    assert float(F.hdr_rmse(pred, target)) == pytest.approx(2.0)


@settings(max_examples=100, deadline=None)
@given(st.floats(-1e30, 1e30, allow_nan=False), st.floats(0, 1e30, allow_nan=False), st.floats(0, 1))
def test_log_metrics_stay_finite_for_extreme_and_negative_predictions(p, t, c):
    pred = torch.full((1, 3), p, dtype=torch.float64)
    target = torch.full((1, 3), t, dtype=torch.float64)
    assert math.isfinite(float(F.l1_log(pred, target)))
    assert math.isfinite(float(F.l1_log_cos(pred, target, torch.tensor([c], dtype=torch.float64))))


def test_shape_mismatch_is_an_error():
    with pytest.raises(ValueError, match="shapes differ"):
        F.l1(torch.zeros(3, 3), torch.zeros(4, 3))
