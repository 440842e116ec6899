"""Fitting many neural BRDFs at once: stacked weights, one batched matmul per layer.

Every material of a batch sees the same training samples in the same order, drawn
uniformly in (θh, θd, φd) — the BRDF-aware sampling of Sztrajman et al. (2021), which puts
many samples near the specular peak (small θh) — with pairs below the horizon dropped
for all, and each material's invalid (negative) cells dropped for it alone. The weights
of M materials are stacked (M, in, out); a minibatch of B samples runs through all of
them as batched matrix products, and a hand-written Adam updates the stack. Each
material's loss is normalised by its own valid-sample count, so the gradients of
different materials never mix: a material's fit does not depend on its batch-mates
(`fit_batched` of one material is the one-at-a-time loop, same arithmetic).

Loss: mean |log(1 + f cos θi) − log(1 + f̂ cos θi)| over valid samples and channels (L1, the
published one); "l2" descends the mean squared difference instead, and "l1_or_l2" fits
with each from the same start on the same samples and keeps, per material, the fit whose
final L1 loss is lower. The epoch losses that the early stop and `Outcome.loss` read are
always L1, so fits by either loss compare. Why the naive MLP needs it: see its class.
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

import logging
import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

import torch
from tqdm.auto import tqdm

from brdfbench import coords, merl
from brdfbench.errors import ConfigError
from brdfbench.nbrdf import network as net

SCHEDULES = ("onecycle", "constant")
OUTPUTS = ("log", "clamped")
SAMPLINGS = ("uniform", "peak")
LOSSES = ("l1", "l2", "l1_or_l2")
ADAM_BETAS = (0.9, 0.999)
ADAM_EPS = 1e-7  # Keras' default, as the reference recipe used
ONECYCLE_WARMUP = 0.1  # fraction of the steps spent warming up
ONECYCLE_START_DIV = 25.0  # the warm-up starts at lr / 25
ONECYCLE_END_DIV = 1e4  # and the cosine anneal ends at lr / 1e4
COS_MIN = 1e-7  # cos θi is clamped into [COS_MIN, 1 − 2⁻²⁴] inside the log-space loss

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
    loss: str = "l1"  # "l1", "l2" (squared log error), or "l1_or_l2" (both fits, the lower L1 loss kept)

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
    descended), the epochs it ran and the loss it descended."""

    weights: dict[str, torch.Tensor]
    loss: float
    epochs: int
    descended: str = "l1"


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
) -> list[Outcome]:
    """Fit one network per table, all in one pass; `inits` gives each one's initial weights.

    `samples` may be passed in to share one draw across several calls (it must match
    `recipe.n_samples`, `features` and `sample_seed`); `on_epoch(epoch, losses)` sees the
    epoch losses (on the CPU) of the still active materials. `device`: where to compute;
    the outcomes' weights live there.
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
        samples = draw_samples(recipe.n_samples, features, sample_seed, recipe.sampling)
    if recipe.loss == "l1_or_l2":
        runs = [fit_batched(tables, inits, features=features, recipe=replace(recipe, loss=loss), output_scale=output_scale,
                            sample_seed=sample_seed, samples=samples, progress=progress, on_epoch=on_epoch,
                            device=device, cuda_graphs=cuda_graphs)
                for loss in ("l1", "l2")]
        return [min(pair, key=lambda o: o.loss) for pair in zip(*runs)]  # ties: the L1 fit
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

    stack = _Stack(inits, names, device)
    steps_per_epoch = math.ceil(n_samples / recipe.batch_size)
    total_steps = recipe.epochs * steps_per_epoch
    if device.type == "cpu" and not _DEVICE_PATH_ON_CPU:
        epochs = _CpuEpochs(stack, recipe, samples.x, log_c, log_1mc, y, mask, total_steps)
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
            outcomes[i] = Outcome(stack.weights(row), float(last_loss[i]), epoch + 1, recipe.loss)
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


class _CpuEpochs:
    """The epochs of a fit on the CPU: eager steps with host scalars."""

    def __init__(self, stack, recipe, x, log_c, log_1mc, y, mask, total_steps):
        self.stack, self.recipe, self.total = stack, recipe, total_steps
        self.x, self.log_c, self.log_1mc, self.y, self.mask = x, log_c, log_1mc, y, mask
        self.step = 0

    def keep(self, rows: torch.Tensor) -> None:
        self.y, self.mask = self.y[:, rows], self.mask[:, rows]

    def run(self, perm: torch.Tensor) -> torch.Tensor:
        """One epoch over the samples in `perm`'s order; each active material's mean L1 loss."""
        stack, recipe = self.stack, self.recipe
        x_e, c_e, d_e = self.x[perm], self.log_c[perm], self.log_1mc[perm]
        y_e, m_e = self.y.index_select(0, perm), self.mask.index_select(0, perm)
        epoch_sum = torch.zeros(self.y.shape[1])
        epoch_count = torch.zeros(self.y.shape[1])
        for start in range(0, perm.shape[0], recipe.batch_size):
            sl = slice(start, start + recipe.batch_size)
            z = stack.forward(x_e[sl])  # (M, B, 3)
            pred = predict_log(z, c_e[sl, None], d_e[sl, None], recipe.output)
            m = m_e[sl].T.contiguous()  # (M, B)
            diff = pred - y_e[sl].transpose(0, 1).contiguous()
            err = diff.abs().mean(dim=2) * m  # (M, B)
            count = m.sum(dim=1)
            descended = diff.square().mean(dim=2) * m if recipe.loss == "l2" else err
            per_material = descended.sum(dim=1) / count.clamp(min=1)
            per_material.sum().backward()
            stack.adam_step(learning_rate(recipe, self.step, self.total))
            self.step += 1
            epoch_sum += err.detach().sum(dim=1)
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


def with_overrides(recipe: Recipe, **changes) -> Recipe:
    return replace(recipe, **{k: v for k, v in changes.items() if v is not None})
