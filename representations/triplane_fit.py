"""Fitting many tripleplane models at once on a CPU: stacked textures and decoders, one
shared minibatch, a hand-written Adam over the stack.

As the NBRDF fitter (nbrdf_fit.py): every material sees the same training pairs, drawn
uniformly in (θh, θd, φd) with pairs below the horizon dropped for all and each material's
invalid cells dropped for it alone; each material's loss is normalised by its own valid
count and Adam is elementwise, so a material's fit does not depend on its batch-mates.

What seed 002 (Sec. 4.3–4.5) prescribes for every model it trains, kept here:
- the textures are optimised through a frequency-domain blur of raw variables, weights
  1/(1 + A·√(fx² + fy²)) (A = 5 for angular textures): a preconditioner, not a penalty, so
  the optimum is unchanged (the weights are positive, the map invertible);
- the loss λ·‖f − exp g‖² / ‖sg(exp g) + ε‖² + (1 − λ)·‖f − exp g‖², λ = 0.9999, ε = 1e-6
  (`loss="mixed"`); `loss="log_l1"` is NBRDF's |log(1 + f cos θi) − log(1 + f̂ cos θi)|;
- Adam (β2 0.999, ε 1e-15) and, optionally, an exponential moving average of the
  parameters (`ema`, the paper's smoothing 0.005) whose value is the fitted model.
The paper trains about 100k iterations of 2^18 pairs per material on a GPU; the schedule
here (epochs over a fixed draw, one-cycle learning rates) is sized for a CPU, a few
thousand steps. At that length the paper's choices cost accuracy, so the defaults differ
(measured on synthetic materials 0, 1, 7 and 13, README): an EMA with smoothing 0.005
averages over about 200 steps, a tenth of the run, and keeps early iterates in the model
(l1_log_cos 0.047 with it, 0.021 without, on the chrome); the mixed loss ends at two to
four times the log-L1 loss's l1_log_cos and a higher HDR RMSE. The default loss is the one
`nbrdf` trains with, so the two compare on one footing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import torch
from tqdm.auto import tqdm

from brdfbench import merl
from brdfbench.errors import ConfigError

from . import triplane_model as tm
from .nbrdf_fit import COS_MIN, Samples, adam_update, draw_samples, one_cycle

LOSSES = ("mixed", "log_l1")
TEXTURE_NAMES = ("H", "D", "D_pole")
MIXED_LAMBDA = 0.9999
MIXED_EPS = 1e-6
LOSS_MAX_LOG = 40.0  # exp(2·40) stays finite in fp32 inside the squared error
ADAM_BETA2, ADAM_EPS = 0.999, 1e-15  # seed 002's


@dataclass(frozen=True)
class Recipe:
    """How a tripleplane model trains."""

    epochs: int = 20
    batch_size: int = 4096
    n_samples: int = 800_000  # drawn before dropping pairs below the horizon (about 62 % stay)
    lr: float = 2e-2  # decoder, one-cycle peak
    texture_lr: float = 5e-2
    loss: str = "log_l1"
    beta1: float = 0.9
    ema: float | None = None  # smoothing factor of the parameter average; None: the last iterate
    precondition: float = 5.0  # A of the blur; 0 turns it off
    init_scale: float = 0.1  # std of the raw texture variables at the start
    owner: str = "tripleplane"  # the plugin named in errors

    def __post_init__(self):
        def bad(key, why):
            raise ConfigError(f"{self.owner}: {key}={getattr(self, key)!r}: {why}")

        for key in ("epochs", "batch_size", "n_samples"):
            v = getattr(self, key)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                bad(key, "must be a positive integer")
        for key in ("lr", "texture_lr", "init_scale"):
            v = getattr(self, key)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
                bad(key, "must be a positive number")
        if self.loss not in LOSSES:
            bad("loss", f"expected one of {', '.join(LOSSES)}")
        if not isinstance(self.beta1, (int, float)) or not 0 <= self.beta1 < 1:
            bad("beta1", "must lie in [0, 1)")
        if self.ema is not None and (not isinstance(self.ema, (int, float)) or not 0 < self.ema <= 1):
            bad("ema", "must lie in (0, 1], or be null for the last iterate")
        if not isinstance(self.precondition, (int, float)) or not math.isfinite(self.precondition) or self.precondition < 0:
            bad("precondition", "must be a non-negative number")


def blur_weights(shape: Sequence[int], strength: float) -> torch.Tensor:
    """1 / (1 + A·√(fx² + fy² …)) over the FFT frequencies of `shape` (cycles per texel)."""
    freqs = torch.meshgrid(*(torch.fft.fftfreq(n, dtype=torch.float64) for n in shape), indexing="ij")
    radius = torch.sqrt(sum(f * f for f in freqs))
    return (1.0 / (1.0 + strength * radius)).to(torch.float32)


def blur(raw: torch.Tensor, weights: torch.Tensor | None, dims: tuple[int, ...]) -> torch.Tensor:
    """The texture of raw variables (M, …, C): filtered over `dims` in the frequency domain."""
    if weights is None:
        return raw
    spectrum = torch.fft.fftn(raw, dim=dims)
    shape = [1] * raw.ndim
    for d, n in zip(dims, weights.shape):
        shape[d] = n
    return torch.fft.ifftn(spectrum * weights.reshape(shape), dim=dims).real


def sample_coords(samples: Samples) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(r_h, r_d, φ) of the shared training pairs, from their Rusinkiewicz encoding."""
    x = samples.x
    r_d = torch.hypot(x[:, 3], x[:, 4])
    phi = torch.remainder(torch.atan2(x[:, 4], x[:, 3]), tm.D_PERIOD)
    return x[:, 0].clamp(0.0, 1.0), r_d.clamp(0.0, 1.0), phi


def targets(table: merl.MerlTable, samples: Samples) -> tuple[torch.Tensor, torch.Tensor]:
    """f (S, 3) float32 in 1/sr at the samples and the valid mask (S,)."""
    values = torch.from_numpy(table.values.reshape(3, -1))[:, samples.cells].T
    valid = (values >= 0).all(dim=1) & torch.isfinite(values).all(dim=1)
    return values.clamp(min=0).nan_to_num(0.0).to(torch.float32), valid


def initial_state(shape: tm.Shape, log_mean: torch.Tensor, generator: torch.Generator, init_scale: float) -> dict:
    """Raw variables of one material: small random textures, Glorot-uniform decoder, the
    last bias at the material's mean log value (so training starts at the right level)."""
    out = {}
    for name, s in shape.tensor_shapes().items():
        if name in TEXTURE_NAMES:
            out[name] = torch.randn(s, generator=generator) * init_scale
        elif name.startswith("W"):
            limit = math.sqrt(6.0 / (s[0] + s[1]))
            out[name] = (torch.rand(s, generator=generator) * 2 - 1) * limit
        elif name == "z_s":
            out[name] = torch.full(s, 1.0 / math.sqrt(s[0]))
        elif name.endswith("_alpha"):  # raw: α = 1/2 + softplus(raw), started near the identity
            alpha = torch.linspace(0.9, 1.1, s[0]) if s[0] > 1 else torch.ones(1)
            out[name] = torch.log(torch.expm1(alpha - tm.WARP_ALPHA_MIN))
        else:  # biases; a warp's raw weights (softmax: equal shares)
            out[name] = torch.zeros(s)
    out[f"b{len(shape.hidden) + 1}"] = log_mean.to(torch.float32).clone()
    return out


@dataclass
class Outcome:
    tensors: dict[str, torch.Tensor]  # the fitted model's tensors (textures blurred), one material
    loss: float
    curve: list[float]


class _Stack:
    """Raw variables of M materials with their Adam moments and parameter average."""

    TEXTURES = {"H": (1,), "D": (1, 2)}  # raw → blurred over these dims

    def __init__(self, shape: tm.Shape, inits: Sequence[dict], recipe: Recipe):
        self.shape, self.recipe = shape, recipe
        self.params = {}
        for name in shape.tensor_shapes():
            t = torch.stack([w[name].to(torch.float32) for w in inits])
            if name.startswith("b"):
                t = t[:, None, :]
            self.params[name] = t.contiguous().requires_grad_()
        self.m = {k: torch.zeros_like(p) for k, p in self.params.items()}
        self.v = {k: torch.zeros_like(p) for k, p in self.params.items()}
        self.avg = {k: p.detach().clone() for k, p in self.params.items()} if recipe.ema else None
        self.t = 0
        a = recipe.precondition
        self.blur = {"H": blur_weights(self.params["H"].shape[1:2], a) if a > 0 else None,
                     "D": blur_weights(self.params["D"].shape[1:3], a) if a > 0 else None}

    def effective(self, params: dict) -> dict:
        """The model's tensors from raw variables: textures blurred; a warp's exponents
        α = 1/2 + softplus(raw) (bounded below as seed 002 bounds them) and its weights a
        softmax (a partition of unity)."""
        out = dict(params)
        for name, dims in self.TEXTURES.items():
            out[name] = blur(params[name], self.blur[name], dims)
        for tex in ("h", "d") if self.shape.warps else ():
            out[f"warp_{tex}_alpha"] = tm.WARP_ALPHA_MIN + torch.nn.functional.softplus(params[f"warp_{tex}_alpha"])
            out[f"warp_{tex}_weight"] = torch.softmax(params[f"warp_{tex}_weight"], dim=-1)
        return out

    @torch.no_grad()
    def adam_step(self, lr: float, texture_lr: float) -> None:
        self.t += 1
        for name, p in self.params.items():
            rate = texture_lr if name in TEXTURE_NAMES else lr
            adam_update(p, self.m[name], self.v[name], rate, self.t, (self.recipe.beta1, ADAM_BETA2), ADAM_EPS)
            if self.avg is not None:
                self.avg[name].lerp_(p, self.recipe.ema)

    @torch.no_grad()
    def fitted(self, row: int) -> dict[str, torch.Tensor]:
        source = self.avg if self.avg is not None else {k: p.detach() for k, p in self.params.items()}
        eff = self.effective({k: t[row:row + 1] for k, t in source.items()})
        return {k: (t[0, 0] if k.startswith("b") else t[0]).clone().contiguous() for k, t in eff.items()}


def batch_loss(g: torch.Tensor, f: torch.Tensor, mask: torch.Tensor, cos_i: torch.Tensor, loss: str) -> torch.Tensor:
    """Per-sample loss (M, B) of log predictions g against targets f, zero where invalid."""
    g = g.clamp(max=LOSS_MAX_LOG)
    if loss == "mixed":
        e = torch.exp(g)
        sq = (f - e) ** 2
        err = MIXED_LAMBDA * sq / (e.detach() + MIXED_EPS) ** 2 + (1 - MIXED_LAMBDA) * sq
    else:
        c = cos_i[None, :, None]
        err = (torch.log1p(f * c) - torch.nn.functional.softplus(g + torch.log(c))).abs()  # log(1 + exp(g)·c)
    return err.mean(dim=2) * mask


def fit_batched(tables: Sequence[merl.MerlTable], init_seeds: Sequence[int], shape: tm.Shape, recipe: Recipe, *,
                sample_seed: int = 0, progress: bool | str = False) -> list[Outcome]:
    """One fitted tripleplane per table, all in one pass; each starts from `initial_state`
    drawn with its own seed (so it does not depend on its batch-mates)."""
    if len(tables) != len(init_seeds) or not tables:
        raise ValueError(f"fit_batched needs one initial seed per table, got {len(init_seeds)} for {len(tables)}")
    samples = draw_samples(recipe.n_samples, "rusinkiewicz", sample_seed)
    r_h, r_d, phi = sample_coords(samples)
    cos_i = samples.cos_i.clamp(COS_MIN, 1 - 2.0**-24)
    f, valid = zip(*(targets(t, samples) for t in tables))
    y, mask = torch.stack(f), torch.stack(valid).to(torch.float32)
    if (mask.sum(dim=1) == 0).any():
        raise ValueError("a target material has no valid cell at the training samples")
    log_means = (torch.log(y + MIXED_EPS) * mask[:, :, None]).sum(dim=1) / mask.sum(dim=1)[:, None]
    inits = [initial_state(shape, log_means[i], torch.Generator().manual_seed(seed), recipe.init_scale)
             for i, seed in enumerate(init_seeds)]
    stack = _Stack(shape, inits, recipe)
    n = samples.x.shape[0]
    steps = math.ceil(n / recipe.batch_size)
    total = recipe.epochs * steps
    order = torch.Generator().manual_seed(sample_seed + 1)
    curves: list[list[float]] = [[] for _ in tables]
    step = 0
    bar = tqdm(range(recipe.epochs), desc=progress if isinstance(progress, str) else "tripleplane fit", unit="epoch",
               disable=not progress, leave=False, dynamic_ncols=True)
    for _ in bar:
        perm = torch.randperm(n, generator=order)
        sums, counts = torch.zeros(len(tables)), torch.zeros(len(tables))
        for start in range(0, n, recipe.batch_size):
            idx = perm[start:start + recipe.batch_size]
            eff = stack.effective(stack.params)
            g = tm.log_value(eff, r_h[idx], r_d[idx], phi[idx])
            m = mask[:, idx]
            err = batch_loss(g, y[:, idx], m, cos_i[idx], recipe.loss)
            count = m.sum(dim=1)
            (err.sum(dim=1) / count.clamp(min=1)).sum().backward()
            stack.adam_step(one_cycle(recipe.lr, step, total), one_cycle(recipe.texture_lr, step, total))
            step += 1
            sums += err.detach().sum(dim=1)
            counts += count
        losses = sums / counts.clamp(min=1)
        for curve, value in zip(curves, losses.tolist()):
            curve.append(value)
        bar.set_postfix(median_loss=f"{float(losses.median()):.4g}")
    bar.close()
    return [Outcome(stack.fitted(i), curves[i][-1], curves[i]) for i in range(len(tables))]
