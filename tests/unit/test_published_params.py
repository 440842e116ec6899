"""PublishedParams: one set of checks and messages for every model's published parameters."""

from __future__ import annotations

import math

import pytest

from brdfbench_representations.published_params import PublishedParams


class Model:
    NAME = "toy"
    PUBLISHED_AS = ("ToyFit",)


def _p(**params):
    return PublishedParams(Model, "ToyFit", params)


def test_the_model_and_the_parameter_names():
    with pytest.raises(ValueError, match=r"^toy: cannot evaluate a published 'Other' fit; it evaluates ToyFit$"):
        PublishedParams(Model, "Other", {})
    with pytest.raises(ValueError, match="toy: published ToyFit fit: parameters must be a dict, got list"):
        PublishedParams(Model, "ToyFit", [1])
    with pytest.raises(ValueError, match=r"missing parameter\(s\) 'b'; expected a, b"):
        _p(a=1).expect(["a", "b"])
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) 'c'; expected a"):
        _p(a=1, c=2).expect(["a"])
    _p(a=1).expect(["a"])


def test_numbers_rgb_and_domains():
    p = _p(n=[2.5], m=[1, 2], s="x", inf=math.inf, rgb=0.5, two=[1, 2], neg=[0.1, -0.2, 0.3], bad=[0.1, None, 0.2])
    assert p.number("n") == 2.5 and p.rgb("rgb") == [0.5, 0.5, 0.5]
    assert p.rgb("neg", nonnegative=False) == [0.1, -0.2, 0.3]
    for key, what in (("m", "must be one number, got [1, 2]"), ("s", "must be a finite number, got 'x'"),
                      ("inf", "must be a finite number, got inf")):
        with pytest.raises(ValueError, match=f"parameter '{key}' {what}".replace("[", r"\[").replace("]", r"\]")):
            p.number(key)
    with pytest.raises(ValueError, match=r"'two' needs 1 or 3 values \(RGB\), got 2"):
        p.rgb("two")
    with pytest.raises(ValueError, match="'neg' must be non-negative"):
        p.rgb("neg")
    with pytest.raises(ValueError, match="'bad' must hold finite numbers"):
        p.rgb("bad")
    with pytest.raises(ValueError, match=r"'diffuse albedo' must be non-negative, got \[0.1, -1, 0.1\]"):
        p.diffuse([0.1, -1, 0.1])
    p.within("n", 2.5, 0.0, 3.0, "[0, 3]")
    with pytest.raises(ValueError, match=r"parameter 'n' = \[2.5\] is outside the model's domain \(below 2\)"):
        p.within("n", 2.5, 0.0, 2.0, "below 2")
    with pytest.raises(ValueError, match="outside the model's domain"):
        p.within("rgb", [0.0, 0.5, 0.5], 0.0, 1.0, "> 0", lo_open=True)
