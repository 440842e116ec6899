"""Hyperdiffusion (Zhou et al. §3.3, Hu 2026 §3.5): a diffusion model over aligned NBRDF weight vectors.

A transformer denoiser reads a noisy weight vector cut into tokens (one per layer, or
contiguous chunks), with sinusoidal positional and timestep embeddings and an optional
condition, and predicts the noise ε. Training is DDPM (T = 100, β linear 1e-4 → 2e-2, loss
‖ε − ε̂‖²); sampling is DDIM with `ddim_steps` steps and `eta`. Conditioning (material
category now; any embedding vector later, see `ConditionEncoder`) uses classifier-free
guidance: training drops the condition with probability `p_uncond`, sampling combines
ε = ε_u + w (ε_c − ε_u) with w = `guidance`.

The default size is for a 2-core CPU, not Zhou et al.'s 86 M-parameter transformer: 15 chunk
tokens of 45 weights plus the context token, d_model 128, 4 pre-norm blocks of 4 heads
(1.0 M parameters), AdamW with batch 128, lr 5e-4 → 5e-6 (warm-up, cosine), EMA 0.999, 300
epochs (5 700 steps on a 2 400-material NeuMERL), 50 DDIM steps. Chunks rather than layers:
"layer" tokens make 3 tokens of 147, 462 and 66 values, too few for attention to matter.
`conf/generator/hyperdiffusion_paper.yaml` is the published size (12 blocks of width 768, 12
heads, the vector as one token: 87.3 M parameters; batch 512, 700 epochs). It is meant for a
GPU: with `max_cpu_hours` set (that config sets 2) a CPU fit whose estimated time
(`training_estimate`: parameters × tokens × steps at CPU_FLOPS) exceeds it is refused before
any work, naming the setting.

Devices: the generator runs on "cpu" and "cuda" (`to`). It is initialised on the CPU from the
seed's generator and moved; the standardisation and the prior are fitted on the CPU. Every
random number (permutations, timesteps, noise, condition dropout; the sampling draws) comes
from a CPU generator in the same order on every device, an epoch's training draws moved
to the device at once, and the epoch's loss is read once per epoch: on the CPU that is the
arithmetic of drawing at each step, bit for bit; on a GPU the same seed draws the same
numbers and the sums round differently.

Two departures from the papers' code, both deliberate:

- DDIM: the papers' code adds the posterior mean where the noise estimate belongs;
  `ddim_step` uses x_s = √ᾱ_s x̂₀ + √(1 − ᾱ_s − σ²) ε̂ + σ z (Song et al. 2021, eq. 12).
- The prior: with T = 100 and this β range ᾱ_T ≈ 0.364, so x_T still carries 36 % of the
  data's variance and q(x_T) is far from N(0, I) along the weights' principal directions
  (and, conditioned, far from the other classes' region). `prior="matched"` (default)
  starts sampling from a Gaussian fit of q(x_T | c): N(√ᾱ_T μ_c, ᾱ_T Σ_w + (1 − ᾱ_T) I),
  μ_c the class mean and Σ_w the pooled within-class covariance of the standardised training
  vectors (one class when unconditional; a condition-free draw picks c by its training
  share); `prior="standard"` starts from N(0, I) as the papers do.

State is tensors (the denoiser's EMA weights, the standardisation, the prior) and
JSON metadata (the NBRDF layout, the class names, the training curve): no pickle.
"""

from __future__ import annotations

import math
import numbers
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn
from tqdm.auto import tqdm

from brdfbench.errors import ConfigError, DataError, ModelFileError
from brdfbench.protocols.generator import TRAINING_CURVE_KEY, Generator, SampleSet, TrainingData, WeightSet
from brdfbench.protocols.generator_state import read_layout, weight_layout
from brdfbench.nbrdf import network as net

from .samples import WeightSamples

NAME = "hyperdiffusion"
#: Diffusion steps and the linear β schedule of Zhou et al..
T = 100
BETA_START, BETA_END = 1e-4, 2e-2
TOKENISATIONS = ("chunk", "layer")
CONDITIONS = (None, "category")
PRIORS = ("matched", "standard")
#: Samples denoised together; larger requests run in batches of this size (bounds activations).
SAMPLE_BATCH = 1024
#: Standard deviations below this share of the median one are floored there (constant weights).
STD_FLOOR = 1e-3
#: Eigenvalues of the within-class covariance kept in the matched prior (relative to the largest).
PRIOR_EIG_FLOOR = 1e-6
#: The CPU training rate `max_cpu_hours` estimates with: 50 GFLOP/s, about what PyTorch
#: sustains on fp32 matrix products over a few CPU cores (a 2-core machine does less).
CPU_FLOPS = 5e10


# --------------------------------------------------------------------------- the schedule


def beta_schedule(steps: int = T, start: float = BETA_START, end: float = BETA_END) -> Tensor:
    """β_1 … β_T, linear (float64)."""
    return torch.linspace(start, end, steps, dtype=torch.float64)


def alpha_bars(betas: Tensor) -> Tensor:
    """ᾱ_t = ∏_{s ≤ t} (1 − β_s), index t − 1 for t = 1 … T (float64)."""
    return torch.cumprod(1.0 - betas, dim=0)


def ddim_timesteps(steps: int, total: int = T) -> list[int]:
    """`steps` distinct timestep indices (0-based, into ᾱ) from total − 1 down to 0."""
    if not 1 <= steps <= total:
        raise ConfigError(f"{NAME}: ddim_steps={steps} must lie in 1..{total}")
    return sorted({int(round(v)) for v in np.linspace(total - 1, 0, steps)}, reverse=True)


def ddim_step(x: Tensor, eps: Tensor, ab_t: float, ab_prev: float, eta: float = 0.0,
              noise: Tensor | None = None) -> Tensor:
    """One DDIM update x_t → x_s (ᾱ_t, ᾱ_s = `ab_t`, `ab_prev`; ᾱ_s = 1 returns x̂₀).

    x̂₀ = (x_t − √(1 − ᾱ_t) ε̂) / √ᾱ_t and x_s = √ᾱ_s x̂₀ + √(1 − ᾱ_s − σ²) ε̂ + σ z, with
    σ = η √((1 − ᾱ_s)/(1 − ᾱ_t)) √(1 − ᾱ_t/ᾱ_s): the noise estimate, not a posterior mean,
    points back along the trajectory. η = 0 is deterministic; η = 1 is DDPM's variance.
    """
    x0 = (x - math.sqrt(1.0 - ab_t) * eps) / math.sqrt(ab_t)
    sigma = eta * math.sqrt((1.0 - ab_prev) / (1.0 - ab_t) * (1.0 - ab_t / ab_prev))
    out = math.sqrt(ab_prev) * x0 + math.sqrt(max(1.0 - ab_prev - sigma**2, 0.0)) * eps
    if sigma > 0:
        if noise is None:
            raise ValueError("ddim_step: eta > 0 needs a noise tensor")
        out = out + sigma * noise
    return out


def guided(eps_uncond: Tensor, eps_cond: Tensor, guidance: float) -> Tensor:
    """Classifier-free guidance: ε = ε_u + w (ε_c − ε_u) (w = 1: the conditional model alone;
    Zhou et al.'s (1 + ω) ε_c − ω ε_u is w = 1 + ω)."""
    return eps_uncond + guidance * (eps_cond - eps_uncond)


def ddim_sample(predict: Callable[[Tensor, int], Tensor], x_T: Tensor, ab: Tensor, steps: int, eta: float = 0.0,
                generator: torch.Generator | None = None) -> Tensor:
    """x₀ from x_T by DDIM: `predict(x, t)` is the noise estimate at timestep index t."""
    ts = ddim_timesteps(steps, len(ab))
    x = x_T
    for i, t in enumerate(ts):
        ab_prev = float(ab[ts[i + 1]]) if i + 1 < len(ts) else 1.0
        noise = None
        if eta > 0 and ab_prev < 1.0:  # drawn on the generator's (CPU) stream, then moved: seeded alike anywhere
            noise = torch.randn(x.shape, generator=generator, dtype=x.dtype).to(x.device)
        x = ddim_step(x, predict(x, t), float(ab[t]), ab_prev, eta, noise)
    return x


# --------------------------------------------------------------------------- tokens


def segments(hidden: Sequence[int], tokens: str, chunk_size: int) -> list[tuple[int, int]]:
    """(start, length) of every token in the flattened vector: a layer's (weight, bias) is
    contiguous in `layouts.flatten`, so "layer" tokens are those runs; "chunk" tokens are
    `chunk_size` values each (the last one shorter)."""
    width = net.n_weights(hidden)
    if tokens == "chunk":
        return [(s, min(chunk_size, width - s)) for s in range(0, width, chunk_size)]
    sizes = net.layer_sizes(hidden)
    out, at = [], 0
    for n_in, n_out in zip(sizes[:-1], sizes[1:]):
        out.append((at, n_in * n_out + n_out))
        at += n_in * n_out + n_out
    return out


def sinusoid(positions: Tensor, dim: int) -> Tensor:
    """Transformer sinusoidal embedding (len, dim) of integer positions or timesteps."""
    half = dim // 2
    freqs = torch.exp(-math.log(10_000.0) * torch.arange(half, dtype=torch.float32, device=positions.device)
                      / max(half, 1))
    angles = positions.to(torch.float32)[:, None] * freqs[None]
    out = torch.cat([torch.sin(angles), torch.cos(angles)], dim=1)
    return F.pad(out, (0, dim - 2 * half))


# --------------------------------------------------------------------------- the denoiser


class Block(nn.Module):
    """Pre-norm transformer block: self-attention, then a GELU MLP, each residual."""

    def __init__(self, d: int, heads: int):
        super().__init__()
        self.heads = heads
        self.norm1, self.norm2 = nn.LayerNorm(d), nn.LayerNorm(d)
        self.qkv, self.proj = nn.Linear(d, 3 * d), nn.Linear(d, d)
        self.fc1, self.fc2 = nn.Linear(d, 4 * d), nn.Linear(4 * d, d)

    def forward(self, h: Tensor) -> Tensor:
        b, n, d = h.shape
        q, k, v = self.qkv(self.norm1(h)).view(b, n, 3, self.heads, d // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v).transpose(1, 2).reshape(b, n, d)
        h = h + self.proj(a)
        return h + self.fc2(F.gelu(self.fc1(self.norm2(h))))


class ConditionEncoder(nn.Module):
    """A condition → a (B, d) vector; index 0 of the class table is the learned "no condition".

    Class labels go through a learned table now; an embedding from a text or image encoder
    would plug in as another encoder with the same `forward(index or vectors, drop)` contract
    (a linear projection of the vector, the same learned null row for dropped conditions).
    """

    def __init__(self, n_classes: int, d: int):
        super().__init__()
        self.table = nn.Embedding(n_classes + 1, d)

    def forward(self, labels: Tensor, drop: Tensor) -> Tensor:
        """`labels` (B,) class indices 0…C−1; `drop` (B,) bool: use the null row instead."""
        return self.table(torch.where(drop, 0, labels + 1))


class Denoiser(nn.Module):
    """ε̂(x_t, t, c): per-token linear embeddings of the weight vector's segments, a context
    token (timestep + condition) in front, a transformer, per-token linear read-outs."""

    def __init__(self, segs: Sequence[tuple[int, int]], width: int, d: int, layers: int, heads: int, n_classes: int):
        super().__init__()
        self.n_tok, self.span, self.d = len(segs), max(n for _, n in segs), d
        self.width = width
        self.embed_w = nn.Parameter(torch.empty(self.n_tok, self.span, d))
        self.embed_b = nn.Parameter(torch.empty(self.n_tok, d))
        self.time = nn.Sequential(nn.Linear(d, d), nn.SiLU(), nn.Linear(d, d))
        self.cond = ConditionEncoder(n_classes, d) if n_classes else None
        self.blocks = nn.ModuleList(Block(d, heads) for _ in range(layers))
        self.norm = nn.LayerNorm(d)
        self.out_w = nn.Parameter(torch.empty(self.n_tok, d, self.span))
        self.out_b = nn.Parameter(torch.empty(self.n_tok, self.span))
        self._segs = tuple(segs)

    def index_buffers(self, device: torch.device | str = "cpu") -> None:
        """Gather / scatter indices and the positional table (derived, never saved), computed
        on the CPU and kept on `device` (where the parameters are)."""
        gather = torch.full((self.n_tok, self.span), self.width, dtype=torch.long)
        for i, (s, n) in enumerate(self._segs):
            gather[i, :n] = torch.arange(s, s + n)
        self.gather = gather.to(device)
        # the read-out positions that hold a weight, as indices: a boolean mask would make each
        # forward pass count its True entries on the host (a device sync per step)
        self.valid = torch.nonzero((gather < self.width).reshape(-1)).squeeze(1).to(device)
        self.positions = sinusoid(torch.arange(self.n_tok + 1), self.d).to(device)

    def place(self, device: torch.device) -> "Denoiser":
        """Parameters and the derived index tables on `device`; returns self."""
        self.to(device)
        self.index_buffers(device)
        return self

    def forward(self, x: Tensor, t: Tensor, cond: Tensor | None = None) -> Tensor:
        """x (B, W) noisy vectors, t (B,) timestep indices, cond (B, d) condition vectors."""
        b = x.shape[0]
        padded = F.pad(x, (0, 1))[:, self.gather]  # (B, n_tok, span), zeros past a segment
        tok = torch.einsum("bns,nsd->bnd", padded, self.embed_w) + self.embed_b
        ctx = self.time(sinusoid(t, self.d))
        if cond is not None:
            ctx = ctx + cond
        h = torch.cat([ctx[:, None], tok + ctx[:, None]], dim=1) + self.positions
        for block in self.blocks:
            h = block(h)
        y = torch.einsum("bnd,nds->bns", self.norm(h[:, 1:]), self.out_w) + self.out_b
        return y.reshape(b, -1).index_select(1, self.valid)


def init_parameters(model: nn.Module, generator: torch.Generator) -> None:
    """Every parameter drawn from `generator` (the global RNG is never touched): Glorot
    kernels, zero biases, unit norms, N(0, 1) class tables, a zero read-out (ε̂ = 0 at start)."""
    with torch.no_grad():
        for name, p in model.named_parameters():
            leaf = name.rsplit(".", 1)[-1]
            if name.startswith("out_"):
                p.zero_()
            elif name == "embed_w":
                nn.init.normal_(p, 0.0, 1.0 / math.sqrt(p.shape[1]), generator=generator)
            elif name.endswith("table.weight"):  # unit scale, as the timestep embedding: conditions
                nn.init.normal_(p, 0.0, 1.0, generator=generator)  # that start near 0 are barely learned
            elif ".norm" in name or name.startswith("norm"):
                (p.fill_(1.0) if leaf == "weight" else p.zero_())
            elif leaf == "weight":
                nn.init.xavier_uniform_(p, generator=generator)
            else:
                p.zero_()


# --------------------------------------------------------------------------- params


def _positive_int(key: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ConfigError(f"{NAME}: {key}={value!r} must be a positive integer")
    return int(value)


def _real(key: str, value, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False) -> float:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
    if ok:
        ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    if not ok:
        brackets = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
        raise ConfigError(f"{NAME}: {key}={value!r} must be a real number in {brackets}")
    return float(value)


def _choice(key: str, value, options: Sequence) -> Any:
    if value not in options:
        raise ConfigError(f"{NAME}: {key}={value!r} must be one of {list(options)}")
    return value


#: The largest classifier-free guidance weight taken: far beyond the 1–10 used in practice,
#: a weight this large only amplifies the denoiser's noise.
MAX_GUIDANCE = 100.0


def checked_params(p: dict[str, Any]) -> dict[str, Any]:
    """The constructor params validated and normalised (JSON-able); ConfigError names the key."""
    out = dict(p)
    out["tokens"] = _choice("tokens", p["tokens"], TOKENISATIONS)
    for key in ("chunk_size", "d_model", "layers", "heads", "epochs", "batch_size", "ddim_steps"):
        out[key] = _positive_int(key, p[key])
    if out["d_model"] % out["heads"] or (out["d_model"] // out["heads"]) % 2:
        raise ConfigError(f"{NAME}: d_model={out['d_model']} must be an even multiple of heads={out['heads']} "
                          "(an even width per head)")
    if out["ddim_steps"] > T:
        raise ConfigError(f"{NAME}: ddim_steps={out['ddim_steps']} must not exceed the {T} diffusion steps")
    out["lr"] = _real("lr", p["lr"], 0.0, math.inf, lo_open=True, hi_open=True)
    out["lr_final"] = _real("lr_final", p["lr_final"], 0.0, out["lr"])
    out["weight_decay"] = _real("weight_decay", p["weight_decay"], 0.0, math.inf, hi_open=True)
    out["ema"] = _real("ema", p["ema"], 0.0, 1.0, hi_open=True)
    out["eta"] = _real("eta", p["eta"], 0.0, 1.0)
    out["guidance"] = _real("guidance", p["guidance"], 0.0, MAX_GUIDANCE)
    out["condition_on"] = _choice("condition_on", p["condition_on"], CONDITIONS)
    if out["condition_on"] is None and out["guidance"] != 1.0:
        raise ConfigError(f"{NAME}: guidance={out['guidance']:g} has no effect without a condition: set "
                          "condition_on='category', or leave guidance at 1")
    out["p_uncond"] = _real("p_uncond", p["p_uncond"], 0.0, 1.0, hi_open=True)
    if out["condition_on"] and out["p_uncond"] == 0.0 and out["guidance"] != 1.0:
        raise ConfigError(f"{NAME}: guidance={out['guidance']:g} needs p_uncond > 0: with p_uncond=0 the "
                          "unconditional branch is never trained")
    out["prior"] = _choice("prior", p["prior"], PRIORS)
    if p["max_cpu_hours"] is not None:
        out["max_cpu_hours"] = _real("max_cpu_hours", p["max_cpu_hours"], 0.0, math.inf, lo_open=True, hi_open=True)
    if p["hidden"] is not None:
        h = p["hidden"]
        if isinstance(h, (str, bytes)) or not isinstance(h, Sequence) or not h:
            raise ConfigError(f"{NAME}: hidden={h!r} must be None or a non-empty list of positive integers")
        out["hidden"] = [_positive_int("hidden", w) for w in h]
    return out


# --------------------------------------------------------------------------- the generator


class HyperDiffusion(Generator):
    """A DDPM over NBRDF weight vectors with a transformer denoiser; see the module docstring."""

    learns_from = "nbrdf"
    tags = frozenset({"conditional"})
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, tokens: str = "chunk", chunk_size: int = 45, d_model: int = 128, layers: int = 4,
                 heads: int = 4, epochs: int = 300, batch_size: int = 128, lr: float = 5e-4, lr_final: float = 5e-6,
                 weight_decay: float = 0.0, ema: float = 0.999, ddim_steps: int = 50, eta: float = 0.0,
                 guidance: float = 1.0, condition_on: str | None = None, p_uncond: float = 0.1,
                 prior: str = "matched", hidden: Sequence[int] | None = None, max_cpu_hours: float | None = None):
        super().__init__(**checked_params(dict(
            tokens=tokens, chunk_size=chunk_size, d_model=d_model, layers=layers, heads=heads, epochs=epochs,
            batch_size=batch_size, lr=lr, lr_final=lr_final, weight_decay=weight_decay, ema=ema,
            ddim_steps=ddim_steps, eta=eta, guidance=guidance, condition_on=condition_on, p_uncond=p_uncond,
            prior=prior, hidden=hidden, max_cpu_hours=max_cpu_hours)))
        self.model: Denoiser | None = None
        self.mean = self.std = None
        self.prior: dict[str, Tensor] | None = None  # matched prior: "means", "weights", "basis"
        self.layout: dict[str, Any] = {}
        self.classes: list[str] = []
        self.curve: dict[str, Any] = {}

    # -- shapes ---------------------------------------------------------------------
    @property
    def hidden(self) -> tuple[int, ...]:
        """The NBRDF hidden widths: from the fitted weight set, else the param, else 6-21-21-3."""
        h = self.layout.get("hidden") or self.params["hidden"] or list(net.PUBLISHED_HIDDEN)
        return tuple(h)

    @property
    def width(self) -> int:
        return net.n_weights(self.hidden)

    def _segments(self) -> list[tuple[int, int]]:
        return segments(self.hidden, self.params["tokens"], self.params["chunk_size"])

    def _build(self, n_classes: int) -> Denoiser:
        """The denoiser with uninitialised storage on the CPU (no RNG used); init or load fills
        it, `Denoiser.place` moves it."""
        model = self._skeleton(n_classes).to_empty(device="cpu")
        model.index_buffers()
        return model

    def _skeleton(self, n_classes: int) -> Denoiser:
        """The denoiser on the meta device: shapes only, no storage."""
        p = self.params
        with torch.device("meta"):
            return Denoiser(self._segments(), self.width, p["d_model"], p["layers"], p["heads"], n_classes)

    def _move(self, device: torch.device) -> None:
        if self.model is not None:
            self.model.place(device)
            self.mean, self.std = self.mean.to(device), self.std.to(device)
            if self.prior is not None:
                self.prior = {k: v.to(device) for k, v in self.prior.items()}

    # -- cost of a training run ---------------------------------------------------------
    def n_parameters(self, n_classes: int = 0) -> int:
        """Parameters of the denoiser these params build (a class table adds n_classes + 1 rows)."""
        return sum(q.numel() for q in self._skeleton(n_classes).parameters())

    def training_estimate(self, n_materials: int) -> dict[str, float]:
        """What training on `n_materials` weight vectors costs, from the parameter count and
        the step count: {"parameters", "steps", "flop", "cpu_hours" (at CPU_FLOPS), "bytes"}.

        FLOP: 3 × the forward pass (forward and backward), the forward pass being
        2 × (the transformer blocks' parameters × tokens + the token embeddings and read-outs
        + the timestep MLP) + the attention products, per training vector and epoch. Bytes:
        weights, gradients, two Adam moments and the EMA copy (5 × 4 B per parameter), plus
        one batch's activations (about 20 values per token, width and block, and the
        attention maps)."""
        p = self.params
        model = self._skeleton(0)
        total = sum(q.numel() for q in model.parameters())
        blocks = sum(q.numel() for q in model.blocks.parameters())
        tokens = model.n_tok + 1
        batch = min(p["batch_size"], n_materials)
        steps = p["epochs"] * math.ceil(n_materials / max(batch, 1))
        attention = 4 * p["layers"] * tokens * tokens * p["d_model"]
        forward = 2 * (blocks * tokens + (total - blocks)) + attention
        flop = 3.0 * forward * p["epochs"] * n_materials
        activations = 4 * batch * p["layers"] * (20 * tokens * p["d_model"] + 2 * p["heads"] * tokens * tokens)
        return {"parameters": float(total), "steps": float(steps), "flop": flop, "cpu_hours": flop / CPU_FLOPS / 3600,
                "bytes": float(5 * 4 * total + activations)}

    def _check_cpu_budget(self, n_materials: int) -> None:
        """Refuse, before any work, a CPU training run estimated to take longer than
        max_cpu_hours (no limit where it is None, the default)."""
        limit = self.params["max_cpu_hours"]
        if limit is None or self.device.type != "cpu":
            return
        est = self.training_estimate(n_materials)
        if est["cpu_hours"] <= limit:
            return
        raise ConfigError(
            f"{NAME}: training this {est['parameters'] / 1e6:.1f} M-parameter denoiser on the CPU would take about "
            f"{_hours(est['cpu_hours'])} ({int(est['steps'])} steps of batch {min(self.params['batch_size'], n_materials)} "
            f"over {n_materials} materials, {est['flop']:.2g} FLOP at an assumed {CPU_FLOPS / 1e9:.0f} GFLOP/s) and "
            f"about {est['bytes'] / 2**30:.1f} GiB of memory, more than max_cpu_hours={limit:g} allows: run it on a "
            f"GPU (device=cuda, or device=auto on a machine with one), or set generator.params.max_cpu_hours=null "
            f"to train on the CPU anyway")

    def _expected_shapes(self, n_classes: int, prior_rank: int) -> dict[str, tuple[int, ...]]:
        shapes = {f"denoiser.{k}": tuple(v.shape) for k, v in self._build(n_classes).state_dict().items()}
        shapes.update({"data_mean": (self.width,), "data_std": (self.width,)})
        if self.params["prior"] == "matched":
            groups = max(1, n_classes)
            shapes.update({"prior_means": (groups, self.width), "prior_weights": (groups,),
                           "prior_basis": (prior_rank, self.width)})
        return shapes

    # -- learning ---------------------------------------------------------------------
    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "HyperDiffusion":
        self._check_cpu_budget(len(data))  # before the weight vectors are read (or fitted)
        ws = data.weights()
        self._check_weight_set(ws)
        self.classes, labels = self._labels(data, ws.names)
        self.layout = weight_layout(ws)
        x = torch.from_numpy(np.ascontiguousarray(ws.vectors, dtype=np.float32))
        # Per-coordinate standardisation: aligned NBRDF weights span scales from ~1e-3 (weights
        # that barely move from the shared initialisation) to ~1 (output biases). Diffusion adds
        # unit-variance noise to every coordinate and the ε-loss weighs them alike, so on raw
        # weights the small-scale coordinates would drown in the noise; standardised, each one is
        # denoised relative to its own spread, and the model's errors scale back with it.
        self.mean = x.mean(dim=0)
        std = x.std(dim=0, unbiased=False)
        self.std = torch.clamp(std, min=STD_FLOOR * float(std.median().clamp(min=1e-12)))
        z = (x - self.mean) / self.std
        self.prior = self._fit_prior(z, labels) if self.params["prior"] == "matched" else None
        gen = torch.Generator().manual_seed(int(seed))  # on the CPU wherever the model trains
        self.model = self._build(len(self.classes))
        init_parameters(self.model, gen)
        device = self.device
        if device.type != "cpu":  # the data and the model move once; the draws stay on `gen`
            self.model.place(device)
            self.mean, self.std = self.mean.to(device), self.std.to(device)
            if self.prior is not None:
                self.prior = {k: v.to(device) for k, v in self.prior.items()}
            z, labels = z.to(device), None if labels is None else labels.to(device)
        self._train(z, labels, gen, progress, seed)
        return self

    def _check_weight_set(self, ws: WeightSet) -> None:
        if len(ws.names) < 2:
            raise ConfigError(f"{NAME}: needs at least 2 training materials, got {len(ws.names)}")
        wanted = self.params["hidden"]
        if wanted is not None and tuple(wanted) != tuple(ws.hidden):
            raise ConfigError(
                f"{NAME}: built for 6-{'-'.join(map(str, wanted))}-3 networks ({net.n_weights(wanted)} weights), "
                f"the training weight set holds 6-{'-'.join(map(str, ws.hidden))}-3 networks "
                f"({ws.vectors.shape[1]} weights); set hidden={list(ws.hidden)} or hidden=None")

    def _labels(self, data: TrainingData, names: Sequence[str]) -> tuple[list[str], Tensor | None]:
        """The class names and each training material's class index (condition_on="category"),
        else no classes and None."""
        if self.params["condition_on"] is None:
            return [], None
        missing = [n for n in names if not data.categories.get(n)]
        if missing:
            raise DataError(f"{NAME}: condition_on='category' but material(s) {missing[:5]} have no category "
                            f"in dataset {data.dataset or '?'!r}")
        classes = sorted({data.categories[n] for n in names})
        index = {c: i for i, c in enumerate(classes)}
        return classes, torch.tensor([index[data.categories[n]] for n in names], dtype=torch.long)

    def _fit_prior(self, z: Tensor, labels: Tensor | None) -> dict[str, Tensor]:
        """Class means μ_c, class shares, and B (k, W) with BᵀB = Σ_w, the pooled within-class
        covariance of the standardised vectors (eigenvalues below PRIOR_EIG_FLOOR of the
        largest dropped), for x_T ~ N(√ᾱ_T μ_c, ᾱ_T Σ_w + (1 − ᾱ_T) I)."""
        groups = max(1, len(self.classes))
        g = torch.zeros(z.shape[0], dtype=torch.long) if labels is None else labels
        counts = torch.bincount(g, minlength=groups).to(torch.float64)
        z64 = z.to(torch.float64)
        means = torch.zeros(groups, z.shape[1], dtype=torch.float64).index_add_(0, g, z64) / counts.clamp(min=1)[:, None]
        _, sv, vh = torch.linalg.svd(z64 - means[g], full_matrices=False)
        lam = sv**2 / z.shape[0]
        keep = lam > PRIOR_EIG_FLOOR * float(lam.max().clamp(min=1e-30))
        return {"means": means.to(torch.float32), "weights": (counts / counts.sum()).to(torch.float32),
                "basis": (lam[keep].sqrt()[:, None] * vh[keep]).to(torch.float32).contiguous()}

    def _train(self, z: Tensor, labels: Tensor | None, gen: torch.Generator, progress, seed: int) -> None:
        """AdamW on the ε-loss, on the device z lives on. Every random number is drawn from
        `gen` (a CPU generator) in the order of the steps, an epoch's worth at a time, and
        moved there once per epoch; the loss is summed there and read once per epoch, so the
        host never waits for the device inside an epoch. On the CPU this is the arithmetic
        of a loop that draws at each step."""
        p, model = self.params, self.model
        n, device = z.shape[0], z.device
        batch = min(p["batch_size"], n)
        steps_per_epoch = math.ceil(n / batch)
        total = p["epochs"] * steps_per_epoch
        ab = alpha_bars(beta_schedule()).to(torch.float32).to(device)
        opt = torch.optim.AdamW(model.parameters(), lr=p["lr"], weight_decay=p["weight_decay"])
        ema = [q.detach().clone() for q in model.parameters()] if p["ema"] > 0 else None
        losses, walls, t0, step = [], [], time.perf_counter(), 0
        bar = tqdm(range(p["epochs"]), desc=progress if isinstance(progress, str) else NAME, unit="epoch",
                   disable=not progress, leave=False, dynamic_ncols=True)
        model.train()
        for _ in bar:
            perm, t, eps, drop = self._epoch_draws(n, batch, z.shape[1], labels is not None, gen, device)
            total_loss = torch.zeros((), dtype=torch.float64, device=device)
            for start in range(0, n, batch):
                rows = slice(start, start + batch)
                idx = perm[rows]
                loss = self._loss(z[idx], None if labels is None else labels[idx], ab, t[rows], eps[rows],
                                  None if drop is None else drop[rows])
                opt.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(model.parameters(), 1.0)
                for group in opt.param_groups:
                    group["lr"] = _learning_rate(p["lr"], p["lr_final"], step, total)
                opt.step()
                if ema is not None:
                    _ema_update(ema, model.parameters(), min(p["ema"], (1 + step) / (10 + step)))
                step += 1
                total_loss += loss.detach().double() * len(idx)  # fp64, as a host float sum would be
            losses.append(float(total_loss) / n)  # the epoch's one read of the device
            walls.append(time.perf_counter() - t0)
            bar.set_postfix(loss=f"{losses[-1]:.4f}")
        if ema is not None:
            with torch.no_grad():
                for q, e in zip(model.parameters(), ema):
                    q.copy_(e)
        model.eval()
        self.curve = {"loss": [round(v, 6) for v in losses], "wall_s": [round(v, 3) for v in walls],
                      "steps": step, "batch_size": batch, "materials": n, "seed": int(seed)}

    def _epoch_draws(self, n: int, batch: int, width: int, conditional: bool, gen: torch.Generator,
                     device: torch.device) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """An epoch's random numbers, drawn from `gen` in the order a step-by-step loop draws
        them (the permutation; then per step t, ε and, conditioned, the dropout draw), and
        moved to `device` once: (perm (n,), t (n,), ε (n, W), drop (n,) or None)."""
        perm = torch.randperm(n, generator=gen)
        ts, epss, drops = [], [], []
        for start in range(0, n, batch):
            b = min(batch, n - start)
            ts.append(torch.randint(0, T, (b,), generator=gen))
            epss.append(torch.randn((b, width), generator=gen))
            if conditional:
                drops.append(torch.rand(b, generator=gen) < self.params["p_uncond"])
        drop = torch.cat(drops).to(device) if conditional else None
        return perm.to(device), torch.cat(ts).to(device), torch.cat(epss).to(device), drop

    def _loss(self, x0: Tensor, labels: Tensor | None, ab: Tensor, t: Tensor, eps: Tensor,
              drop: Tensor | None) -> Tensor:
        """‖ε − ε̂(√ᾱ_t x₀ + √(1 − ᾱ_t) ε, t, c)‖² (mean): t uniform, ε ~ N(0, I), c dropped where
        `drop` (drawn with probability p_uncond)."""
        a = ab[t][:, None]
        xt = a.sqrt() * x0 + (1 - a).sqrt() * eps
        cond = None
        if labels is not None:
            cond = self.model.cond(labels, drop)
        return F.mse_loss(self.model(xt, t, cond), eps)

    # -- sampling -------------------------------------------------------------------------
    def _condition_labels(self, n: int, condition: Any) -> Tensor | None:
        """(n,) class indices, or None for unconditional sampling; clear errors otherwise."""
        if not self.classes:
            if condition is not None:
                raise ConfigError(f"{NAME} was trained unconditionally (condition_on=None): condition must be None, "
                                  f"got {condition!r}; fit with condition_on='category' to sample a category")
            return None
        if condition is None:
            if self.params["p_uncond"] == 0.0:
                raise ConfigError(f"{NAME}: trained with p_uncond=0, it has no unconditional branch: "
                                  f"pass a condition, one of {self.classes}")
            return None
        if isinstance(condition, str):
            wanted = [condition] * n
        elif isinstance(condition, Sequence):
            wanted = list(condition)
        else:
            raise ConfigError(f"{NAME}: condition={condition!r} must be a category name or a list of n of them")
        if len(wanted) != n:
            raise ConfigError(f"{NAME}: {len(wanted)} conditions given for n={n} samples")
        unknown = sorted({str(c) for c in wanted if c not in self.classes})
        if unknown:
            raise ConfigError(f"{NAME}: unknown condition(s) {unknown}; the model knows {self.classes}")
        index = {c: i for i, c in enumerate(self.classes)}
        return torch.tensor([index[c] for c in wanted], dtype=torch.long)

    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        """Drawn from a CPU generator seeded by `seed` (moved to the model's device after each
        draw): the same seed draws the same numbers on every device."""
        labels = self._condition_labels(n, condition)
        if labels is not None:
            labels = labels.to(self.device)
        gen = torch.Generator().manual_seed(seed)
        x_T = self._prior_draw(n, labels, gen)
        out = torch.cat([self._denoise(x_T[s:s + SAMPLE_BATCH], None if labels is None else labels[s:s + SAMPLE_BATCH],
                                       gen) for s in range(0, n, SAMPLE_BATCH)])
        weights = out * self.std + self.mean
        return WeightSamples(weights, self.hidden, self.layout.get("features", "rusinkiewicz"),
                             self.layout.get("raw_units", False))

    def _prior_draw(self, n: int, labels: Tensor | None, gen: torch.Generator) -> Tensor:
        """x_T in the standardised space: N(0, I), or the matched prior of each sample's class
        (without a condition, the class drawn by its training share)."""
        device = self.device
        noise = torch.randn((n, self.width), generator=gen).to(device)
        if self.prior is None:
            return noise
        if labels is None:
            labels = torch.multinomial(self.prior["weights"].cpu(), n, replacement=True, generator=gen).to(device)
        ab_T = float(alpha_bars(beta_schedule())[-1])
        z = torch.randn((n, self.prior["basis"].shape[0]), generator=gen).to(device)
        return math.sqrt(ab_T) * (self.prior["means"][labels] + z @ self.prior["basis"]) + math.sqrt(1.0 - ab_T) * noise

    @torch.no_grad()
    def _denoise(self, x_T: Tensor, labels: Tensor | None, gen: torch.Generator) -> Tensor:
        p, model = self.params, self.model
        b = x_T.shape[0]
        w = p["guidance"]
        cond = uncond = None
        device = x_T.device
        if self.classes:
            uncond = model.cond(torch.zeros(b, dtype=torch.long, device=device),
                                torch.ones(b, dtype=torch.bool, device=device))
            if labels is not None:
                cond = model.cond(labels, torch.zeros(b, dtype=torch.bool, device=device))

        def predict(x: Tensor, t: int) -> Tensor:
            tt = torch.full((x.shape[0],), t, dtype=torch.long, device=device)
            if cond is None:
                return model(x, tt, uncond)
            if w == 1.0:
                return model(x, tt, cond)
            both = model(torch.cat([x, x]), torch.cat([tt, tt]), torch.cat([uncond, cond]))
            return guided(both[:b], both[b:], w)

        return ddim_sample(predict, x_T, alpha_bars(beta_schedule()), p["ddim_steps"], p["eta"], gen)

    def sample_nbytes(self, n: int) -> int:
        """Vectors held for all n (x_T, the denoised batches, their concatenation, the
        de-standardised output, and a spare: 5 (n, W) float32 arrays) plus one batch's
        activations (twice the batch under guidance). Measured peaks stay within it."""
        p = self.params
        b = min(n, SAMPLE_BATCH) * (2 if p["condition_on"] and p["guidance"] != 1.0 else 1)
        segs = self._segments()
        tokens, span, d = len(segs) + 1, max(s for _, s in segs), p["d_model"]
        per_row = tokens * (12 * d + 2 * p["heads"] * tokens) + 3 * len(segs) * span
        return int(4 * (5 * n * self.width + 2 * b * per_row)) + (1 << 20)

    # -- persistence ------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Tensor]:
        if self.model is None:
            return {}
        out = {f"denoiser.{k}": v.detach() for k, v in self.model.state_dict().items()}
        out.update({"data_mean": self.mean, "data_std": self.std})
        if self.prior is not None:
            out.update({f"prior_{k}": v for k, v in self.prior.items()})
        return out

    def metadata(self) -> dict[str, Any]:
        if self.model is None:
            return {}
        rank = 0 if self.prior is None else int(self.prior["basis"].shape[0])
        return {**self.layout, "width": self.width, "classes": list(self.classes), "prior_rank": rank,
                "timesteps": T, "beta": [BETA_START, BETA_END], "training": dict(self.curve),
                TRAINING_CURVE_KEY: {"loss": list(self.curve.get("loss", []))}}

    @classmethod
    def from_state(cls, params: dict[str, Any], tensors: dict[str, Tensor], metadata: dict[str, Any]) -> "HyperDiffusion":
        gen = cls(**params)
        if not tensors and not metadata:
            return gen  # what an untrained generator saves: it loads untrained, as the others do
        gen._read_metadata(metadata)
        expected = gen._expected_shapes(len(gen.classes), int(metadata.get("prior_rank", 0)))
        for key, shape in expected.items():
            if key not in tensors:
                raise ModelFileError(f"{NAME}: lacks tensor {key!r}")
            t = tensors[key]
            if tuple(t.shape) != shape:
                raise ModelFileError(f"{NAME}: tensor {key!r} has shape {tuple(t.shape)}, expected {shape} "
                                     f"for params {params} and the file's metadata")
            if not t.dtype.is_floating_point or not torch.isfinite(t).all():
                raise ModelFileError(f"{NAME}: tensor {key!r} must be finite floating point")
        extra = sorted(set(tensors) - set(expected))
        if extra:
            raise ModelFileError(f"{NAME}: unexpected tensor(s) {extra} for params {params}")
        if float(tensors["data_std"].min()) <= 0:
            raise ModelFileError(f"{NAME}: tensor 'data_std' must be positive")
        gen.model = gen._build(len(gen.classes))
        gen.model.load_state_dict({k[len("denoiser."):]: tensors[k].to(torch.float32) for k in expected
                                   if k.startswith("denoiser.")})
        gen.model.eval()
        gen.mean = tensors["data_mean"].to(torch.float32).clone()
        gen.std = tensors["data_std"].to(torch.float32).clone()
        if "prior_basis" in expected:
            gen.prior = {k: tensors[f"prior_{k}"].to(torch.float32).clone() for k in ("means", "weights", "basis")}
            if float(gen.prior["weights"].min()) < 0 or float(gen.prior["weights"].sum()) <= 0:
                raise ModelFileError(f"{NAME}: tensor 'prior_weights' must be non-negative with a positive sum")
        return gen

    def _read_metadata(self, metadata: dict[str, Any]) -> None:
        """The NBRDF layout (saved beside the other keys) and class names from a saved file's
        metadata, checked."""
        layout = read_layout(NAME, metadata, "metadata")
        if self.params["hidden"] is not None and layout["hidden"] != list(self.params["hidden"]):
            raise ModelFileError(f"{NAME}: metadata hidden={layout['hidden']} contradicts param hidden={self.params['hidden']}")
        classes = metadata.get("classes", [])
        if not isinstance(classes, list) or not all(isinstance(c, str) for c in classes):
            raise ModelFileError(f"{NAME}: metadata 'classes' must be a list of category names")
        if bool(classes) != (self.params["condition_on"] is not None):
            raise ModelFileError(f"{NAME}: metadata names {len(classes)} classes but condition_on="
                                 f"{self.params['condition_on']!r}")
        rank = metadata.get("prior_rank", 0)
        if isinstance(rank, bool) or not isinstance(rank, int) or rank < 0:
            raise ModelFileError(f"{NAME}: metadata 'prior_rank'={rank!r} must be a non-negative integer")
        self.layout = layout
        self.classes = list(classes)
        training = metadata.get("training", {})
        self.curve = dict(training) if isinstance(training, dict) else {}


def _hours(h: float) -> str:
    return f"{h:.1f} h" if h < 10 else f"{h:.0f} h" if h < 48 else f"{h / 24:.0f} days"


def _learning_rate(lr: float, lr_final: float, step: int, total: int) -> float:
    """Linear warm-up over the first 2 % of steps, then cosine decay from lr to lr_final."""
    warm = max(1, total // 50)
    if step < warm:
        return lr * (step + 1) / warm
    frac = (step - warm) / max(1, total - warm)
    return lr_final + 0.5 * (lr - lr_final) * (1 + math.cos(math.pi * min(frac, 1.0)))


def _ema_update(ema: list[Tensor], params, decay: float) -> None:
    with torch.no_grad():
        for e, q in zip(ema, params):
            e.lerp_(q.detach(), 1.0 - decay)
