"""Quadratures the model tests share."""

from __future__ import annotations

import math

import torch


def normal_incidence_albedo(m, n: int = 400_000) -> torch.Tensor:
    """∫ f cosθo dωo (RGB) for ωi = normal (azimuthally symmetric: a 1-D midpoint rule in θo)."""
    t = (torch.arange(n, dtype=torch.float64) + 0.5) * (math.pi / 2 / n)
    wo = torch.stack((torch.sin(t), torch.zeros_like(t), torch.cos(t)), dim=1)
    wi = torch.zeros_like(wo)
    wi[:, 2] = 1.0
    w = 2 * math.pi * torch.cos(t) * torch.sin(t) * (math.pi / 2 / n)
    return (m.eval(wi, wo) * w[:, None]).sum(0)
