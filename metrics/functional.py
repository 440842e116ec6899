"""Functional BRDF-space metrics over matched (N, 3) predictions and targets.

Log metrics follow Hu 2026 (eq. 4.12 and section 4.4.1): L1-log = |log(1+f1) - log(1+f2)|,
L1-log-cos = |log(1+f1 cos θi) - log(1+f2 cos θi)|, averaged over samples and channels.
Predictions are clamped at 0 before log1p so log of a value <= -1 cannot occur.
"""

from __future__ import annotations

import torch


def _check(pred: torch.Tensor, target: torch.Tensor) -> None:
    if pred.shape != target.shape:
        raise ValueError(f"pred and target shapes differ: {tuple(pred.shape)} vs {tuple(target.shape)}")


def l1_terms(pred, target, cos_i=None):
    _check(pred, target)
    return (pred.double() - target.double()).abs()


def l1_log_terms(pred, target, cos_i=None):
    _check(pred, target)
    return (torch.log1p(pred.double().clamp_min(0)) - torch.log1p(target.double().clamp_min(0))).abs()


def l1_log_cos_terms(pred, target, cos_i):
    _check(pred, target)
    c = cos_i.double().clamp_min(0).reshape(-1, *([1] * (pred.ndim - 1)))
    return (torch.log1p(pred.double().clamp_min(0) * c) - torch.log1p(target.double().clamp_min(0) * c)).abs()


def squared_error_terms(pred, target, cos_i=None):
    _check(pred, target)
    return (pred.double() - target.double()) ** 2


def l1(pred, target, cos_i=None) -> torch.Tensor:
    return l1_terms(pred, target).mean()


def l1_log(pred, target, cos_i=None) -> torch.Tensor:
    return l1_log_terms(pred, target).mean()


def l1_log_cos(pred, target, cos_i) -> torch.Tensor:
    return l1_log_cos_terms(pred, target, cos_i).mean()


def hdr_rmse(pred, target, cos_i=None) -> torch.Tensor:
    """Root mean squared error of unclipped (HDR) BRDF values."""
    return squared_error_terms(pred, target).mean().sqrt()


def hdr_mae(pred, target, cos_i=None) -> torch.Tensor:
    """Mean absolute error of unclipped (HDR) BRDF values."""
    return l1_terms(pred, target).mean()
