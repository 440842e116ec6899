"""The MAPE image metrics (`mape_ldr`, `mape_hdr`): values against an independent numpy
computation and by hand, the streaming classes and their registration, the metric kit."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.testing import check_metric
from brdfbench_metrics import image as IM
from brdfbench.distances import image_functional as IF


def _images(n=None, h=9, w=11, seed=0, scale=2.0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    shape = (h, w, 3) if n is None else (n, h, w, 3)
    return torch.rand(shape, generator=g, dtype=torch.float64) * scale


def _srgb(x: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    x = np.clip(x * 2.0 ** exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _mape_numpy(pred, target, space, exposure=0.0, eps=0.01):
    if space == "ldr":
        pred, target = _srgb(pred, exposure), _srgb(target, exposure)
    per_value = np.abs(pred - target) / (target + eps)
    return 100.0 * per_value.reshape(pred.shape[0], -1).mean(axis=1)


@pytest.mark.parametrize("space", IF.SPACES)
@pytest.mark.parametrize("exposure", [0.0, 1.0])
def test_mape_matches_numpy(space, exposure):
    p, t = _images(n=3, seed=1), _images(n=3, seed=2)
    want = _mape_numpy(p.numpy(), t.numpy(), space, exposure)
    got = IF.mape(p, t, space=space, exposure=exposure, reduction="none")
    np.testing.assert_allclose(got.numpy(), want, rtol=1e-12)
    assert float(IF.mape(p, t, space=space, exposure=exposure)) == pytest.approx(want.mean(), rel=1e-12)
    one = IF.mape(p[0], t[0], space=space, exposure=exposure)
    assert one.ndim == 0 and float(one) == pytest.approx(want[0], rel=1e-12)


def test_mape_by_hand():
    t = torch.full((4, 4, 3), 0.99, dtype=torch.float64)
    # 10 % too bright everywhere: |0.099| / (0.99 + 0.01) = 9.9 %
    assert float(IF.mape(t * 1.1, t, space="hdr")) == pytest.approx(9.9)
    assert float(IF.mape(t, t, space="ldr")) == 0.0
    # a black target: the error is relative to ε alone, finite
    black = torch.zeros(2, 2, 3, dtype=torch.float64)
    assert float(IF.mape(black + 0.01, black, space="hdr")) == pytest.approx(100.0)
    assert float(IF.mape(black + 0.01, black, space="hdr", eps=0.1)) == pytest.approx(10.0)
    # scale-free where the target is far above ε: bright images give the plain relative error
    p, q = _images(seed=3), _images(seed=4) + 0.5
    plain = 100.0 * float(((p - q).abs() / q).mean())
    assert float(IF.mape(p * 1e4, q * 1e4, space="hdr")) == pytest.approx(plain, rel=1e-5)
    assert float(IF.mape(p, q, space="hdr")) < plain


def test_mape_rejects_bad_input():
    t = _images()
    with pytest.raises(ValueError, match="mape: unknown space"):
        IF.mape(t, t, space="linear")
    with pytest.raises(ValueError, match="mape: eps must be a positive"):
        IF.mape(t, t, space="hdr", eps=0.0)
    with pytest.raises(ValueError, match="mape in HDR space needs non-negative radiance"):
        IF.mape(t, t - 5.0, space="hdr")
    bad = t.clone()
    bad[0, 0, 0] = float("inf")
    with pytest.raises(ValueError, match="mape: target has 1 non-finite"):
        IF.mape(t, bad, space="hdr")


@pytest.mark.parametrize(("name", "cls", "space"), [("mape_ldr", IM.MAPELDR, "ldr"), ("mape_hdr", IM.MAPEHDR, "hdr")])
def test_streaming_mape_is_the_mean_over_images(name, cls, space):
    p, t = _images(n=5, seed=7), _images(n=5, seed=8)
    whole, chunked = cls(), cls()
    whole.update(p, t)
    for s in (slice(0, 2), slice(2, 5)):
        chunked.update(p[s], t[s])
    want = _mape_numpy(p.numpy(), t.numpy(), space).mean()
    assert whole.compute() == pytest.approx(want, rel=1e-12)
    assert chunked.compute() == pytest.approx(want, rel=1e-12)
    spec = registry.get("metrics", name)
    assert spec.load() is cls and spec.unit == "%" == cls.unit and not spec.higher_is_better


@pytest.mark.parametrize("name", ["mape_ldr", "mape_hdr"])
def test_the_metric_kit_passes(name):
    check_metric(name).raise_on_failure()
