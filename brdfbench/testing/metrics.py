"""Conformance checks for metric plugins: declared direction and unit, best value on a
perfect prediction, worse on a worse one, and chunking invariance of the streaming class.

BRDF-space metrics are fed (N, 3) BRDF values; image metrics (`domain = "image"`) are fed
a stack of HDR images (N, H, W, 3) whose radiance reaches past 1, so tone mapping clips."""

from __future__ import annotations

import torch

from .. import registry
from ..specs import MetricSpec


def _data(n: int = 4096, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(n, 3, generator=g, dtype=torch.float64) * 10
    cos_i = torch.rand(n, generator=g, dtype=torch.float64)
    noise = torch.rand(n, 3, generator=g, dtype=torch.float64)
    return target, cos_i, noise


def _images(n: int = 8, size: int = 24, seed: int = 0):
    """Smooth HDR images with texture (radiance in [0, 1.5)) and a multiplicative noise field."""
    g = torch.Generator().manual_seed(seed)
    ramp = torch.linspace(0.1, 1.0, size, dtype=torch.float64)
    albedo = torch.rand(n, 1, 1, 3, generator=g, dtype=torch.float64)
    shade = (ramp[:, None] * ramp.flip(0)[None, :])[None, :, :, None] * albedo
    target = 1.5 * (0.7 * shade + 0.3 * torch.rand(n, size, size, 3, generator=g, dtype=torch.float64))
    noise = torch.rand(n, size, size, 3, generator=g, dtype=torch.float64)
    return target, None, noise


def _point_sets(n: int = 24, shift: float = 0.0, seed: int = 0):
    """Two point clouds (n, 4) in R⁴, the second shifted by `shift`, and their L1 distance matrices."""
    g = torch.Generator().manual_seed(seed)
    r = torch.randn(n, 4, generator=g, dtype=torch.float64)
    s = torch.randn(n, 4, generator=g, dtype=torch.float64) + shift
    d = lambda a, b: torch.cdist(a, b, p=1).numpy()  # noqa: E731
    return d(r, r), d(s, s), d(r, s)


def _check_set_metric(spec: MetricSpec, metric) -> None:
    """A set metric must rank a sample set from R's distribution above one far from it."""
    near, far = metric.compute(*_point_sets(shift=0.0)), metric.compute(*_point_sets(shift=6.0))
    better = (lambda a, b: a > b) if spec.higher_is_better else (lambda a, b: a < b)
    assert better(near, far), f"{spec.name}: a set from R's distribution scored {near}, a set far from it {far}"
    again = metric.compute(*_point_sets(shift=0.0))
    assert again == near, f"{spec.name}: not deterministic ({near} then {again})"


def check_metric(spec_or_name: MetricSpec | str) -> None:
    """Raise AssertionError naming the first fault of a metric plugin."""
    spec = spec_or_name if isinstance(spec_or_name, MetricSpec) else registry.get("metrics", spec_or_name)
    cls = spec.load()
    metric = cls()
    assert metric.unit == spec.unit, f"{spec.name}: class unit {metric.unit!r} != spec unit {spec.unit!r}"
    assert metric.higher_is_better == spec.higher_is_better, f"{spec.name}: class and spec disagree on higher_is_better"
    domain = getattr(metric, "domain", None)
    if domain == "set":
        return _check_set_metric(spec, metric)
    if domain == "image_set":
        return  # computed from two image sets by a model of its own: its plugin's tests cover it
    image = domain == "image"
    target, cos_i, noise = _images() if image else _data()

    def value(pred, chunks=1):
        m = cls()
        for part in range(chunks):
            s = slice(part * len(pred) // chunks, (part + 1) * len(pred) // chunks)
            if image:
                m.update(pred[s], target[s])
            else:
                m.update(pred[s], target[s], cos_i[s])
        return m.compute()

    perfect, slightly, badly = value(target), value(target * (1 + 0.05 * noise)), value(target * (1 + 2 * noise))
    better = (lambda a, b: a > b) if spec.higher_is_better else (lambda a, b: a < b)
    assert better(perfect, slightly) and better(slightly, badly), (
        f"{spec.name}: not monotone in error: perfect={perfect}, 5% off={slightly}, 200% off={badly}"
    )
    chunked = value(target * (1 + 2 * noise), chunks=7)
    assert abs(chunked - badly) <= 1e-9 * max(1.0, abs(badly)), f"{spec.name}: chunked {chunked} != whole {badly}"
