"""Fitting many tripleplane models at once: stacked textures and decoders, one shared
minibatch, a hand-written Adam over the stack; on the CPU or on a GPU.

As the NBRDF fitter (nbrdf_fit.py): every material sees the same training pairs, drawn
uniformly in (θh, θd, φd) with pairs below the horizon dropped for all and each material's
invalid cells dropped for it alone; each material's loss is normalised by its own valid
count and Adam is elementwise, so a material's fit does not depend on its batch-mates.

What Timonen, Kemppinen and Lehtinen ("A Real-Time Multi-Scale Neural Representation for
Complex Surface Reflectance", Sec. 4.3–4.5) prescribe for every model they train, kept here:
- the textures are optimised through a frequency-domain blur of raw variables, weights
  1/(1 + A·√(fx² + fy²)) (A = 5 for angular textures): a preconditioner, not a penalty, so
  the optimum is unchanged (the weights are positive, the map invertible);
- the loss λ·‖f − exp g‖² / ‖sg(exp g) + ε‖² + (1 − λ)·‖f − exp g‖², λ = 0.9999, ε = 1e-6
  (`loss="mixed"`); `loss="log_l1"` is NBRDF's |log(1 + f cos θi) − log(1 + f̂ cos θi)|;
- Adam (β2 0.999, ε 1e-15) and, optionally, an exponential moving average of the
  parameters (`ema`, the paper's smoothing 0.005) whose value is the fitted model.
The paper trains about 100k iterations of 2^18 pairs per material on a GPU, each batch
drawn afresh with cosine-weighted directions, at a learning rate of 3e-3 decayed by 0.9
every 10k iterations, Adam β1 0.99. The default schedule here (epochs over a fixed draw,
one-cycle learning rates) is sized for a CPU, a few thousand steps. At that length the
paper's choices cost accuracy, so the defaults differ (measured on synthetic materials 0,
1, 7 and 13, README): an EMA with smoothing 0.005 averages over about 200 steps, a tenth of
the run, and keeps early iterates in the model (l1_log_cos 0.047 with it, 0.021 without,
on the chrome); the mixed loss ends at two to four times the log-L1 loss's l1_log_cos and a
higher HDR RMSE. The default loss is the one `nbrdf` trains with, so the two compare on one
footing. The paper's schedule is one set of options away (conf/representation/
triplane_gated_paper.yaml): `iterations` (a step count instead of epochs), `resample`
(fresh pairs every step instead of minibatches of a fixed draw), `sampling="cosine"`
(ωi and ωo cosine-weighted, the paper's draw) and `schedule="step"` (`lr` times
`lr_decay` every `lr_decay_every` steps). With every one at its default the fit is the
one it always was, bit for bit.

On a GPU (`device`), the draw (or, with `resample`, the MERL tables), the targets and the
stacked parameters move there once per call; each step gathers (or draws) its minibatch
there, Adam reads its learning rates and bias corrections from a schedule precomputed for
the whole run in device memory (`adam_schedule`), and the epoch's losses accumulate there
and are read once per epoch, so the host never waits for the device inside an epoch. The
steps run eagerly (no CUDA graphs: at the default minibatch a step is ~200 small kernels,
about a millisecond of launches; at the paper's 2^18 pairs the kernels dominate). The
arithmetic is the CPU path's, reassociated in the Adam update only; a GPU fit is not the
CPU fit bit for bit (see tests/gpu/test_triplane_gpu.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch
from tqdm.auto import tqdm

from brdfbench import merl
from brdfbench.errors import ConfigError

from . import triplane_model as tm
from .nbrdf_fit import COS_MIN, Samples, adam_update, adam_update_scheduled, draw_samples, one_cycle

LOSSES = ("mixed", "log_l1")
SAMPLINGS = ("uniform", "cosine")
SCHEDULES = ("onecycle", "step")
TEXTURE_NAMES = ("H", "D", "D_pole")
MIXED_LAMBDA = 0.9999
MIXED_EPS = 1e-6
LOSS_MAX_LOG = 40.0  # exp(2·40) stays finite in fp32 inside the squared error
ADAM_BETA2, ADAM_EPS = 0.999, 1e-15  # Timonen et al.'s
COS_MAX = 1 - 2.0**-24
#: Pairs of the draw that sets each material's starting level (the last bias) when the
#: training pairs are drawn afresh every step (`resample`): a fixed CPU draw, the same on
#: every device.
LEVEL_PAIRS = 2**18
#: Share of a uniform (θh, θd, φd) draw above the horizon (for cost estimates).
UNIFORM_KEPT = 0.62

#: Tests set this to run the GPU path's arithmetic (Adam from the device schedule) on the
#: CPU, where CI can check it against the CPU path.
_DEVICE_PATH_ON_CPU = False


@dataclass(frozen=True)
class Recipe:
    """How a tripleplane model trains."""

    epochs: int = 20
    batch_size: int = 4096
    n_samples: int = 800_000  # drawn before dropping pairs below the horizon (about 62 % stay); with
    # `resample`, the pairs of one epoch (ceil(n_samples / batch_size) steps between loss readings)
    lr: float = 2e-2  # decoder, one-cycle peak (the start of a "step" schedule)
    texture_lr: float = 5e-2
    loss: str = "log_l1"
    beta1: float = 0.9
    ema: float | None = None  # smoothing factor of the parameter average; None: the last iterate
    precondition: float = 5.0  # A of the blur; 0 turns it off
    init_scale: float = 0.1  # std of the raw texture variables at the start
    iterations: int | None = None  # Adam steps in all; None: `epochs` passes over the draw
    resample: bool = False  # fresh training pairs every step instead of minibatches of one draw
    sampling: str = "uniform"  # "uniform" in (θh, θd, φd), or "cosine": ωi and ωo cosine-weighted
    schedule: str = "onecycle"  # or "step": lr · lr_decay^⌊step / lr_decay_every⌋
    lr_decay: float = 0.9
    lr_decay_every: int = 10_000
    owner: str = "tripleplane"  # the plugin named in errors

    def __post_init__(self):
        def bad(key, why):
            raise ConfigError(f"{self.owner}: {key}={getattr(self, key)!r}: {why}")

        def positive_int(v) -> bool:
            return isinstance(v, int) and not isinstance(v, bool) and v >= 1

        for key in ("epochs", "batch_size", "n_samples", "lr_decay_every"):
            if not positive_int(getattr(self, key)):
                bad(key, "must be a positive integer")
        if self.iterations is not None and not positive_int(self.iterations):
            bad("iterations", "must be a positive integer, or null for `epochs` passes over the draw")
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
        if not isinstance(self.resample, bool):
            bad("resample", "must be true or false")
        if self.sampling not in SAMPLINGS:
            bad("sampling", f"expected one of {', '.join(SAMPLINGS)}")
        if self.schedule not in SCHEDULES:
            bad("schedule", f"expected one of {', '.join(SCHEDULES)}")
        if not isinstance(self.lr_decay, (int, float)) or isinstance(self.lr_decay, bool) or not 0 < self.lr_decay <= 1:
            bad("lr_decay", "must lie in (0, 1]")

    def steps_per_epoch(self, n_pairs: int | None = None) -> int:
        """Steps between loss readings: over the `n_pairs` kept pairs of a fixed draw (an
        estimate from n_samples where not given), or n_samples fresh pairs with `resample`."""
        if n_pairs is None or self.resample:
            kept = 1.0 if self.resample or self.sampling == "cosine" else UNIFORM_KEPT
            n_pairs = max(1, int(self.n_samples * kept))
        return math.ceil(n_pairs / self.batch_size)

    def total_steps(self, n_pairs: int | None = None) -> int:
        """Adam steps of a fit (`n_pairs`: as in `steps_per_epoch`)."""
        return self.iterations if self.iterations is not None else self.epochs * self.steps_per_epoch(n_pairs)

    def rates(self, step: int, total: int) -> tuple[float, float]:
        """(decoder, texture) learning rates at `step` of `total`."""
        if self.schedule == "step":
            factor = self.lr_decay ** (step // self.lr_decay_every)
            return self.lr * factor, self.texture_lr * factor
        return one_cycle(self.lr, step, total), one_cycle(self.texture_lr, step, total)


def training_flops(recipe: Recipe, shape: tm.Shape) -> float:
    """FLOPs of one material's fit, estimated: steps × pairs × (forward + backward ≈ 3 × the
    model's evaluation FLOPs)."""
    return float(recipe.total_steps()) * recipe.batch_size * 3 * shape.flops()


def adam_schedule(recipe: Recipe, total: int, device: torch.device) -> torch.Tensor:
    """(total, 2, 2) float32 on `device`: at each step, for the decoder (row 0) and the
    textures (row 1), `adam_update_scheduled`'s (lr / (1 − β₁ᵗ), 1 / (1 − β₂ᵗ))."""
    b1 = recipe.beta1
    rows = []
    for s in range(total):
        lr, texture_lr = recipe.rates(s, total)
        c1, c2 = 1 - b1 ** (s + 1), 1 / (1 - ADAM_BETA2 ** (s + 1))
        rows.append(((lr / c1, c2), (texture_lr / c1, c2)))
    return torch.tensor(rows, dtype=torch.float32).to(device)


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


def merl_cells(theta_h: torch.Tensor, theta_d: torch.Tensor, phi_d: torch.Tensor) -> torch.Tensor:
    """Flat MERL cell indices (nearest cell below, as the reader's) of angles, in torch on
    their device (φd in [0, 2π) or [−π, π], folded by reciprocity). brdfbench.merl's
    indices are numpy's, exact at the cells' edges; for training pairs torch's suffice."""
    t = theta_h.clamp(min=0.0)
    u_h = torch.sqrt(t / (math.pi / 2) * (merl.RES_THETA_H * merl.RES_THETA_H))
    u_d = theta_d / (math.pi / 2) * merl.RES_THETA_D
    p = torch.where(phi_d < 0, phi_d + math.pi, torch.where(phi_d > math.pi, phi_d - math.pi, phi_d))
    u_p = p / math.pi * merl.RES_PHI_D
    i_h = torch.floor(u_h).clamp(0, merl.RES_THETA_H - 1).long()
    i_d = torch.floor(u_d).clamp(0, merl.RES_THETA_D - 1).long()
    i_p = torch.floor(u_p).clamp(0, merl.RES_PHI_D - 1).long()
    return (i_h * merl.RES_THETA_D + i_d) * merl.RES_PHI_D + i_p


@dataclass
class Pairs:
    """Training pairs shared by every material: texture coordinates, cos θi, MERL cells and
    whether the pair is above the horizon (a float mask)."""

    r_h: torch.Tensor
    r_d: torch.Tensor
    phi: torch.Tensor
    cos_i: torch.Tensor
    cells: torch.Tensor
    above: torch.Tensor


def draw_pairs(n: int, sampling: str, generator: torch.Generator, device: torch.device) -> Pairs:
    """n pairs drawn with `generator` (on `device`): "uniform" in (θh, θd, φd) with φh = 0,
    or "cosine": ωi and ωo independently cosine-weighted about the normal (Timonen et al.,
    Sec. 4.2). Pairs below the horizon are kept, marked in `above` (a uniform draw loses
    about 38 %; a cosine-weighted one none). Elementwise kernels only (no host value is
    copied in), so a draw on a GPU never waits for the host."""
    u = torch.rand(4, n, generator=generator, device=device, dtype=torch.float64)
    if sampling == "cosine":
        wi, wo = _cosine_direction(u[0], u[1]), _cosine_direction(u[2], u[3])
        h = wi + wo  # both above the horizon: never zero
        h = h / torch.linalg.vector_norm(h, dim=0)
        rho = torch.hypot(h[0], h[1])
        theta_h = torch.atan2(rho, h[2])
        safe = torch.where(rho > 0, rho, torch.ones_like(rho))
        cos_p = torch.where(rho > 0, h[0] / safe, torch.ones_like(rho))
        sin_p = torch.where(rho > 0, h[1] / safe, torch.zeros_like(rho))
        x, y = cos_p * wi[0] + sin_p * wi[1], cos_p * wi[1] - sin_p * wi[0]  # ωi rotated by −φh about z
        dx, dz = h[2] * x - rho * wi[2], rho * x + h[2] * wi[2]  # then by −θh about y
        theta_d = torch.atan2(torch.hypot(dx, y), dz)
        phi_d = torch.atan2(y, dx)  # [−π, π]; merl_cells and the texture read fold it
        cos_i, cos_o = wi[2], wo[2]
    else:
        theta_h, theta_d, phi_d = u[0] * (math.pi / 2), u[1] * (math.pi / 2), u[2] * (2 * math.pi)
        dx, dz = torch.sin(theta_d) * torch.cos(phi_d), torch.cos(theta_d)
        st, ct = torch.sin(theta_h), torch.cos(theta_h)
        cos_i, cos_o = ct * dz - st * dx, ct * dz + st * dx  # ωi = Ry(θh) d, ωo = Ry(θh) (−dx, −dy, dz)
    above = (cos_i > 0) & (cos_o > 0)
    return Pairs(r_h=torch.sin(theta_h).clamp(0.0, 1.0).to(torch.float32),
                 r_d=torch.sin(theta_d).clamp(0.0, 1.0).to(torch.float32),
                 phi=torch.remainder(phi_d, tm.D_PERIOD).to(torch.float32),
                 cos_i=cos_i.clamp(COS_MIN, COS_MAX).to(torch.float32),
                 cells=merl_cells(theta_h, theta_d, phi_d),
                 above=above.to(torch.float32))


def _cosine_direction(u1: torch.Tensor, u2: torch.Tensor) -> torch.Tensor:
    """(3, n) unit vectors cosine-distributed about +z (Malley: a uniform disk point lifted)."""
    rho, a = torch.sqrt(u1), u2 * (2 * math.pi)
    return torch.stack((rho * torch.cos(a), rho * torch.sin(a), torch.sqrt(1 - u1)))


def table_targets(table: merl.MerlTable) -> tuple[torch.Tensor, torch.Tensor]:
    """A whole table as `targets` reads it: f (cells, 3) float32 and the valid mask (cells,)."""
    values = torch.from_numpy(np.ascontiguousarray(table.values.reshape(3, -1).T))
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
    tensors: dict[str, torch.Tensor]  # the fitted model's tensors (textures blurred), one material, on the fit's device
    loss: float
    curve: list[float]


class _Stack:
    """Raw variables of M materials with their Adam moments and parameter average, on `device`."""

    TEXTURES = {"H": (1,), "D": (1, 2)}  # raw → blurred over these dims

    def __init__(self, shape: tm.Shape, inits: Sequence[dict], recipe: Recipe, device: torch.device | str = "cpu"):
        device = torch.device(device)
        self.shape, self.recipe = shape, recipe
        self.params = {}
        for name in shape.tensor_shapes():
            t = torch.stack([w[name].to(torch.float32) for w in inits]).to(device)
            if name.startswith("b"):
                t = t[:, None, :]
            self.params[name] = t.contiguous().requires_grad_()
        self.m = {k: torch.zeros_like(p) for k, p in self.params.items()}
        self.v = {k: torch.zeros_like(p) for k, p in self.params.items()}
        self.avg = {k: p.detach().clone() for k, p in self.params.items()} if recipe.ema else None
        self.t = 0
        a = recipe.precondition
        self.blur = {"H": blur_weights(self.params["H"].shape[1:2], a).to(device) if a > 0 else None,
                     "D": blur_weights(self.params["D"].shape[1:3], a).to(device) if a > 0 else None}

    def effective(self, params: dict) -> dict:
        """The model's tensors from raw variables: textures blurred; a warp's exponents
        α = 1/2 + softplus(raw) (bounded below as the paper bounds them) and its weights a
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
        """Adam with host scalars (the CPU path)."""
        self.t += 1
        for name, p in self.params.items():
            rate = texture_lr if name in TEXTURE_NAMES else lr
            adam_update(p, self.m[name], self.v[name], rate, self.t, (self.recipe.beta1, ADAM_BETA2), ADAM_EPS)
            if self.avg is not None:
                self.avg[name].lerp_(p, self.recipe.ema)

    @torch.no_grad()
    def adam_step_scheduled(self, hyper: torch.Tensor) -> None:
        """Adam with the step's scalars read from device memory, `hyper` (2, 2) a row of
        `adam_schedule` (the device path: no host value enters the kernels)."""
        self.t += 1
        for name, p in self.params.items():
            h = hyper[1] if name in TEXTURE_NAMES else hyper[0]
            adam_update_scheduled(p, self.m[name], self.v[name], h, (self.recipe.beta1, ADAM_BETA2), ADAM_EPS)
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


class _FixedDraw:
    """Minibatches of one draw of `recipe.n_samples` pairs (pairs below the horizon dropped),
    reshuffled every epoch; the draw and the targets live on `device`."""

    def __init__(self, tables, recipe: Recipe, sample_seed: int, device: torch.device):
        if recipe.sampling == "uniform":  # the draw every fit made before there was another
            samples = draw_samples(recipe.n_samples, "rusinkiewicz", sample_seed)
            r_h, r_d, phi = sample_coords(samples)
            cos_i = samples.cos_i.clamp(COS_MIN, COS_MAX)
        else:
            pairs = draw_pairs(recipe.n_samples, recipe.sampling, torch.Generator().manual_seed(sample_seed),
                               torch.device("cpu"))
            keep = pairs.above > 0
            r_h, r_d, phi, cos_i = pairs.r_h[keep], pairs.r_d[keep], pairs.phi[keep], pairs.cos_i[keep]
            samples = Samples(x=torch.empty(0), cos_i=cos_i, cells=pairs.cells[keep])
        f, valid = zip(*(targets(t, samples) for t in tables))
        y, mask = torch.stack(f), torch.stack(valid).to(torch.float32)
        if (mask.sum(dim=1) == 0).any():
            raise ValueError("a target material has no valid cell at the training samples")
        self.log_means = (torch.log(y + MIXED_EPS) * mask[:, :, None]).sum(dim=1) / mask.sum(dim=1)[:, None]
        self.n = r_h.shape[0]
        self.r_h, self.r_d, self.phi, self.cos_i = (t.to(device) for t in (r_h, r_d, phi, cos_i))
        self.y, self.mask = y.to(device), mask.to(device)
        self.device, self.batch = device, recipe.batch_size
        self.order = torch.Generator().manual_seed(sample_seed + 1)
        self.perm = None

    def start_epoch(self) -> None:
        self.perm = torch.randperm(self.n, generator=self.order).to(self.device)

    def batch_at(self, k: int):
        idx = self.perm[k * self.batch:(k + 1) * self.batch]
        return self.r_h[idx], self.r_d[idx], self.phi[idx], self.cos_i[idx], self.y[:, idx], self.mask[:, idx]


class _FreshDraws:
    """`recipe.batch_size` fresh pairs every step, drawn on `device` (its generator seeded
    with the sample seed), the targets read there from the whole MERL tables."""

    def __init__(self, tables, recipe: Recipe, sample_seed: int, device: torch.device):
        values, valid = zip(*(table_targets(t) for t in tables))
        self.values = torch.stack(values).to(device)  # (M, cells, 3)
        self.valid = torch.stack(valid).to(torch.float32).to(device)  # (M, cells)
        level = draw_pairs(LEVEL_PAIRS, recipe.sampling, torch.Generator().manual_seed(sample_seed), torch.device("cpu"))
        cells = level.cells[level.above > 0]
        y = torch.stack([v[cells] for v in values])
        mask = torch.stack([m[cells] for m in valid]).to(torch.float32)
        if (mask.sum(dim=1) == 0).any():
            raise ValueError("a target material has no valid cell at the training samples")
        self.log_means = (torch.log(y + MIXED_EPS) * mask[:, :, None]).sum(dim=1) / mask.sum(dim=1)[:, None]
        self.generator = torch.Generator(device=device).manual_seed(sample_seed + 1)
        self.device, self.batch, self.sampling = device, recipe.batch_size, recipe.sampling

    def start_epoch(self) -> None:
        pass

    def batch_at(self, k: int):
        p = draw_pairs(self.batch, self.sampling, self.generator, self.device)
        mask = self.valid.index_select(1, p.cells) * p.above
        return p.r_h, p.r_d, p.phi, p.cos_i, self.values.index_select(1, p.cells), mask


def fit_batched(tables: Sequence[merl.MerlTable], init_seeds: Sequence[int], shape: tm.Shape, recipe: Recipe, *,
                sample_seed: int = 0, progress: bool | str = False,
                device: torch.device | str = "cpu") -> list[Outcome]:
    """One fitted tripleplane per table, all in one pass on `device` (where the outcomes'
    tensors live); each starts from `initial_state` drawn with its own seed (so it does not
    depend on its batch-mates)."""
    if len(tables) != len(init_seeds) or not tables:
        raise ValueError(f"fit_batched needs one initial seed per table, got {len(init_seeds)} for {len(tables)}")
    device = torch.device(device)
    data = (_FreshDraws if recipe.resample else _FixedDraw)(tables, recipe, sample_seed, device)
    inits = [initial_state(shape, data.log_means[i], torch.Generator().manual_seed(seed), recipe.init_scale)
             for i, seed in enumerate(init_seeds)]
    stack = _Stack(shape, inits, recipe, device)
    per_epoch = recipe.steps_per_epoch(None if recipe.resample else data.n)
    total = recipe.total_steps(None if recipe.resample else data.n)
    scheduled = device.type != "cpu" or _DEVICE_PATH_ON_CPU
    schedule = adam_schedule(recipe, total, device) if scheduled else None
    curves: list[list[float]] = [[] for _ in tables]
    step = 0
    bar = tqdm(range(math.ceil(total / per_epoch)), desc=progress if isinstance(progress, str) else "tripleplane fit",
               unit="epoch", disable=not progress, leave=False, dynamic_ncols=True)
    for _ in bar:
        data.start_epoch()
        sums = torch.zeros(len(tables), device=device)
        counts = torch.zeros(len(tables), device=device)
        for k in range(min(per_epoch, total - step)):
            r_h, r_d, phi, cos_i, y, m = data.batch_at(k)
            eff = stack.effective(stack.params)
            g = tm.log_value(eff, r_h, r_d, phi)
            err = batch_loss(g, y, m, cos_i, recipe.loss)
            count = m.sum(dim=1)
            (err.sum(dim=1) / count.clamp(min=1)).sum().backward()
            if scheduled:
                stack.adam_step_scheduled(schedule[step])
            else:
                stack.adam_step(*recipe.rates(step, total))
            step += 1
            sums += err.detach().sum(dim=1)
            counts += count
        losses = (sums / counts.clamp(min=1)).cpu()  # the epoch's one read of the device
        for curve, value in zip(curves, losses.tolist()):
            curve.append(value)
        bar.set_postfix(median_loss=f"{float(losses.median()):.4g}")
    bar.close()
    return [Outcome(stack.fitted(i), curves[i][-1], curves[i]) for i in range(len(tables))]
