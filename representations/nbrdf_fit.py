"""Fitting many neural BRDFs at once: stacked weights, one batched matmul per layer.

Every material of a batch sees the same training samples in the same order, drawn
uniformly in (θh, θd, φd) — the BRDF-aware sampling of Sztrajman et al. (2021), which puts
many samples near the specular peak (small θh) — with pairs below the horizon dropped
for all, and each material's invalid (negative) cells dropped for it alone. The weights
of M materials are stacked (M, in, out); a minibatch of B samples runs through all of
them as batched matrix products, and a hand-written Adam updates the stack. On the CPU the
forward and backward passes are hand-written too (`_CpuEpochs`: autograd's bookkeeping and
temporaries cost more than the arithmetic of these small networks); `engine="autograd"` is
the reference they are tested against. Each material's loss is normalised by its own
valid-sample count, so the gradients of different materials never mix: a material's fit
does not depend on its batch-mates (`fit_batched` of one material is the one-at-a-time
loop, same arithmetic).

Loss: mean |log(1 + f cos θi) − log(1 + f̂ cos θi)| over valid samples and channels (L1, the
published one); "l2" descends the mean squared difference instead, and "l1_or_l2" fits
with each from the same start on the same samples and keeps, per material, the fit whose
final L1 loss is lower. "l1_then_l2" fits with L1 and refits with L2 (same start, same
samples) only the materials whose L1 fit collapsed — its final loss above `COLLAPSE_RATIO`
times the best constant BRDF's (`collapse_ratio`) — then keeps the lower
L1 loss as "l1_or_l2" does, at the cost of one fit where nothing collapsed. The epoch
losses that the early stop and `Outcome.loss` read are always L1, so fits by either loss
compare. Why the naive MLP needs it: see its class.
With output="log" (the default) the prediction is computed from the last layer's z as
log(1 + expm1(z) c) = logaddexp(z + log c, log(1 − c)): exact, finite for any z (no fp32
overflow), and with a gradient everywhere — unlike the reference's relu(expm1(z)),
whose clamp stops every gradient once a dark material's outputs all go negative. The
clamp at 0 is applied at evaluation only. output="clamped" reproduces the reference.

Early stop: in the second half of the schedule (where the learning rate anneals and the
loss falls steadily; earlier, a plateau at a high rate is noise), a material leaves the
batch — its rows are compacted out, which makes the remaining epochs cheaper — once its
epoch loss improved by less than `min_improvement` (relative) over `patience` epochs.

On a GPU (`device`), the samples, targets and stacked weights move there once per call;
each step gathers its minibatch there by index, the Adam step reads its schedule (learning
rate and bias corrections, precomputed for the whole run) from device memory, and the
epoch's losses accumulate there, so the host never waits for the device inside an epoch.
The step is captured once as a CUDA graph per batch shape and replayed (`cuda_graphs`;
recaptured when early stops shrink the stack): a step of ~90 small kernels then costs one
launch instead of ~90 from Python. The arithmetic is the CPU path's, reassociated in the
Adam update only; a GPU fit is not the CPU fit bit for bit (see tests/gpu).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
import torch
from tqdm.auto import tqdm

from brdfbench import coords, merl
from brdfbench.errors import ConfigError
from brdfbench.nbrdf import network as net

SCHEDULES = ("onecycle", "constant")
OUTPUTS = ("log", "clamped")
SAMPLINGS = ("uniform", "peak")
LOSSES = ("l1", "l2", "l1_or_l2", "l1_then_l2")
ENGINES = ("manual", "autograd")  # the CPU steps: hand-written, or torch autograd (the reference)
ADAM_BETAS = (0.9, 0.999)
ADAM_EPS = 1e-7  # Keras' default, as the reference recipe used
ONECYCLE_WARMUP = 0.1  # fraction of the steps spent warming up
ONECYCLE_START_DIV = 25.0  # the warm-up starts at lr / 25
ONECYCLE_END_DIV = 1e4  # and the cosine anneal ends at lr / 1e4
COS_MIN = 1e-7  # cos θi is clamped into [COS_MIN, 1 − 2⁻²⁴] inside the log-space loss
#: "l1_then_l2" refits with L2 where the L1 fit's final loss is above this fraction of the best
#: constant BRDF's loss: a collapsed fit is no better than the diffuse-only prediction (its ratio
#: near 1), a healthy one about four times better or more (see NaiveMLP for the figures).
COLLAPSE_RATIO = 0.25
COLLAPSE_SAMPLES = 20_000  # training pairs (the first ones drawn) that the best constant is fitted to

log = logging.getLogger(__name__)
#: Tests set this to run the GPU path's arithmetic (scheduled Adam, index gathers, device
#: accumulators; no graphs) on the CPU, where CI can check it against the CPU path.
_DEVICE_PATH_ON_CPU = False


@dataclass(frozen=True)
class Recipe:
    """How to train: sample count, epochs, minibatch, learning rate and its schedule."""

    epochs: int = 15
    batch_size: int = 2048
    lr: float = 2e-2
    schedule: str = "onecycle"
    n_samples: int = 800_000  # drawn before dropping pairs below the horizon (about 62 % stay)
    output: str = "log"
    patience: int | None = 2
    min_improvement: float = 5e-3
    sampling: str = "uniform"  # θh of the training pairs: "uniform", or "peak" (θh = u²·π/2, MERL's spacing)
    # "l1", "l2" (squared log error), "l1_or_l2" (both fits, the lower L1 loss kept), or
    # "l1_then_l2" (the L2 fit only where the L1 fit collapsed, then the lower L1 loss kept)
    loss: str = "l1"

    def __post_init__(self):
        def bad(key, why):
            raise ConfigError(f"nbrdf: {key}={getattr(self, key)!r}: {why}")

        for key in ("epochs", "batch_size", "n_samples"):
            value = getattr(self, key)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                bad(key, "must be a positive integer")
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            bad("lr", "must be a positive number")
        if self.schedule not in SCHEDULES:
            bad("schedule", f"expected one of {', '.join(SCHEDULES)}")
        if self.output not in OUTPUTS:
            bad("output", f"expected one of {', '.join(OUTPUTS)}")
        if self.patience is not None and (not isinstance(self.patience, int) or self.patience < 1):
            bad("patience", "must be a positive integer, or null for no early stop")
        if self.sampling not in SAMPLINGS:
            bad("sampling", f"expected one of {', '.join(SAMPLINGS)}")
        if self.loss not in LOSSES:
            bad("loss", f"expected one of {', '.join(LOSSES)}")


#: The published recipe of Sztrajman et al. (2021): Adam 5e-4, minibatch 512, 100 epochs,
#: constant rate, output relu(expm1(z)) in training too, no early stop.
REFERENCE_RECIPE = Recipe(epochs=100, batch_size=512, lr=5e-4, schedule="constant", output="clamped", patience=None)


@dataclass(frozen=True)
class Samples:
    """Training inputs shared by every material: encodings, cos θi, and MERL cells."""

    x: torch.Tensor  # (S, 6) float32
    cos_i: torch.Tensor  # (S,) float32
    cells: torch.Tensor  # (S,) flat MERL cell index of each pair (nearest cell, as the reference)


def draw_samples(n: int, features: str, seed: int, sampling: str = "uniform") -> Samples:
    """n pairs uniform in (θd, φd) (and φh, for direction inputs), above-horizon ones kept;
    θh uniform, or for sampling="peak" θh = u²·π/2 with u uniform (the MERL grid's spacing:
    about 8 % of the drawn pairs within 0.01 rad of the specular peak instead of 0.6 %)."""
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, generator=g, dtype=torch.float64)
    theta_h = (u * u if sampling == "peak" else u) * (math.pi / 2)
    theta_d = torch.rand(n, generator=g, dtype=torch.float64) * (math.pi / 2)
    phi_d = torch.rand(n, generator=g, dtype=torch.float64) * (2 * math.pi)
    phi_h = torch.rand(n, generator=g, dtype=torch.float64) * (2 * math.pi)
    if features == "rusinkiewicz":
        phi_h = torch.zeros_like(phi_h)  # the encoding drops φh: keep the pairs in its frame
    wi, wo = coords.from_half_diff(theta_h, phi_h, theta_d, phi_d)
    keep = coords.above_horizon(wi, wo)
    wi, wo = wi[keep], wo[keep]
    theta_h, theta_d, phi_d = theta_h[keep], theta_d[keep], phi_d[keep]
    if features == "rusinkiewicz":
        x = net.rusinkiewicz_from_angles(theta_h, theta_d, phi_d)
    else:
        x = net.encode(wi, wo, features)
    cells = (merl.theta_half_index(theta_h) * merl.RES_THETA_D + merl.theta_diff_index(theta_d)) * merl.RES_PHI_D
    cells = cells + merl.phi_diff_index(phi_d)
    return Samples(x=x.to(torch.float32), cos_i=wi[:, 2].to(torch.float32), cells=cells)


@functools.lru_cache(maxsize=2)
def _drawn(n: int, features: str, seed: int, sampling: str) -> Samples:
    """`draw_samples`, kept for the next call: the runner fits a sweep's batches one after
    another from the same draw (the fitters only read the samples)."""
    return draw_samples(n, features, seed, sampling)


def targets(table: merl.MerlTable, samples: Samples, output_scale: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """log(1 + f cos θi) (S, 3) float32 of one material in the network's units, and its valid mask (S,)."""
    values = torch.from_numpy(table.values.reshape(3, -1))[:, samples.cells].T  # (S, 3) float64, 1/sr
    valid = (values >= 0).all(dim=1)
    f = values.clamp(min=0) / output_scale.to(torch.float64)
    return torch.log1p(f * samples.cos_i.double()[:, None]).to(torch.float32), valid


def predict_log(z: torch.Tensor, log_c: torch.Tensor, log_1mc: torch.Tensor, output: str = "log") -> torch.Tensor:
    """The network's log(1 + f̂ cos θi) from its last-layer value z, given log cos θi and log(1 − cos θi).

    "log": f̂ = expm1(z) unclamped, so log(1 + f̂ c) = logaddexp(z + log c, log(1 − c)), finite for
    every finite z and never without a gradient. "clamped": f̂ = relu(expm1(z)), the reference.
    """
    if output == "log":
        return torch.logaddexp(z + log_c, log_1mc.expand_as(z))
    f = torch.relu(torch.expm1(torch.clamp(z, max=net.MAX_LOG_VALUE)))
    return torch.log1p(f * torch.exp(log_c))


@dataclass
class Outcome:
    """One material's fitted weights, its final training loss (the L1 loss, whatever loss was
    descended), the epochs it ran, the loss it descended, the losses it was fitted with and,
    for "l1_then_l2", the L1 fit's `collapse_ratio`."""

    weights: dict[str, torch.Tensor]
    loss: float
    epochs: int
    descended: str = "l1"
    fitted: tuple[str, ...] = ("l1",)
    collapse: float | None = None


@torch.no_grad()
def constant_loss(tables: Sequence[merl.MerlTable], samples: Samples, output_scale: torch.Tensor | None = None,
                  n: int = COLLAPSE_SAMPLES, iterations: int = 30) -> torch.Tensor:
    """(M,) the L1 training loss of each table's best constant BRDF (one value per channel: the
    diffuse-only prediction), on the first `n` training pairs: a golden-section search over
    log f per channel (each pair's term falls, then rises, in it)."""
    scale = torch.ones(3) if output_scale is None else output_scale.detach().cpu().to(torch.float32)
    head = Samples(x=samples.x[:n], cos_i=samples.cos_i[:n], cells=samples.cells[:n])
    ys, valids = zip(*(targets(t, head, scale) for t in tables))
    y, valid = torch.stack(ys, dim=1), torch.stack(valids, dim=1).to(torch.float32)  # (n, M, 3), (n, M)
    count = valid.sum(dim=0).clamp(min=1)
    c = head.cos_i.clamp(COS_MIN, 1 - 2.0**-24)[:, None, None]

    def loss(log_f):  # (M, 3) -> (M, 3) mean over valid pairs
        return ((torch.log1p(log_f.exp() * c) - y).abs() * valid[:, :, None]).sum(dim=0) / count[:, None]

    ratio = (math.sqrt(5) - 1) / 2
    lo, hi = torch.full((len(tables), 3), -16.0), torch.full((len(tables), 3), 10.0)
    for _ in range(iterations):
        a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
        left = loss(a) < loss(b)
        hi, lo = torch.where(left, b, hi), torch.where(left, lo, a)
    return loss((lo + hi) / 2).mean(dim=1)


def collapse_ratio(tables: Sequence[merl.MerlTable], losses: Sequence[float], samples: Samples,
                   output_scale: torch.Tensor | None = None) -> list[float]:
    """Each fit's final L1 loss over its table's best constant BRDF's (`constant_loss`): near 1
    where the fit collapsed to the diffuse-only solution, far below where it found the lobe."""
    const = constant_loss(tables, samples, output_scale)
    return [float(loss) / max(float(c), 1e-12) for loss, c in zip(losses, const)]


def one_cycle(peak: float, step: int, total: int) -> float:
    """The one-cycle rate at `step` of `total`: a linear warm-up from peak / 25 over the first
    10 %, then a cosine anneal to peak / 1e4 (the triplane fitter uses it too)."""
    warm = max(1, int(ONECYCLE_WARMUP * total))
    if step < warm:
        start = peak / ONECYCLE_START_DIV
        return start + (peak - start) * step / warm
    t = (step - warm) / max(1, total - warm)
    end = peak / ONECYCLE_END_DIV
    return end + (peak - end) * 0.5 * (1 + math.cos(math.pi * t))


def learning_rate(recipe: Recipe, step: int, total: int) -> float:
    return recipe.lr if recipe.schedule == "constant" else one_cycle(recipe.lr, step, total)


@torch.no_grad()
def adam_update(p: torch.Tensor, m: torch.Tensor, v: torch.Tensor, lr: float, step: int,
                betas: tuple[float, float] = ADAM_BETAS, eps: float = ADAM_EPS) -> None:
    """One bias-corrected Adam step of `p` from its gradient, in place (moments m, v; `step`
    counts from 1); clears the gradient. Elementwise, so stacked materials never mix."""
    b1, b2 = betas
    c1, c2 = 1 - b1**step, 1 - b2**step
    g = p.grad
    m.mul_(b1).add_(g, alpha=1 - b1)
    v.mul_(b2).addcmul_(g, g, value=1 - b2)
    denom = (v / c2).sqrt_().add_(eps)
    p.addcdiv_(m, denom, value=-lr / c1)
    p.grad = None


@torch.no_grad()
def adam_update_scheduled(p: torch.Tensor, m: torch.Tensor, v: torch.Tensor, hyper: torch.Tensor,
                          betas: tuple[float, float] = ADAM_BETAS, eps: float = ADAM_EPS) -> None:
    """`adam_update` with the step's scalars in a device tensor `hyper` = (lr / (1 − β₁ᵗ),
    1 / (1 − β₂ᵗ)): no host value enters the kernels, so a step can be captured and replayed."""
    b1, b2 = betas
    g = p.grad
    m.mul_(b1).add_(g, alpha=1 - b1)
    v.mul_(b2).addcmul_(g, g, value=1 - b2)
    denom = (v * hyper[1]).sqrt_().add_(eps)
    p.addcdiv_(m * hyper[0], denom, value=-1.0)
    p.grad = None


def adam_schedule(recipe: "Recipe", total: int, device: torch.device,
                  betas: tuple[float, float] = ADAM_BETAS) -> torch.Tensor:
    """(total, 2) float32 on `device`: each step's `hyper` for `adam_update_scheduled`."""
    b1, b2 = betas
    rows = [(learning_rate(recipe, s, total) / (1 - b1 ** (s + 1)), 1 / (1 - b2 ** (s + 1))) for s in range(total)]
    return torch.tensor(rows, dtype=torch.float32).to(device)


class _Stack:
    """Stacked weights of the active materials with their Adam moments."""

    def __init__(self, inits: Sequence[dict[str, torch.Tensor]], names: list[str], device: torch.device = torch.device("cpu")):
        self.names = names
        self.params = []
        for name in names:
            t = torch.stack([w[name].to(torch.float32) for w in inits]).to(device)
            if name.startswith("b"):
                t = t[:, None, :]  # (M, 1, out): broadcasts over the minibatch
            self.params.append(t.contiguous().requires_grad_())
        self.m = [torch.zeros_like(p) for p in self.params]
        self.v = [torch.zeros_like(p) for p in self.params]
        self.t = 0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """z (M, B, 3) for a shared minibatch x (B, 6)."""
        h = x
        n = len(self.params) // 2
        for i in range(n):
            w, b = self.params[2 * i], self.params[2 * i + 1]
            h = torch.baddbmm(b, h, w) if h.ndim == 3 else torch.matmul(h, w) + b
            if i < n - 1:
                h = torch.relu(h)
        return h

    @torch.no_grad()
    def adam_step(self, lr: float) -> None:
        self.t += 1
        for p, m, v in zip(self.params, self.m, self.v):
            adam_update(p, m, v, lr, self.t)

    @torch.no_grad()
    def adam_step_scheduled(self, hyper: torch.Tensor) -> None:
        for p, m, v in zip(self.params, self.m, self.v):
            adam_update_scheduled(p, m, v, hyper)

    def state(self) -> list[torch.Tensor]:
        return [*self.params, *self.m, *self.v]

    def keep(self, rows: torch.Tensor) -> None:
        rows = rows.to(self.params[0].device)
        with torch.no_grad():
            self.params = [p[rows].contiguous().requires_grad_() for p in self.params]
            self.m = [m[rows].contiguous() for m in self.m]
            self.v = [v[rows].contiguous() for v in self.v]

    def weights(self, row: int) -> dict[str, torch.Tensor]:
        out = {}
        for name, p in zip(self.names, self.params):
            t = p[row].detach().clone()
            out[name] = t[0] if name.startswith("b") else t
        return out


def fit_batched(
    tables: Sequence[merl.MerlTable],
    inits: Sequence[dict[str, torch.Tensor]],
    *,
    features: str = "rusinkiewicz",
    recipe: Recipe = Recipe(),
    output_scale: torch.Tensor | None = None,
    sample_seed: int = 0,
    samples: Samples | None = None,
    progress: bool | str = False,
    on_epoch: Callable[[int, torch.Tensor], None] | None = None,
    device: torch.device | str = "cpu",
    cuda_graphs: bool = True,
    engine: str = "manual",
) -> list[Outcome]:
    """Fit one network per table, all in one pass; `inits` gives each one's initial weights.

    `samples` may be passed in to share one draw across several calls (it must match
    `recipe.n_samples`, `features` and `sample_seed`); `on_epoch(epoch, losses)` sees the
    epoch losses (on the CPU) of the still active materials. `device`: where to compute;
    the outcomes' weights live there. `engine` (CPU only, not a config key): "manual", the
    hand-written forward and backward pass, or "autograd", the reference it is tested against.
    """
    if len(tables) != len(inits) or not tables:
        raise ValueError(f"fit_batched needs one initial weight dict per table, got {len(inits)} for {len(tables)}")
    device = torch.device(device)
    scale = torch.ones(3) if output_scale is None else output_scale.detach().cpu().to(torch.float32)
    names = list(inits[0])
    hidden = net.hidden_of(inits[0])
    for w in inits:
        if list(w) != names or net.hidden_of(w) != hidden:
            raise ValueError("every initial weight dict must have the same layout")
    if samples is None:
        samples = _drawn(recipe.n_samples, features, sample_seed, recipe.sampling)
    if recipe.loss in ("l1_or_l2", "l1_then_l2"):
        kw = dict(features=features, output_scale=output_scale, sample_seed=sample_seed, samples=samples,
                  progress=progress, on_epoch=on_epoch, device=device, cuda_graphs=cuda_graphs, engine=engine)
        first = fit_batched(tables, inits, recipe=replace(recipe, loss="l1"), **kw)
        if recipe.loss == "l1_or_l2":
            second = fit_batched(tables, inits, recipe=replace(recipe, loss="l2"), **kw)
            return [replace(min(pair, key=lambda o: o.loss), fitted=("l1", "l2")) for pair in zip(first, second)]  # ties: L1
        ratios = collapse_ratio(tables, [o.loss for o in first], samples, output_scale)
        refit = [i for i, r in enumerate(ratios) if r > COLLAPSE_RATIO]
        second = dict(zip(refit, fit_batched([tables[i] for i in refit], [inits[i] for i in refit],
                                             recipe=replace(recipe, loss="l2"), **kw))) if refit else {}
        out = []
        for i, (one, r) in enumerate(zip(first, ratios)):
            kept = min((one, second[i]), key=lambda o: o.loss) if i in second else one  # ties: the L1 fit
            out.append(replace(kept, fitted=("l1", "l2") if i in second else ("l1",), collapse=r))
        return out
    n_samples = samples.x.shape[0]
    log_targets, valid = zip(*(targets(t, samples, scale) for t in tables))
    # Sample-major (S, M, 3) and (S, M): each epoch's shuffle gathers whole rows, several
    # times faster than gathering along the middle dimension; each step's slice is made
    # material-major again, so the arithmetic is the same.
    y = torch.stack(log_targets, dim=1)
    mask = torch.stack(valid, dim=1).to(torch.float32)
    if (mask.sum(dim=0) == 0).any():
        raise ValueError("a target material has no valid cell at the training samples")
    cos = samples.cos_i.clamp(COS_MIN, 1 - 2.0**-24)
    log_c, log_1mc = torch.log(cos), torch.log1p(-cos)

    if engine not in ENGINES:
        raise ValueError(f"fit_batched: engine={engine!r}, expected one of {', '.join(ENGINES)}")
    steps_per_epoch = math.ceil(n_samples / recipe.batch_size)
    total_steps = recipe.epochs * steps_per_epoch
    on_cpu = device.type == "cpu" and not _DEVICE_PATH_ON_CPU
    stack = _FlatStack(inits, names) if on_cpu and engine == "manual" else _Stack(inits, names, device)
    if on_cpu:
        kind = _CpuEpochs if engine == "manual" else _AutogradEpochs
        epochs = kind(stack, recipe, samples.x, log_c, log_1mc, y, mask, total_steps)
    else:
        epochs = _DeviceEpochs(stack, recipe, samples.x, log_c, log_1mc, y, mask, total_steps, device, cuda_graphs)
    active = torch.arange(len(tables))
    outcomes: list[Outcome | None] = [None] * len(tables)
    best = torch.full((len(tables),), math.inf)
    since_best = torch.zeros(len(tables), dtype=torch.long)
    last_loss = torch.full((len(tables),), math.inf)
    order = torch.Generator().manual_seed(sample_seed + 1)
    bar = tqdm(range(recipe.epochs), desc=progress if isinstance(progress, str) else "nbrdf fit", unit="epoch",
               disable=not progress, leave=False, dynamic_ncols=True)
    for epoch in bar:
        losses = epochs.run(torch.randperm(n_samples, generator=order))
        last_loss[active] = losses
        if on_epoch is not None:
            on_epoch(epoch, losses)
        improved = losses < best[active] * (1 - recipe.min_improvement)
        best[active] = torch.minimum(best[active], losses)
        since_best[active] = torch.where(improved, 0, since_best[active] + 1)
        final = epoch == recipe.epochs - 1
        may_stop = recipe.patience is not None and 2 * (epoch + 1) > recipe.epochs
        if final:
            done = torch.ones(len(active), dtype=torch.bool)
        elif may_stop:
            done = since_best[active] >= recipe.patience
        else:
            done = torch.zeros(len(active), dtype=torch.bool)
        for row in torch.nonzero(done).flatten().tolist():
            i = int(active[row])
            outcomes[i] = Outcome(stack.weights(row), float(last_loss[i]), epoch + 1, recipe.loss, (recipe.loss,))
        if done.any() and not final:
            rows = torch.nonzero(~done).flatten()
            stack.keep(rows)
            active = active[rows]
            epochs.keep(rows)
        bar.set_postfix(active=len(active), median_loss=f"{float(losses.median()):.4g}")
        if len(active) == 0:
            break
    bar.close()
    return [o for o in outcomes if o is not None]


class _AutogradEpochs:
    """The epochs of a fit on the CPU by torch autograd: eager steps with host scalars. The
    reference that the hand-written `_CpuEpochs` is tested and benchmarked against."""

    def __init__(self, stack, recipe, x, log_c, log_1mc, y, mask, total_steps):
        self.stack, self.recipe, self.total = stack, recipe, total_steps
        self.x, self.log_c, self.log_1mc, self.y, self.mask = x, log_c, log_1mc, y, mask
        self.step = 0

    def keep(self, rows: torch.Tensor) -> None:
        self.y, self.mask = self.y[:, rows], self.mask[:, rows]

    def _backward(self, x, log_c, log_1mc, y, mask) -> tuple[torch.Tensor, torch.Tensor]:
        """The gradients of one minibatch into the stack's .grad; its (M,) summed L1 errors and counts."""
        recipe = self.recipe
        z = self.stack.forward(x)  # (M, B, 3)
        pred = predict_log(z, log_c[:, None], log_1mc[:, None], recipe.output)
        m = mask.T.contiguous()  # (M, B)
        diff = pred - y.transpose(0, 1).contiguous()
        err = diff.abs().mean(dim=2) * m  # (M, B)
        count = m.sum(dim=1)
        descended = diff.square().mean(dim=2) * m if recipe.loss == "l2" else err
        per_material = descended.sum(dim=1) / count.clamp(min=1)
        per_material.sum().backward()
        return err.detach().sum(dim=1), count

    def gradients(self, idx: torch.Tensor) -> list[dict[str, torch.Tensor]]:
        """Each material's gradient of the minibatch `idx`, in the weights' layout (no step taken)."""
        self._backward(self.x[idx], self.log_c[idx], self.log_1mc[idx], self.y[idx], self.mask[idx])
        out = [{} for _ in range(self.y.shape[1])]
        for name, p in zip(self.stack.names, self.stack.params):
            for i, g in enumerate(p.grad):
                out[i][name] = (g[0] if name.startswith("b") else g).clone()
            p.grad = None
        return out

    def run(self, perm: torch.Tensor) -> torch.Tensor:
        """One epoch over the samples in `perm`'s order; each active material's mean L1 loss."""
        x_e, c_e, d_e = self.x[perm], self.log_c[perm], self.log_1mc[perm]
        y_e, m_e = self.y.index_select(0, perm), self.mask.index_select(0, perm)
        epoch_sum = torch.zeros(self.y.shape[1])
        epoch_count = torch.zeros(self.y.shape[1])
        for start in range(0, perm.shape[0], self.recipe.batch_size):
            sl = slice(start, start + self.recipe.batch_size)
            err, count = self._backward(x_e[sl], c_e[sl], d_e[sl], y_e[sl], m_e[sl])
            self.stack.adam_step(learning_rate(self.recipe, self.step, self.total))
            self.step += 1
            epoch_sum += err
            epoch_count += count
        return epoch_sum / epoch_count.clamp(min=1)


class _FlatStack:
    """`_Stack` for the hand-written CPU steps: every layer transposed, weights (M, out, in)
    and biases (M, out, 1), all of them views of one flat buffer (and so their gradients
    and Adam moments), so that activations are (M, width, B) with the minibatch contiguous
    and one Adam update covers the whole stack."""

    def __init__(self, inits: Sequence[dict[str, torch.Tensor]], names: list[str]):
        self.names = names
        self.shapes = [tuple(inits[0][names[2 * i]].shape[::-1]) for i in range(len(names) // 2)]  # (out, in)
        n = len(inits)
        self._allocate(n)
        for i, (out, _) in enumerate(self.shapes):
            self.W[i].copy_(torch.stack([w[names[2 * i]].to(torch.float32).T for w in inits]))
            self.b[i].copy_(torch.stack([w[names[2 * i + 1]].to(torch.float32) for w in inits])[:, :, None])
        self.t = 0

    def _allocate(self, n: int) -> None:
        size = n * sum(o * i + o for o, i in self.shapes)
        self.flat, self.grad = torch.empty(size), torch.zeros(size)
        self.m, self.v, self.denom = torch.zeros(size), torch.zeros(size), torch.empty(size)
        self.W, self.b = self._views(self.flat)
        self.gW, self.gb = self._views(self.grad)

    def _views(self, buffer: torch.Tensor):
        n = buffer.numel() // sum(o * i + o for o, i in self.shapes)
        ws, bs, at = [], [], 0
        for out, inp in self.shapes:
            ws.append(buffer[at:at + n * out * inp].view(n, out, inp))
            at += n * out * inp
            bs.append(buffer[at:at + n * out].view(n, out, 1))
            at += n * out
        return ws, bs

    @property
    def n(self) -> int:
        return self.W[0].shape[0]

    def adam_step(self, lr: float) -> None:
        """`adam_update` of the whole stack (the same arithmetic, one buffer)."""
        self.t += 1
        b1, b2 = ADAM_BETAS
        c1, c2 = 1 - b1**self.t, 1 - b2**self.t
        g = self.grad
        self.m.mul_(b1).add_(g, alpha=1 - b1)
        self.v.mul_(b2).addcmul_(g, g, value=1 - b2)
        torch.div(self.v, c2, out=self.denom).sqrt_().add_(ADAM_EPS)
        self.flat.addcdiv_(self.m, self.denom, value=-lr / c1)

    def keep(self, rows: torch.Tensor) -> None:
        old = [self._views(t) for t in (self.flat, self.m, self.v)]
        self._allocate(len(rows))
        for buffer, (ws, bs) in zip((self.flat, self.m, self.v), old):
            new_ws, new_bs = self._views(buffer)
            for dst, src in zip(new_ws + new_bs, ws + bs):
                torch.index_select(src, 0, rows, out=dst)

    def weights(self, row: int) -> dict[str, torch.Tensor]:
        out = {}
        for i in range(len(self.shapes)):
            out[self.names[2 * i]] = self.W[i][row].T.clone(memory_format=torch.contiguous_format)
            out[self.names[2 * i + 1]] = self.b[i][row, :, 0].clone()
        return out

    def gradient(self, row: int) -> dict[str, torch.Tensor]:
        out = {}
        for i in range(len(self.shapes)):
            out[self.names[2 * i]] = self.gW[i][row].T.clone(memory_format=torch.contiguous_format)
            out[self.names[2 * i + 1]] = self.gb[i][row, :, 0].clone()
        return out


class _CpuEpochs:
    """The epochs of a fit on the CPU with a hand-written forward and backward pass (no
    autograd): batched matrix products into buffers allocated once per stack size, and
    in-place elementwise steps. Activations are (M, width, B), the minibatch contiguous: the
    first layer, whose input is shared, is one matrix product for all materials, and the
    narrow last layer runs fast. Each step gathers its samples' rows with numpy's `take`
    (torch's row gather of these wide rows is many times slower). Same loss and gradients as
    `_AutogradEpochs` (tests/unit/test_nbrdf_backward.py)."""

    def __init__(self, stack: _FlatStack, recipe, x, log_c, log_1mc, y, mask, total_steps):
        self.stack, self.recipe, self.total = stack, recipe, total_steps
        self.inputs = torch.cat((x, log_c[:, None], log_1mc[:, None]), dim=1).contiguous()  # (S, 8)
        self._set_targets(y, mask)
        self.step = 0

    def _set_targets(self, y: torch.Tensor, mask: torch.Tensor) -> None:
        """Each sample's row of targets (M, 3) then mask (M): one gather per step."""
        self.n_out = y.shape[2]
        self.rows = torch.cat((y.reshape(y.shape[0], -1), mask), dim=1).contiguous()
        self.buffers: dict[int, dict[str, torch.Tensor]] = {}  # minibatch size -> its buffers

    def keep(self, rows: torch.Tensor) -> None:
        k = self.n_out
        old = self.rows.shape[1] // (k + 1)
        y = self.rows[:, :old * k].view(-1, old, k)[:, rows]
        self._set_targets(y, self.rows[:, old * k:][:, rows])

    def _buffers(self, size: int) -> dict[str, torch.Tensor]:
        if size not in self.buffers:
            n, k, e = self.stack.n, self.n_out, torch.empty
            widths = [o for o, _ in self.stack.shapes]
            buf = {"a": [e(n, o, size) for o in widths], "g": [e(n, o, size) for o in widths[:-1]]}
            buf.update(inputs=e(size, self.inputs.shape[1]), rows=e(size, self.rows.shape[1]),
                       xT=e(self.inputs.shape[1] - 2, size), c=e(size), d=e(size), y=e(n, k, size), m=e(n, 1, size),
                       s=e(n, k, size), pred=e(n, k, size), diff=e(n, k, size), gz=e(n, k, size), err=e(n, size))
            self.buffers[size] = buf
        return self.buffers[size]

    def _backward(self, idx) -> tuple[torch.Tensor, torch.Tensor]:
        """The gradients of the minibatch `idx` (a numpy index array) into the stack's grad
        buffer; each material's summed L1 error (over samples, mean over channels) and valid count."""
        st, recipe, b = self.stack, self.recipe, self._buffers(len(idx))
        n, k, size = st.n, self.n_out, len(idx)
        inputs = b["inputs"]
        np.take(self.inputs.numpy(), idx, axis=0, out=inputs.numpy())
        np.take(self.rows.numpy(), idx, axis=0, out=b["rows"].numpy())
        xT = b["xT"].copy_(inputs[:, :-2].T)
        log_c, log_1mc = b["c"].copy_(inputs[:, -2]), b["d"].copy_(inputs[:, -1])
        y = b["y"].copy_(b["rows"][:, :n * k].view(size, n, k).permute(1, 2, 0))
        m = b["m"].copy_(b["rows"][:, n * k:].T[:, None, :])
        # forward: a[i] is layer i's output, after the ReLU on the hidden layers
        a = b["a"]
        last = len(a) - 1
        rows0 = n * st.shapes[0][0]
        torch.addmm(st.b[0].view(rows0, 1), st.W[0].view(rows0, -1), xT, out=a[0].view(rows0, size))
        for i in range(1, len(a)):
            a[i - 1].relu_()
            torch.baddbmm(st.b[i], st.W[i], a[i - 1], out=a[i])
        z = a[last]
        # the loss, and its gradient with respect to z
        s, pred, diff, gz = b["s"], b["pred"], b["diff"], b["gz"]
        if recipe.output == "log":
            torch.add(z, log_c, out=s)
            torch.logaddexp(s, log_1mc.expand_as(s), out=pred)  # as predict_log
        else:
            torch.clamp(z, max=net.MAX_LOG_VALUE, out=s)
            torch.expm1(s, out=pred).relu_()
            pred.mul_(log_c.exp()).log1p_()
        torch.sub(pred, y, out=diff)
        count = m.sum(dim=(1, 2))
        err = torch.sum(torch.abs(diff, out=gz), dim=1, out=b["err"]).mul_(m[:, 0])
        errs = err.sum(dim=1).div_(k)
        weight = m / (k * count.clamp(min=1))[:, None, None]  # the per-material mean over valid samples and channels
        if recipe.loss == "l2":
            torch.mul(diff, weight, out=gz).mul_(2)
        else:
            torch.sign(diff, out=gz).mul_(weight)
        if recipe.output == "log":
            gz.mul_(s.sub_(pred).exp_())  # d pred / d z = sigmoid(z + log c − log(1 − c)) = exp(z + log c − pred)
        else:  # d pred / d z = c e^z / (1 + f c) = exp(z + log c − pred) where relu and the clamp pass it, else 0
            gz.mul_(s.add_(log_c).sub_(pred).exp_()).mul_((z > 0) & (z <= net.MAX_LOG_VALUE))
        # backward
        g = gz
        for i in range(last, 0, -1):
            torch.bmm(g, a[i - 1].transpose(1, 2), out=st.gW[i])
            torch.sum(g, dim=2, keepdim=True, out=st.gb[i])
            h = b["g"][i - 1]
            torch.bmm(st.W[i].transpose(1, 2), g, out=h)
            g = torch.ops.aten.threshold_backward.grad_input(h, a[i - 1], 0.0, grad_input=h)  # ReLU's gradient
        torch.mm(g.view(rows0, size), xT.T, out=st.gW[0].view(rows0, -1))
        torch.sum(g, dim=2, keepdim=True, out=st.gb[0])
        return errs, count

    def gradients(self, idx: torch.Tensor) -> list[dict[str, torch.Tensor]]:
        """Each material's gradient of the minibatch `idx`, in the weights' layout (no step taken)."""
        self._backward(idx.numpy())
        return [self.stack.gradient(i) for i in range(self.stack.n)]

    def run(self, perm: torch.Tensor) -> torch.Tensor:
        """One epoch over the samples in `perm`'s order; each active material's mean L1 loss."""
        epoch_sum = torch.zeros(self.stack.n)
        epoch_count = torch.zeros(self.stack.n)
        order = perm.numpy()
        for start in range(0, len(order), self.recipe.batch_size):
            errs, count = self._backward(order[start:start + self.recipe.batch_size])
            self.stack.adam_step(learning_rate(self.recipe, self.step, self.total))
            self.step += 1
            epoch_sum += errs
            epoch_count += count
        return epoch_sum / epoch_count.clamp(min=1)


class _DeviceEpochs:
    """The epochs of a fit on a GPU: data moved once, steps that never wait for the host,
    one CUDA graph per minibatch shape (see the module docstring)."""

    def __init__(self, stack, recipe, x, log_c, log_1mc, y, mask, total_steps, device, cuda_graphs: bool):
        self.stack, self.recipe, self.device = stack, recipe, device
        self.x, self.log_c, self.log_1mc = x.to(device), log_c.to(device), log_1mc.to(device)
        self.y, self.mask = y.to(device), mask.to(device)
        self.schedule = adam_schedule(recipe, total_steps, device)
        self.hyper = torch.empty(2, device=device)
        self.acc = torch.zeros(2, y.shape[1], device=device)  # the epoch's summed L1 errors and counts
        self.step = 0
        self.use_graphs = cuda_graphs and device.type == "cuda"
        self.graphs: dict[int, tuple] = {}  # minibatch size -> (graph, its index buffer)

    def keep(self, rows: torch.Tensor) -> None:
        rows = rows.to(self.device)
        self.y, self.mask = self.y[:, rows], self.mask[:, rows]
        self.acc = torch.zeros(2, self.y.shape[1], device=self.device)
        self.graphs.clear()  # the stack's tensors are new: capture again

    def _step(self, idx: torch.Tensor) -> None:
        recipe = self.recipe
        z = self.stack.forward(self.x.index_select(0, idx))  # (M, B, 3)
        pred = predict_log(z, self.log_c.index_select(0, idx)[:, None], self.log_1mc.index_select(0, idx)[:, None],
                           recipe.output)
        m = self.mask.index_select(0, idx).T.contiguous()  # (M, B)
        diff = pred - self.y.index_select(0, idx).transpose(0, 1).contiguous()
        err = diff.abs().mean(dim=2) * m
        count = m.sum(dim=1)
        descended = diff.square().mean(dim=2) * m if recipe.loss == "l2" else err
        per_material = descended.sum(dim=1) / count.clamp(min=1)
        per_material.sum().backward()
        self.stack.adam_step_scheduled(self.hyper)
        with torch.no_grad():
            self.acc[0].add_(err.detach().sum(dim=1))
            self.acc[1].add_(count)

    def _graph(self, size: int):
        """The captured step for minibatches of `size` (None where capture is unavailable)."""
        if size not in self.graphs:
            self.graphs[size] = self._capture(size) if self.use_graphs else None
        return self.graphs[size]

    def _capture(self, size: int):
        idx = torch.zeros(size, dtype=torch.long, device=self.device)
        state = self.stack.state()
        saved = [t.detach().clone() for t in (*state, self.acc)]
        try:
            side = torch.cuda.Stream(self.device)
            side.wait_stream(torch.cuda.current_stream(self.device))
            with torch.cuda.stream(side):  # warm-up (cuBLAS handles, autograd) off the capture
                for _ in range(2):
                    self._step(idx)
            torch.cuda.current_stream(self.device).wait_stream(side)
            with torch.no_grad():  # the warm-up steps were not training: undo them
                for t, v in zip((*state, self.acc), saved):
                    t.copy_(v)
            for p in self.stack.params:
                p.grad = None
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):
                self._step(idx)
            with torch.no_grad():  # capturing ran the kernels' allocation, not their effect; restore anyway
                for t, v in zip((*state, self.acc), saved):
                    t.copy_(v)
            return graph, idx
        except Exception as exc:  # a driver or torch without graph support: eager steps, same arithmetic
            log.warning("nbrdf fit: CUDA graph capture failed (%s); stepping eagerly", exc)
            self.use_graphs = False
            with torch.no_grad():
                for t, v in zip((*state, self.acc), saved):
                    t.copy_(v)
            for p in self.stack.params:
                p.grad = None
            return None

    def run(self, perm: torch.Tensor) -> torch.Tensor:
        perm = perm.to(self.device)
        self.acc.zero_()
        batch = self.recipe.batch_size
        for start in range(0, perm.shape[0], batch):
            idx = perm[start:start + batch]
            self.hyper.copy_(self.schedule[self.step])
            captured = self._graph(idx.shape[0])
            if captured is None:
                self._step(idx)
            else:
                graph, buffer = captured
                buffer.copy_(idx)
                graph.replay()
            self.step += 1
        losses = self.acc[0] / self.acc[1].clamp(min=1)
        return losses.cpu()
