"""Reading one published fit's parameters (BBM's notation, as `published_parse` gives them)
onto a model's coefficients, with one set of checks and messages for every model.

Each failure is a ValueError "<model>: published <BBM model> fit: <what>", naming the
parameter and its value; `published.PublishedFit` turns it into that material's failed cell.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

_PARAM = object()  # "the parameter's own value"


class PublishedParams:
    """The parameters of one published fit for the model class `cls` (its NAME and PUBLISHED_AS)."""

    def __init__(self, cls: type, bbm_name: str, params: Any):
        if bbm_name not in cls.PUBLISHED_AS:
            evaluates = ", ".join(cls.PUBLISHED_AS) or "no published fits"
            raise ValueError(f"{cls.NAME}: cannot evaluate a published {bbm_name!r} fit; it evaluates {evaluates}")
        self.model, self.bbm_name = cls.NAME, bbm_name
        if not isinstance(params, dict):
            raise self.fail(f"parameters must be a dict, got {type(params).__name__}")
        self.params = params

    def fail(self, what: str) -> ValueError:
        return ValueError(f"{self.model}: published {self.bbm_name} fit: {what}")

    def expect(self, keys: Iterable[str]) -> None:
        """Exactly these parameter names: the missing and the unknown ones named."""
        expected = list(keys)
        missing = [k for k in expected if k not in self.params]
        if missing:
            raise self.fail(f"missing parameter(s) {', '.join(map(repr, missing))}; expected {', '.join(expected)}")
        unknown = [k for k in self.params if k not in expected]
        if unknown:
            raise self.fail(f"unknown parameter(s) {', '.join(map(repr, unknown))}; expected {', '.join(expected)}")

    def number(self, key: str, value: Any = _PARAM) -> float:
        """One finite number (a one-element list is one number); `value` defaults to the parameter's."""
        raw = self.params[key] if value is _PARAM else value
        v = raw
        if isinstance(v, (list, tuple)):
            if len(v) != 1:
                raise self.fail(f"parameter {key!r} must be one number, got {raw!r}")
            v = v[0]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise self.fail(f"parameter {key!r} must be a finite number, got {raw!r}")
        return float(v)

    def rgb(self, key: str, value: Any = _PARAM, *, nonnegative: bool = True) -> list[float]:
        """Three finite numbers (one is used for all channels), ≥ 0 unless `nonnegative` is False."""
        raw = self.params[key] if value is _PARAM else value
        values = list(raw) if isinstance(raw, (list, tuple)) else [raw]
        if len(values) == 1:
            values = values * 3
        if len(values) != 3:
            raise self.fail(f"parameter {key!r} needs 1 or 3 values (RGB), got {len(values)}: {raw!r}")
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) for v in values):
            raise self.fail(f"parameter {key!r} must hold finite numbers, got {raw!r}")
        out = [float(v) for v in values]
        if nonnegative and min(out) < 0:
            raise self.fail(f"parameter {key!r} must be non-negative, got {raw!r}")
        return out

    def within(self, key: str, values: float | list[float], lo: float, hi: float, meaning: str, *,
               lo_open: bool = False, raw: Any = _PARAM) -> None:
        """Every value in [lo, hi] (or (lo, hi] with `lo_open`), else the parameter is named with
        its published value and `meaning`, the domain in words."""
        for v in values if isinstance(values, list) else [values]:
            if v < lo or (lo_open and v == lo) or v > hi:
                shown = self.params.get(key) if raw is _PARAM else raw
                raise self.fail(f"parameter {key!r} = {shown!r} is outside the model's domain ({meaning})")

    def diffuse(self, diffuse: Any) -> list[float]:
        """The Lambertian albedo beside the model: k_d (f_d = albedo/π, as BBM's Lambertian)."""
        return self.rgb("diffuse albedo", diffuse)
