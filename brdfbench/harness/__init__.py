"""Harnesses: each measures one aspect of a fitted representation and returns Measurements."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Measurement:
    metric: str
    value: float
    unit: str
    higher_is_better: bool
