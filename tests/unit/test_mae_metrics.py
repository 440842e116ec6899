"""The MAE image metrics (`mae_ldr`, `mae_hdr`): values against an independent numpy
computation, the streaming classes and their registration, the metric kit, and where the
render harness lists them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.testing import check_metric
from brdfbench_metrics import image as IM
from brdfbench.distances import image_functional as IF

REPO = Path(__file__).resolve().parents[2]


def _images(n=None, h=12, w=10, seed=0, scale=2.0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    shape = (h, w, 3) if n is None else (n, h, w, 3)
    return torch.rand(shape, generator=g, dtype=torch.float64) * scale


def _srgb(x: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Tone mapping written out here: 2^exposure, clamp to [0, 1], the sRGB curve."""
    x = np.clip(x * 2.0 ** exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _mae_numpy(pred: np.ndarray, target: np.ndarray, space: str, exposure: float = 0.0) -> np.ndarray:
    """Per-image MAE over pixels and channels, (N,)."""
    if space == "ldr":
        pred, target = _srgb(pred, exposure), _srgb(target, exposure)
    return np.abs(pred - target).reshape(pred.shape[0], -1).mean(axis=1)


@pytest.mark.parametrize("space", IF.SPACES)
@pytest.mark.parametrize("exposure", [0.0, -1.5])
def test_mae_matches_numpy(space, exposure):
    p, t = _images(n=3, seed=1), _images(n=3, seed=2)
    want = _mae_numpy(p.numpy(), t.numpy(), space, exposure)
    got = IF.mae(p, t, space=space, exposure=exposure, reduction="none")
    np.testing.assert_allclose(got.numpy(), want, rtol=1e-12, atol=1e-15)
    assert float(IF.mae(p, t, space=space, exposure=exposure)) == pytest.approx(want.mean(), rel=1e-12)
    one = IF.mae(p[0], t[0], space=space, exposure=exposure)
    assert one.ndim == 0 and float(one) == pytest.approx(want[0], rel=1e-12)


def test_mae_by_hand():
    t = torch.zeros(4, 4, 3, dtype=torch.float64)
    assert float(IF.mae(t + 0.25, t, space="hdr")) == pytest.approx(0.25)
    assert float(IF.mae(t, t, space="ldr")) == 0.0
    half = torch.zeros(4, 4, 3, dtype=torch.float64)
    half[:2] = 2.0  # half the pixels off by 2 (HDR); in LDR both clamp to 1, so off by 1
    assert float(IF.mae(half, t, space="hdr")) == pytest.approx(1.0)
    assert float(IF.mae(half, t, space="ldr")) == pytest.approx(0.5)
    # MAE never exceeds RMSE (the mean of |e| is at most the root mean of e²)
    p, q = _images(seed=3), _images(seed=4)
    for space in IF.SPACES:
        assert float(IF.mae(p, q, space=space)) <= float(IF.rmse(p, q, space=space)) + 1e-15


def test_mae_rejects_what_the_others_reject():
    t = _images()
    with pytest.raises(ValueError, match="mae: unknown space"):
        IF.mae(t, t, space="linear")
    with pytest.raises(ValueError, match="mae: pred and target shapes differ"):
        IF.mae(t, t[:4], space="hdr")
    bad = t.clone()
    bad[0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="mae: pred has 1 non-finite"):
        IF.mae(bad, t, space="hdr")


def test_mae_takes_a_device():
    p, t = _images(n=2, seed=5), _images(n=2, seed=6)
    for space in IF.SPACES:
        want = IF.mae(p, t, space=space, reduction="none")
        got = IF.mae(p, t, space=space, reduction="none", device="cpu")
        assert got.device == p.device and torch.equal(got, want)


@pytest.mark.parametrize(("name", "cls", "space", "unit"),
                         [("mae_ldr", IM.MAELDR, "ldr", "1"), ("mae_hdr", IM.MAEHDR, "hdr", "radiance")])
def test_streaming_mae_is_the_mean_over_images_in_any_chunks(name, cls, space, unit):
    p, t = _images(n=7, seed=7), _images(n=7, seed=8)
    whole = cls()
    whole.update(p, t)
    chunked = cls()
    for s in (slice(0, 1), slice(1, 4), slice(4, 7)):
        chunked.update(p[s], t[s])
    want = _mae_numpy(p.numpy(), t.numpy(), space).mean()
    assert whole.compute() == pytest.approx(want, rel=1e-12)
    assert chunked.compute() == pytest.approx(want, rel=1e-12)
    # the state merges: two halves' sums and counts make the whole
    a, b = cls(), cls()
    a.update(p[:3], t[:3])
    b.update(p[3:], t[3:])
    assert (a._sum + b._sum) / (a._count + b._count) == pytest.approx(want, rel=1e-12)
    spec = registry.get("metrics", name)
    assert spec.load() is cls and spec.unit == unit == cls.unit and not spec.higher_is_better
    assert "image" in spec.tags and cls.domain == "image"


@pytest.mark.parametrize("name", ["mae_ldr", "mae_hdr"])
def test_the_metric_kit_passes(name):
    check_metric(name).raise_on_failure()


def test_the_render_harness_computes_mae_wherever_it_computes_rmse():
    from omegaconf import OmegaConf

    from brdfbench.pipeline.config import harness_config

    metrics = harness_config("render").metrics
    assert metrics and list(metrics) == list(OmegaConf.load(REPO / "conf" / "harness" / "render.yaml").metrics)
    for metrics in (metrics,):
        for space in IF.SPACES:
            if f"rmse_{space}" in metrics:
                assert f"mae_{space}" in metrics, metrics
