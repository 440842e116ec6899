"""Fitting the analytic BRDFs (`representations/analytic.py`) to a measured MERL table.

Objective (the model's `loss`, `fit_losses.py`): by default the NBRDF loss
|log(1 + f cosθi) − log(1 + f̂ cosθi)|, averaged over RGB and over a seeded uniform
subsample (`n_samples`, default 2^15) of the target's usable cells (valid, both directions
above the horizon): an unbiased estimate of the benchmark's `l1_log_cos` over the grid; or
the metric a published fit was made with, over direction pairs drawn as its authors weighted
them. (Measured on 16 materials, GGX: 2^13 cells gives a full-grid
loss 0.7 % worse than 2^15; 2^16 gives the same as 2^15.)

Optimiser: scipy L-BFGS-B in float64 on bounded coefficients (k_s, roughness-like and
IoR / exponent coefficients in log space, k_d and F0 linear), with autograd gradients of
a smooth surrogate sqrt(r² + ε²) − ε of |r| (squared losses need none); the reported loss
is the true one. The per-cell geometry is computed once, so an objective evaluation is only the lobe's
arithmetic. Restarts run on the first COARSE_SAMPLES cells of the subsample (a random
subset, as the subsample is in random order); the best is refined on all of it.
Torch runs single-threaded during the fit (restored after): see `brdfbench.threads`.

Initialisation: k_d = π × the cosine-weighted median of the subsample's values (as
`lambert.py`); on the full table, the specular peak is the median value of the cells with
θh in the first two MERL bins and θd < 30°, minus the diffuse level, and the GGX-
equivalent α comes from the θh at which the (θd < 30°) specular profile falls to half its
peak (GGX: tanθ½ = 0.6436 α). Restarts try α_est, ×4, ÷4, then 0.5, ×16, ÷16, ...; each
starts k_s so that the model's lobe matches the peak (Fresnel at its default). The best
(lowest true loss) wins. `metadata()` records the loss, the restarts and their
(coarse-subset) losses.

Errors: a table with NaN/Inf values, or without a single valid cell above the horizon,
raises `DataError` naming the material.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from scipy.optimize import minimize

from brdfbench import merl
from brdfbench.errors import DataError
from brdfbench.threads import torch_threads
from brdfbench.protocols.representation import Material, Representation

from .analytic_terms import HALF_WIDTH_PER_ALPHA, Geometry, geometry
from .fit_losses import DEFAULT_LOSS, LOSSES, FitLoss, compared, sample_pairs
from .lambert import weighted_median

#: Surrogate smoothing of |r| (r in log(1 + 1/sr) units).
EPSILON = 1e-3
#: Restarts run on the first COARSE_SAMPLES cells of the (random) subsample; the best
#: REFINE_TOP of them are then refined on the whole subsample.
COARSE_SAMPLES = 4096
COARSE_MAX_ITER = 100
REFINE_TOP = 1
ALPHA_INIT_MIN = 1e-3
#: L-BFGS-B iterations of the refinement, and its relative/gradient stopping tolerances.
MAX_ITER = 300
FTOL = 1e-10
GTOL = 1e-9
#: θd bins (of 90) used for the specular profile: θd < 30°.
PROFILE_THETA_D_BINS = 30
RESTART_FACTORS = (1.0, 4.0, 0.25, None, 16.0, 1 / 16, 64.0, 1 / 64)  # None: a fixed α = 0.5


@dataclass
class FitData:
    """What the optimiser needs, computed once per (target, n_samples, seed)."""

    geom: Geometry  # (N,) float64 each
    cos_i: torch.Tensor  # (N, 1)
    y: torch.Tensor  # (N, 3): the target as the loss compares it (log1p(f cosθi) or f cosθi)
    n_usable: int
    diffuse: np.ndarray  # (3,) π × cosine-weighted median
    peak: np.ndarray  # (3,) specular excess at θh ≈ 0, θd < 30° (1/sr)
    peak_theta_d: float
    alpha_est: float
    loss: FitLoss = LOSSES[DEFAULT_LOSS]
    cells: np.ndarray | None = None  # (N,) flat MERL cell of each row (its target value's cell)


@dataclass
class FitResult:
    coefficients: dict[str, list[float]]
    loss: float
    info: dict[str, Any] = field(default_factory=dict)


def _usable_cells(target: Material, model_name: str) -> np.ndarray:
    raw = target.table.raw
    bad = ~np.isfinite(raw)
    if bad.any():
        c, i, j, k = np.argwhere(bad)[0]
        raise DataError(
            f"{target.name}: {int(bad.sum())} non-finite (NaN/Inf) values in the MERL table "
            f"(first at channel {c}, index ({i}, {j}, {k})); cannot fit {model_name}"
        )
    usable = target.table.valid.reshape(-1) & merl.grid_above_horizon().numpy()
    if not usable.any():
        raise DataError(f"{target.name}: no valid MERL cell above the horizon (all cells invalid); cannot fit {model_name}")
    return usable


def _bin_centre_theta_h(i: np.ndarray | float) -> np.ndarray | float:
    return ((np.asarray(i) + 0.5) / merl.RES_THETA_H) ** 2 * (math.pi / 2)


def _peak_statistics(target: Material, usable: np.ndarray, diffuse: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(peak excess RGB, its median θd, GGX-equivalent α from the half width)."""
    jd = PROFILE_THETA_D_BINS
    values = target.table.values[:, :, :jd, :]  # (3, 90, jd, 180)
    mask = usable.reshape(merl.SHAPE)[:, :jd, :]
    level = diffuse / math.pi

    head = mask[:2]
    if head.any():
        peak = np.array([np.median(values[c, :2][head]) for c in range(3)]) - level
        theta_d_bins = np.nonzero(head)[1]
        peak_theta_d = float((np.median(theta_d_bins) + 0.5) / merl.RES_THETA_D * (math.pi / 2))
    else:
        peak = np.zeros(3)
        peak_theta_d = math.radians(15.0)
    peak = np.maximum(peak, 0.0)

    mean = np.where(mask, values.mean(axis=0), np.nan).reshape(merl.RES_THETA_H, -1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-invalid θh bins give NaN
        profile = np.nanmedian(mean, axis=1) - level.mean()
    p0 = float(peak.mean())
    if not p0 > 0.05 * max(float(level.mean()), 1e-3):
        return peak, peak_theta_d, 0.5  # no clear specular peak: start broad
    theta_half = None
    prev_i, prev_p = 0, p0
    for i in range(1, merl.RES_THETA_H):
        p = profile[i]
        if not np.isfinite(p):
            continue
        if p < 0.5 * p0:
            t0, t1 = _bin_centre_theta_h(prev_i), _bin_centre_theta_h(i)
            w = (prev_p - 0.5 * p0) / max(prev_p - p, 1e-300)
            theta_half = float(t0 + min(max(w, 0.0), 1.0) * (t1 - t0))
            break
        prev_i, prev_p = i, p
    if theta_half is None:
        return peak, peak_theta_d, 1.0
    return peak, peak_theta_d, float(math.tan(theta_half) / HALF_WIDTH_PER_ALPHA)


def prepare(target: Material, n_samples: int, seed: int, model_name: str, loss: str = DEFAULT_LOSS) -> FitData:
    usable = _usable_cells(target, model_name)
    spec = LOSSES[loss]
    if spec.sampling == "cells":
        cells = np.flatnonzero(usable)
        # A seeded random order: any prefix (the coarse restarts use one) is a uniform subsample.
        rng = np.random.default_rng(seed)
        cells = rng.permutation(cells)[:n_samples]
        idx = torch.from_numpy(cells)
        wi_all, wo_all = merl.grid_directions(torch.float64)
        wi, wo = wi_all[idx], wo_all[idx]
    else:  # direction pairs drawn as the loss's authors weighted them, in random order too
        wi, wo, cells = sample_pairs(spec, n_samples, seed, usable)
    f = torch.from_numpy(target.table.values.reshape(3, -1)[:, cells].T.copy()).clamp_min(0.0)
    cos_i = wi[:, 2:3].clone()
    weights = (wi[:, 2] * wo[:, 2]).numpy()
    diffuse = np.array([math.pi * weighted_median(f[:, c].numpy(), weights) for c in range(3)])
    peak, peak_theta_d, alpha_est = _peak_statistics(target, usable, diffuse)
    return FitData(
        geom=geometry(wi, wo),
        cos_i=cos_i,
        y=compared(spec, f, cos_i),
        n_usable=int(usable.sum()),
        diffuse=diffuse,
        peak=peak,
        peak_theta_d=peak_theta_d,
        alpha_est=alpha_est,
        loss=spec,
        cells=cells,
    )


# --------------------------------------------------------------------------- optimisation


class _Space:
    """Maps the model's coefficients to and from the optimiser's bounded vector."""

    def __init__(self, coeffs):
        self.coeffs = coeffs
        self.bounds: list[tuple[float, float]] = []
        for c in coeffs:
            lo, hi = (math.log(c.lower), math.log(c.upper)) if c.log else (c.lower, c.upper)
            self.bounds += [(lo, hi)] * c.size

    def to_x(self, values: dict[str, Any]) -> np.ndarray:
        parts = []
        for c in self.coeffs:
            v = np.clip(np.broadcast_to(np.asarray(values[c.name], dtype=np.float64), (c.size,)), c.lower, c.upper)
            parts.append(np.log(v) if c.log else v)
        return np.concatenate(parts)

    def unpack(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        out, k = {}, 0
        for c in self.coeffs:
            v = x[k : k + c.size]
            out[c.name] = torch.exp(v) if c.log else v
            k += c.size
        return out


def _predict(cls, geom: Geometry, values: dict[str, torch.Tensor]) -> torch.Tensor:
    return cls.combine(values["kd"], values["ks"], cls.lobe(geom, cls.shape_of(values)))


def _peak_geometry(theta_d: float) -> Geometry:
    """θh = 0, θd = `theta_d`, φd = π/2: the pair at the centre of the specular peak."""
    s, c = math.sin(theta_d), math.cos(theta_d)
    wi = torch.tensor([[0.0, s, c]], dtype=torch.float64)
    wo = torch.tensor([[0.0, -s, c]], dtype=torch.float64)
    return geometry(wi, wo)


def _initial_alphas(data: FitData, restarts: int, lo: float) -> list[float]:
    alphas: list[float] = []
    for factor in RESTART_FACTORS:
        a = 0.5 if factor is None else data.alpha_est * factor
        a = float(min(max(a, lo), 1.0))
        if all(abs(math.log(a / b)) > math.log(1.5) for b in alphas):
            alphas.append(a)
        if len(alphas) == restarts:
            break
    return alphas


def fit_analytic(model: Representation, target: Material, *, seed: int = 0) -> FitResult:
    """Fit an analytic model (an `analytic.AnalyticBRDF`: its class gives NAME, COEFFS,
    `lobe`, `init_shape` and `combine`) to `target`."""
    with torch_threads(1):
        return _fit(model, target, seed)


def _fit(model: Representation, target: Material, seed: int) -> FitResult:
    cls = type(model)
    data = prepare(target, model.n_samples, seed, cls.NAME, getattr(model, "loss", DEFAULT_LOSS))
    space = _Space(cls.COEFFS)
    ks_spec = next(c for c in cls.COEFFS if c.name == "ks")
    peak_geom = _peak_geometry(data.peak_theta_d)
    level = data.diffuse / math.pi
    peak = np.maximum(data.peak, 0.05 * max(float(level.max()), 1e-3))
    n = data.y.shape[0]
    coarse = _Problem(cls, space, data, slice(0, min(n, COARSE_SAMPLES)))
    fine = _Problem(cls, space, data, slice(0, n))

    runs = []
    for alpha in _initial_alphas(data, model.restarts, ALPHA_INIT_MIN):
        shape = cls.init_shape(alpha)
        for c in cls.COEFFS:  # keep the initial shape inside the bounds
            if c.name in shape:
                shape[c.name] = min(max(shape[c.name], c.lower), c.upper)
        with torch.no_grad():
            init = cls.shape_of({c.name: torch.full((c.size,), float(shape[c.name]), dtype=torch.float64)
                                 for c in cls.COEFFS if c.name in shape})
            s_peak = float(cls.lobe(peak_geom, init).reshape(-1).mean())
        ks = np.clip(peak / max(s_peak, 1e-300), ks_spec.lower, ks_spec.upper)
        x0 = space.to_x({"kd": data.diffuse, "ks": ks, **shape})
        x, nit = coarse.minimize(x0, COARSE_MAX_ITER)
        runs.append([coarse.true_loss(x), alpha, nit, x])

    # Refine the best coarse runs on the whole subsample; keep the best refined one.
    order = sorted(range(len(runs)), key=lambda i: runs[i][0] if math.isfinite(runs[i][0]) else math.inf)[:REFINE_TOP]
    refined = []
    for i in order:
        x, nit = fine.minimize(runs[i][3], MAX_ITER)
        refined.append((fine.true_loss(x), i, nit, x))
    loss, best, nit, x = min(refined, key=lambda r: (r[0], r[1]))
    values = space.unpack(torch.from_numpy(x))
    info = {
        "restarts": len(runs),
        "best_restart": best,
        "restart_losses": [r[0] for r in runs],  # on the coarse subset
        "coarse_cells": int(min(n, COARSE_SAMPLES)),
        "initial_alphas": [r[1] for r in runs],
        "iterations": [r[2] for r in runs] + [nit],
        "n_fit_cells": int(n),
        "n_usable_cells": data.n_usable,
        "seed": int(seed),
        "loss": data.loss.name,
    }
    return FitResult({k: v.tolist() for k, v in values.items()}, float(loss), info)


class _Problem:
    """The surrogate objective and the true loss on the cells `rows` of the fit data."""

    def __init__(self, cls, space: _Space, data: FitData, rows: slice):
        self.cls, self.space = cls, space
        self.geom = Geometry(*(t[rows] for t in data.geom))
        self.cos_i, self.y = data.cos_i[rows], data.y[rows]
        self.loss = data.loss

    def residual(self, x: torch.Tensor) -> torch.Tensor:
        pred = _predict(self.cls, self.geom, self.space.unpack(x))
        return compared(self.loss, pred, self.cos_i) - self.y

    def objective(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        xt = torch.from_numpy(x).requires_grad_(True)
        r = self.residual(xt)
        if self.loss.power == 1:
            loss = (torch.sqrt(r * r + EPSILON * EPSILON) - EPSILON).mean()
        else:
            loss = (r * r).mean()
        if not bool(torch.isfinite(loss.detach())):
            return 1e30, np.zeros_like(x)
        loss.backward()
        return float(loss.detach()), xt.grad.numpy().copy()

    def true_loss(self, x: np.ndarray) -> float:
        with torch.no_grad():
            r = self.residual(torch.from_numpy(x))
            return float((r.abs() if self.loss.power == 1 else r * r).mean())

    def minimize(self, x0: np.ndarray, max_iter: int) -> tuple[np.ndarray, int]:
        res = minimize(
            self.objective,
            x0,
            jac=True,
            method="L-BFGS-B",
            bounds=self.space.bounds,
            options={"maxiter": max_iter, "ftol": FTOL, "gtol": GTOL},
        )
        return res.x, int(res.nit)
