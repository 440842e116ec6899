"""VAE-A and VAE-N: the VAE baselines of Zhou et al.'s Table 1 (Sec. 4.3, A.4, B.5).

Both are Gaussian VAEs (Kingma and Welling) with MLP encoder and decoder, trained on the
ELBO with an MSE likelihood and sampled from the standard normal prior, z ~ N(0, I).

- `vae_nbrdf` (VAE-N) learns from aligned NBRDF weight vectors (675 values), standardised
  per coordinate (training mean and standard deviation, kept in the state). Coordinates
  with no variance (e.g. the first layer's weights on the always-zero input of the
  Rusinkiewicz encoding, which a shared initialisation leaves equal) are fed as 0, left
  out of the loss and decoded as their constant. 4 layers each side, hidden and latent
  100, batch 32, lr 1e-3 (Zhou et al., B.5).
- `vae_brdf` (VAE-A) learns from MERL tables downsampled to 45 × 45 × 90 (Zhou et al., B.5).
  Value space: x = ln(1 + ρ·cosθi·cosθo / ε), the logrel mapping relative to the zero BRDF
  (`logrel.to_mapped` with reference 0, ε = 1e-3): reference-free, ≥ 0, and, like the PCA
  space, weighing the specular peak and the diffuse floor alike. A low-resolution cell is
  the mean of x over the valid cells (both directions above the horizon) of its 2 × 2 × 2
  block; the blocks with no cell above the horizon are dropped, leaving 3 × 139 254 values.
  A decoded table is upsampled by nearest neighbour (each cell takes its block's x) and
  unmapped with each cell's own cosine weight; cells below the horizon are invalid.

  Architecture: the 417 762 values pass first through a fixed linear reduction, the
  principal directions of the training tables (centred, at most n − 1 of them: lossless
  on the training set), and the MLP VAE (hidden 256, latent 300, batch 16 as in B.5; 4
  layers each side as VAE-N's) works on the coefficients. Why: an MLP's first layer on the raw values would hold
  10⁸ parameters, which neither fits the CPU budget nor can be learned from a few hundred
  tables; and under gradient descent a first layer only ever moves within the span of its
  training inputs (its gradient is a sum of outer products with them), while the decoder's
  best output for a training table lies in their span too (projecting onto it can only
  lower the squared error), so the reduction takes away nothing the training tables could
  teach the network. The encoder sees the coefficients whitened; the decoder predicts them
  whitened, scaled back by each component's deviation. The likelihood stays an MSE in the
  value space: the basis is orthonormal, so the squared error of the coefficients is the
  squared error of the low-resolution table within the span. Samples are TableSamples
  whose array holds the decoded coefficients (n, r).

The loss per material is U + kl_weight · KL: U the squared error as a share of the training
set's total variance (VAE-N: of the standardised coordinates; VAE-A: of the value space),
KL the posterior's divergence from the prior in nats. That is the negative ELBO (scaled)
of a Gaussian likelihood whose noise variance in every direction is kl_weight / 2 of the
total variance: as in probabilistic PCA, directions holding less than that are left to
the noise. The source papers name an MSE likelihood but no weight; kl_weight = 2e-3 by default
models the directions holding more than 0.1 % of the variance (99 % of it on 180
synthetic tables). A weaker KL (2e-4) lets 180 training tables be memorised in narrow
posteriors whose gaps the prior's samples fall into (they decode near the mean); a much
stronger one keeps only the top few directions.

"Until convergence" (B.5) is an epoch budget with early stopping: training stops once
the monitored loss has not improved by 0.01 % for `patience` epochs, and the best
weights are kept. The monitored loss is that of a held-out `val_fraction` of the
training vectors (evaluated at z = μ, deterministic), or, where that leaves fewer than
1 held-out or 2 training vectors, the training loss. VAE-A trains at lr 1e-3, not B.5's
5e-3: at 5e-3 Adam diverged on 180 synthetic tables (the loss went from 0.12 to 25).

Devices: both run on "cpu" and "cuda" (`to`). The data are prepared on the CPU (VAE-A reads
and reduces its tables there, the Gram matrix and the basis computed on the device) and
moved once; the networks are initialised on the CPU from the seed and moved. Shuffles and
noise come from CPU generators in a step-by-step loop's order, an epoch's draws moved at
once, and the epoch's loss sums stay on the device in fp64 and are read once per epoch: on
the CPU this is the arithmetic of a loop that reads each step's loss, bit for bit.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from brdfbench import logrel, merl
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.threads import torch_threads
from brdfbench.protocols.generator import TRAINING_CURVE_KEY, Generator, SampleSet, TrainingData
from brdfbench.protocols.generator_state import check_tensor, read_layout, weight_layout

from .pca import (
    FIT_OVERHEAD, MAX_MAPPED, values_on_domain, block_columns, check_fit_memory, chunked_combine, domain_table,
    gram_pca, positive_int, select_names, training_vectors, weight_samples,
)
from .samples import TableSamples

log = logging.getLogger(__name__)

#: Low-resolution table shape (each dimension of 90 × 90 × 180 halved).
LOW_SHAPE = tuple(s // 2 for s in merl.SHAPE)
#: Relative improvement the early stop counts as progress.
MIN_IMPROVEMENT = 1e-4
#: Samples decoded at once.
DECODE_BATCH = 4096
#: Bounds of the predicted log-variance (keeps exp() finite early in training).
LOGVAR_RANGE = (-30.0, 20.0)


# --------------------------------------------------------------------------- parameters


def positive_float(owner: str, key: str, value: Any, *, zero_ok: bool = False) -> float:
    """`value` as a finite float > 0 (≥ 0 when zero_ok), else a ConfigError naming the key."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    ok = ok and math.isfinite(value) and (value >= 0 if zero_ok else value > 0)
    if not ok:
        raise ConfigError(f"{owner}: {key}={value!r} must be a finite number {'≥ 0' if zero_ok else '> 0'}")
    return float(value)


def fraction(owner: str, key: str, value: Any) -> float:
    """`value` as a float in [0, 0.5), else a ConfigError naming the key."""
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not ok or not 0 <= value < 0.5:
        raise ConfigError(f"{owner}: {key}={value!r} must be a number in [0, 0.5)")
    return float(value)


@dataclass(frozen=True)
class Recipe:
    """The training settings shared by both VAEs (validated constructor params)."""

    latent: int
    hidden: int
    layers: int
    epochs: int
    batch_size: int
    lr: float
    kl_weight: float
    patience: int | None
    val_fraction: float

    @classmethod
    def checked(cls, owner: str, **p) -> "Recipe":
        return cls(
            latent=positive_int(owner, "latent", p["latent"]), hidden=positive_int(owner, "hidden", p["hidden"]),
            layers=positive_int(owner, "layers", p["layers"]), epochs=positive_int(owner, "epochs", p["epochs"]),
            batch_size=positive_int(owner, "batch_size", p["batch_size"]), lr=positive_float(owner, "lr", p["lr"]),
            kl_weight=positive_float(owner, "kl_weight", p["kl_weight"], zero_ok=True),
            patience=positive_int(owner, "patience", p["patience"], optional=True),
            val_fraction=fraction(owner, "val_fraction", p["val_fraction"]),
        )

    def params(self) -> dict[str, Any]:
        return dict(self.__dict__)


def rng(seed: int, purpose: int) -> torch.Generator:
    """An explicit generator per purpose (split, init, training noise, sampling) of a seed."""
    return torch.Generator().manual_seed(int(seed) * 8 + purpose)


def holdout(n: int, val_fraction: float, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(train, held-out) indices, each ascending: round(val_fraction · n) held out, none where
    that would leave no held-out or fewer than 2 training vectors."""
    n_val = int(math.floor(val_fraction * n + 0.5))
    if n_val < 1 or n - n_val < 2:
        if val_fraction > 0:
            log.info("%d training vectors leave no held-out set at val_fraction=%s: early stopping "
                     "monitors the training loss", n, val_fraction)
        return torch.arange(n), torch.arange(0)
    order = torch.randperm(n, generator=rng(seed, 0))
    return order[n_val:].sort().values, order[:n_val].sort().values


# --------------------------------------------------------------------------- the network


def _mlp(sizes: list[int], generator: torch.Generator) -> nn.Sequential:
    """Linear layers of `sizes` with ReLU between, initialised U(±1/√fan_in) from `generator`
    (PyTorch's default bounds, without touching the global RNG)."""
    modules: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layer = nn.utils.skip_init(nn.Linear, a, b)
        bound = 1.0 / math.sqrt(a)
        with torch.no_grad():
            layer.weight.uniform_(-bound, bound, generator=generator)
            layer.bias.uniform_(-bound, bound, generator=generator)
        modules.append(layer)
        if i < len(sizes) - 2:
            modules.append(nn.ReLU())
    return nn.Sequential(*modules)


class VAENet(nn.Module):
    """Encoder x → (μ, log σ²) and decoder z → x̂, `layers` linear layers each."""

    def __init__(self, d_in: int, recipe: Recipe, generator: torch.Generator):
        super().__init__()
        inner = [recipe.hidden] * (recipe.layers - 1)
        self.latent = recipe.latent
        self.encoder = _mlp([d_in, *inner, 2 * recipe.latent], generator)
        self.decoder = _mlp([recipe.latent, *inner, d_in], generator)

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logvar = self.encoder(x).split(self.latent, dim=1)
        return mu, logvar.clamp(*LOGVAR_RANGE)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        return self.decoder(z)


def net_shapes(d_in: int, recipe: Recipe) -> dict[str, tuple[int, ...]]:
    """Names and shapes of a VAENet's tensors, as state_dict() names them."""
    inner = [recipe.hidden] * (recipe.layers - 1)
    shapes = {}
    for part, sizes in (("encoder", [d_in, *inner, 2 * recipe.latent]), ("decoder", [recipe.latent, *inner, d_in])):
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
            shapes[f"{part}.{2 * i}.weight"] = (b, a)
            shapes[f"{part}.{2 * i}.bias"] = (b,)
    return shapes


def load_net(owner: str, tensors: dict, d_in: int, recipe: Recipe) -> VAENet:
    """A VAENet from saved tensors `net.*`, each checked against the params."""
    state = {}
    for name, shape in net_shapes(d_in, recipe).items():
        state[name] = check_tensor(owner, tensors, f"net.{name}", shape, torch.float32)
    net = VAENet(d_in, recipe, torch.Generator().manual_seed(0))
    net.load_state_dict(state)
    return net.eval()




def loss_terms(net: VAENet, x: torch.Tensor, weight: torch.Tensor, total: float,
               eps: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    """(squared error weighted per coordinate, as a share of `total`; KL in nats), each averaged
    over the batch; z = μ where eps is None."""
    mu, logvar = net.encode(x)
    z = mu if eps is None else mu + torch.exp(0.5 * logvar) * eps
    recon = (((net.decode(z) - x) ** 2) * weight).sum(dim=1) / total
    kl = 0.5 * (mu**2 + logvar.exp() - 1.0 - logvar).sum(dim=1)
    return recon.mean(), kl.mean()


def train(net: VAENet, x: torch.Tensor, x_val: torch.Tensor | None, weight: torch.Tensor, total: float,
          recipe: Recipe, seed: int, progress, label: str) -> dict[str, Any]:
    """Adam on the ELBO with early stopping (see the module docstring); keeps the best weights.
    Returns the training curves. Runs where `net` and the data are (one device); the
    random numbers come from CPU generators (`rng`) on every device."""
    with torch_threads(1):
        g = rng(seed, 2)
        opt = torch.optim.Adam(net.parameters(), lr=recipe.lr)
        stop = EarlyStop(recipe.patience)
        curves: dict[str, list[float]] = {"train_loss": [], "train_kl": [], "val_loss": []}
        bar = tqdm(range(recipe.epochs), desc=progress if isinstance(progress, str) else label, unit="epoch",
                   disable=not progress, leave=False, dynamic_ncols=True)
        for epoch in bar:
            loss, kl = train_epoch(net, opt, x, weight, total, recipe, g)
            curves["train_loss"].append(loss)
            curves["train_kl"].append(kl)
            monitored = loss
            if x_val is not None:
                monitored = held_out_loss(net, x_val, weight, total, recipe)
                curves["val_loss"].append(monitored)
            if not math.isfinite(monitored):
                raise ConfigError(f"{label}: the loss diverged (non-finite at epoch {epoch + 1}); lower lr "
                                  f"(now {recipe.lr})")
            bar.set_postfix(loss=f"{loss:.4g}")
            if stop.update(monitored, net):
                break
        net.load_state_dict(stop.best_state)
        net.eval()
    return {**curves, "val_loss": curves["val_loss"] if x_val is not None else None,
            "best_epoch": stop.best_epoch, "epochs_run": len(curves["train_loss"]),
            "stopped": "patience" if stop.stopped else "epochs",
            "monitored": "val_loss" if x_val is not None else "train_loss"}


def epoch_draws(n: int, recipe: Recipe, g: torch.Generator, device: torch.device) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """An epoch's shuffled batches and their latent noise, drawn from `g` (a CPU generator)
    in a step-by-step loop's order (the permutation, then each batch's ε), moved to `device`
    once: [(rows, ε)] per batch."""
    batches = torch.randperm(n, generator=g).split(recipe.batch_size)
    eps = [torch.randn(rows.numel(), recipe.latent, generator=g) for rows in batches]
    rows_d, eps_d = torch.cat(batches).to(device), torch.cat(eps).to(device)
    sizes = [rows.numel() for rows in batches]
    return list(zip(rows_d.split(sizes), eps_d.split(sizes)))


def train_epoch(net: VAENet, opt: torch.optim.Optimizer, x: torch.Tensor, weight: torch.Tensor, total: float,
                recipe: Recipe, g: torch.Generator) -> tuple[float, float]:
    """One pass over x in shuffled batches; the epoch's mean loss and mean KL. The sums stay
    on x's device in fp64 (what host floats would hold) and are read once, at the end."""
    net.train()
    sums = torch.zeros(2, dtype=torch.float64, device=x.device)  # loss, KL
    for rows, eps in epoch_draws(x.shape[0], recipe, g, x.device):
        recon, kl = loss_terms(net, x[rows], weight, total, eps)
        loss = recon + recipe.kl_weight * kl
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sums[0] += loss.detach().double() * rows.numel()
        sums[1] += kl.detach().double() * rows.numel()
    sum_loss, sum_kl = sums.tolist()
    return sum_loss / x.shape[0], sum_kl / x.shape[0]


def held_out_loss(net: VAENet, x_val: torch.Tensor, weight: torch.Tensor, total: float, recipe: Recipe) -> float:
    """The loss of held-out vectors at z = μ (deterministic)."""
    net.eval()
    with torch.no_grad():
        recon, kl = loss_terms(net, x_val, weight, total, None)
    return float(recon + recipe.kl_weight * kl)


class EarlyStop:
    """Tracks the best monitored loss and its weights; says stop after `patience` epochs
    without a relative improvement of MIN_IMPROVEMENT (never, when patience is None)."""

    def __init__(self, patience: int | None):
        self.patience = patience
        self.best, self.best_state, self.best_epoch, self.since, self.epoch = math.inf, None, 0, 0, 0
        self.stopped = False

    def update(self, monitored: float, net: nn.Module) -> bool:
        self.epoch += 1
        if self.best_state is None or monitored < self.best * (1 - MIN_IMPROVEMENT):
            self.best, self.best_epoch, self.since = monitored, self.epoch, 0
            self.best_state = copy.deepcopy(net.state_dict())
        else:
            self.since += 1
        self.stopped = self.patience is not None and self.since >= self.patience
        return self.stopped


def decode(net: VAENet, n: int, seed: int) -> torch.Tensor:
    """Decoder outputs (n, d) of z ~ N(0, I) drawn from a CPU generator seeded by `seed`,
    decoded on the net's device (the outputs live there)."""
    g = torch.Generator().manual_seed(int(seed))
    z = torch.randn(n, net.latent, generator=g).to(next(net.parameters()).device)
    with torch.no_grad(), torch_threads(1):
        return torch.cat([net.decode(b) for b in z.split(DECODE_BATCH)])


def net_state(net: VAENet) -> dict[str, torch.Tensor]:
    return {f"net.{k}": v for k, v in net.state_dict().items()}


# --------------------------------------------------------------------------- VAE-N


class VAENBRDF(Generator):
    """VAE-N: an MLP VAE over standardised NBRDF weight vectors (see the module docstring)."""

    learns_from = "nbrdf"
    NAME = "vae_nbrdf"
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, latent: int = 100, hidden: int = 100, layers: int = 4, epochs: int = 2000,
                 batch_size: int = 32, lr: float = 1e-3, kl_weight: float = 2e-3, patience: int | None = 200,
                 val_fraction: float = 0.1):
        self.recipe = Recipe.checked(self.NAME, latent=latent, hidden=hidden, layers=layers, epochs=epochs,
                                     batch_size=batch_size, lr=lr, kl_weight=kl_weight, patience=patience,
                                     val_fraction=val_fraction)
        super().__init__(**self.recipe.params())
        self.net: VAENet | None = None
        self.mean: torch.Tensor | None = None  # (W,) fp32
        self.std: torch.Tensor | None = None  # (W,) fp32, 0 where the coordinate is constant
        self.layout: dict[str, Any] | None = None
        self.info: dict[str, Any] = {}

    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "VAENBRDF":
        start = time.perf_counter()
        ws = training_vectors(self.NAME, self.layout, data)
        n, width = ws.vectors.shape
        x = torch.from_numpy(np.ascontiguousarray(ws.vectors, dtype=np.float32))
        train_rows, val_rows = holdout(n, self.recipe.val_fraction, seed)
        mean, std = standardisation(x[train_rows])
        varying = std > 0
        if not varying.any():
            raise ConfigError(f"{self.NAME}: the training weight vectors are identical: no variance to model")
        z = (x - mean) / torch.where(varying, std, 1.0)
        device = self.device  # built and standardised on the CPU; the net and the vectors move once
        net = VAENet(width, self.recipe, rng(seed, 1)).to(device)
        curves = train(net, z[train_rows].to(device), z[val_rows].to(device) if val_rows.numel() else None,
                       varying.float().to(device), float(varying.sum()), self.recipe, seed, progress, self.NAME)
        self.net, self.mean, self.std, self.layout = net, mean.to(device), std.to(device), weight_layout(ws)
        self.info = {"n_materials": n, "n_train": int(train_rows.numel()), "n_held_out": int(val_rows.numel()),
                     "constant_coordinates": int((~varying).sum()), **curves,
                     "fit_seconds": time.perf_counter() - start}
        return self

    def _move(self, device: torch.device) -> None:
        if self.net is not None:
            self.net.to(device)
            self.mean, self.std = self.mean.to(device), self.std.to(device)

    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        out = decode(self.net, n, seed)
        return weight_samples(self.mean + out * self.std, self.layout)

    def sample_nbytes(self, n: int) -> int:
        width = 675 if self.mean is None else self.mean.numel()
        r = self.recipe
        batch = min(n, DECODE_BATCH) * (r.layers * r.hidden + width) * 4 * 2
        return n * (r.latent + 3 * width) * 4 + batch  # z; decoded, rescaled, the array; one batch's activations

    def state_dict(self) -> dict[str, torch.Tensor]:
        if self.net is None:
            return {}
        return {"mean": self.mean, "std": self.std, **net_state(self.net)}

    def metadata(self) -> dict[str, Any]:
        return {**self.info, "layout": self.layout, **curve_entry(self.info)}

    @classmethod
    def from_state(cls, params, tensors, metadata) -> "VAENBRDF":
        model = cls(**params)
        if not tensors:
            return model
        owner = f"{cls.NAME} model"
        layout = read_layout(owner, metadata.get("layout"))
        w = layout["width"]
        model.mean = check_tensor(owner, tensors, "mean", (w,), torch.float32)
        model.std = check_tensor(owner, tensors, "std", (w,), torch.float32, nonnegative=True)
        model.net = load_net(owner, tensors, w, model.recipe)
        model.layout = layout
        model.info = {k: v for k, v in metadata.items() if k != "layout"}
        return model


def standardisation(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-coordinate mean and standard deviation (fp32) of x (n, W), computed in fp64; the
    deviation is exactly 0 where every vector holds the same value."""
    xd = x.double()
    std = xd.std(dim=0) if x.shape[0] > 1 else torch.zeros(x.shape[1], dtype=torch.float64)
    constant = (x == x[0]).all(dim=0)
    return xd.mean(dim=0).float(), torch.where(constant, 0.0, std).float()


# --------------------------------------------------------------------------- downsampling (VAE-A)


def downsample(x: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Block means (C, 45, 45, 90) of x (C, 90, 90, 180) over the valid cells of each 2×2×2
    block, and each block's valid-cell count (45, 45, 90); blocks without one hold 0."""
    c = x.shape[0]
    a, b, d = LOW_SHAPE
    mask = valid.to(x.dtype)
    sums = (x * mask).reshape(c, a, 2, b, 2, d, 2).sum(dim=(2, 4, 6))
    counts = mask.reshape(a, 2, b, 2, d, 2).sum(dim=(1, 3, 5))
    return sums / counts.clamp_min(1), counts.to(torch.int64)


def upsample(low: torch.Tensor) -> torch.Tensor:
    """Nearest-neighbour upsampling (C, 45, 45, 90) → (C, 90, 90, 180): each cell takes its block's value."""
    return low.repeat_interleave(2, dim=1).repeat_interleave(2, dim=2).repeat_interleave(2, dim=3)


@lru_cache(maxsize=1)
def low_domain() -> torch.Tensor:
    """Flat indices of the low-resolution blocks that hold a cell with both directions above the horizon."""
    cells, _ = logrel.domain()
    full = torch.zeros(merl.N_CELLS, dtype=torch.bool)
    full[cells] = True
    _, counts = downsample(torch.zeros(1, *merl.SHAPE), full.view(merl.SHAPE))
    return torch.nonzero(counts.reshape(-1)).squeeze(1)


@lru_cache(maxsize=1)
def cell_blocks() -> torch.Tensor:
    """(P,) int64: for each cell of the logrel domain, the position of its block in `low_domain()`."""
    cells, _ = logrel.domain()
    a, b, d = merl.SHAPE
    ih, rest = cells // (b * d), cells % (b * d)
    block = (ih // 2) * (LOW_SHAPE[1] * LOW_SHAPE[2]) + (rest // d // 2) * LOW_SHAPE[2] + (rest % d) // 2
    position = torch.full((int(np.prod(LOW_SHAPE)),), -1, dtype=torch.int64)
    position[low_domain()] = torch.arange(low_domain().numel())
    return position[block]


def _zero_reference() -> torch.Tensor:
    return torch.zeros((), dtype=torch.float64)


def table_to_low(material) -> tuple[torch.Tensor, torch.Tensor]:
    """A material's low-resolution values (3, B) fp64 on the low domain, and (B,) block validity.

    `downsample` restricted to the domain's blocks, summed per block with index_add (the
    same means; the tests compare the two).
    """
    _, w = logrel.domain()
    values, valid = values_on_domain(material)
    x = logrel.to_mapped(values[:, valid].clamp_min(0.0), _zero_reference(), w[valid])
    blocks = cell_blocks()[valid]
    n_blocks = low_domain().numel()
    sums = torch.zeros(3, n_blocks, dtype=torch.float64).index_add_(1, blocks, x)
    counts = torch.bincount(blocks, minlength=n_blocks)
    return sums / counts.clamp_min(1), counts > 0


def low_to_table(low: torch.Tensor) -> merl.MerlTable:
    """The full MERL table of low-resolution values (3, B): nearest upsampling (each domain
    cell takes its block's value, as `upsample`), then unmapped with the cell's own weight."""
    _, w = logrel.domain()
    x = low.double()[:, cell_blocks()]
    return domain_table(logrel.from_mapped(x.clamp(max=MAX_MAPPED), _zero_reference(), w))


# --------------------------------------------------------------------------- VAE-A


class Reduction(NamedTuple):
    """VAE-A's fixed linear reduction and its training inputs."""

    mean: torch.Tensor  # (D,) fp32 mean low-resolution values of the training tables
    scale: float  # root mean per-value variance: values are divided by it
    basis: torch.Tensor  # (D, r) fp32 orthonormal principal directions
    variance: torch.Tensor  # (r,) fp64 each direction's training variance (scaled units)
    explained: torch.Tensor  # (r,) fp64 share of the total variance
    whitened: torch.Tensor  # (n_train, r) fp32 training coefficients / their deviation
    held_out: torch.Tensor | None  # (n_val, r) fp32, likewise


def reduce_tables(x: torch.Tensor, n_train: int, r: int, owner: str,
                  device: torch.device | None = None) -> Reduction:
    """The reduction of low-resolution tables x (n, D), training rows first; x is modified
    (centred, scaled) in place on the CPU. The Gram matrix, the basis and the coefficients
    are computed on `device` (default: x's), where the returned tensors but `mean` live."""
    device = x.device if device is None else device
    mean = x[:n_train].mean(dim=0)
    x -= mean
    d = x.shape[1]
    squares = sum(float((x[:n_train, c].double() ** 2).sum()) for c in block_columns(n_train, d))
    scale = max(math.sqrt(squares / ((n_train - 1) * d)), 1e-30)
    x /= scale
    eigvals, scores, basis, total = gram_pca(x[:n_train], r, owner, device=device)
    variance = eigvals / (n_train - 1)
    whitened = (scores / variance.sqrt()).float()
    held = (x[n_train:].to(device) @ basis) / variance.sqrt().float() if x.shape[0] > n_train else None
    return Reduction(mean, scale, basis, variance, eigvals / total, whitened, held)


class VAEBRDF(Generator):
    """VAE-A: an MLP VAE over downsampled MERL tables, through a fixed linear reduction
    (see the module docstring)."""

    learns_from = "tables"
    NAME = "vae_brdf"
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, latent: int = 300, hidden: int = 256, layers: int = 4, epochs: int = 2000,
                 batch_size: int = 16, lr: float = 1e-3, kl_weight: float = 2e-3, patience: int | None = 200,
                 val_fraction: float = 0.1, reduce_dim: int | None = None, max_materials: int | None = None):
        self.recipe = Recipe.checked(self.NAME, latent=latent, hidden=hidden, layers=layers, epochs=epochs,
                                     batch_size=batch_size, lr=lr, kl_weight=kl_weight, patience=patience,
                                     val_fraction=val_fraction)
        super().__init__(**self.recipe.params(),
                         reduce_dim=positive_int(self.NAME, "reduce_dim", reduce_dim, optional=True),
                         max_materials=positive_int(self.NAME, "max_materials", max_materials, optional=True))
        self.net: VAENet | None = None
        self.mean: torch.Tensor | None = None  # (D,) fp32 mean low-resolution values
        self.scale: torch.Tensor | None = None  # (1,) fp64: root mean per-value variance
        self.basis: torch.Tensor | None = None  # (D, r) fp32, orthonormal columns
        self.component_std: torch.Tensor | None = None  # (r,) fp32, in units of `scale`
        self.info: dict[str, Any] = {}

    @staticmethod
    def values_per_table() -> int:
        return 3 * low_domain().numel()

    def fit_nbytes(self, n: int, r: int) -> int:
        """Planned peak bytes of a fit on n tables with an r-dimensional reduction."""
        d = self.values_per_table()
        arrays = n * d * 4 + n * d // 3 + d * r * 4 + 3 * n * n * 8
        per_table = 6 * 3 * merl.N_CELLS * 8  # a table read, mapped on the full grid, downsampled
        return arrays + per_table + (64 << 20) * 2 + FIT_OVERHEAD

    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "VAEBRDF":
        start = time.perf_counter()
        names = select_names(self.NAME, data, self.params["max_materials"], seed)
        train_rows, val_rows = holdout(len(names), self.recipe.val_fraction, seed)
        order = [names[i] for i in torch.cat([train_rows, val_rows]).tolist()]  # training tables first
        n_train = train_rows.numel()
        r = self._reduce_dim(n_train)
        need = self.fit_nbytes(len(names), r)
        check_fit_memory(self.NAME, need, f"max_materials (now {self.params['max_materials']}, {len(names)} used)")
        device = self.device  # tables read and reduced on the CPU; the products and the VAE on `device`
        red = reduce_tables(self._load(data, order, n_train, progress), n_train, r, self.NAME, device)
        read_seconds = time.perf_counter() - start
        net = VAENet(red.basis.shape[1], self.recipe, rng(seed, 1)).to(device)
        curves = train(net, red.whitened, red.held_out, red.variance.float(), float(red.mean.numel()),
                       self.recipe, seed, progress, self.NAME)
        self.net, self.mean, self.basis = net, red.mean.to(device), red.basis
        self.component_std = red.variance.sqrt().float()
        self.scale = torch.tensor([red.scale], dtype=torch.float64, device=device)
        self.info = {"n_materials": len(names), "n_train": int(n_train), "n_held_out": int(val_rows.numel()),
                     "reduce_dim": int(red.basis.shape[1]), "values_per_table": int(red.mean.numel()),
                     "explained_variance": red.explained.tolist(), **curves,
                     "fit_seconds": time.perf_counter() - start, "read_and_reduce_seconds": read_seconds,
                     "planned_peak_bytes": need, "training_materials": order[:n_train]}
        return self

    def _reduce_dim(self, n_train: int) -> int:
        """The reduction's dimension: reduce_dim (default n − 1), capped at n − 1."""
        cap = self.params["reduce_dim"]
        r = min(cap or n_train, n_train - 1)
        if cap is not None and r < cap:
            log.info("%s: reduce_dim=%d capped at n - 1 = %d (%d training tables, mean removed)",
                     self.NAME, cap, r, n_train)
        return r

    def _load(self, data: TrainingData, names: list[str], n_train: int, progress) -> torch.Tensor:
        """(n, D) fp32 low-resolution values; a block invalid in a table takes the training tables' mean there."""
        d = self.values_per_table()
        x = torch.empty(len(names), d, dtype=torch.float32)
        valid = torch.empty(len(names), d // 3, dtype=torch.bool)
        label = progress if isinstance(progress, str) else f"{self.NAME} read"
        for i, name in enumerate(tqdm(names, desc=label, unit="table", disable=not progress, leave=False)):
            low, ok = table_to_low(data.load(name))
            x[i], valid[i] = low.reshape(-1), ok
        sums, counts = torch.zeros(d, dtype=torch.float64), torch.zeros(d // 3, dtype=torch.float64)
        for i in range(n_train):
            sums += torch.where(valid[i].repeat(3), x[i], 0.0)
            counts += valid[i]
        fill = (sums / counts.clamp_min(1).repeat(3)).float()
        for i in range(len(names)):
            x[i] = torch.where(valid[i].repeat(3), x[i], fill)
        return x

    def _move(self, device: torch.device) -> None:
        if self.net is not None:
            self.net.to(device)
            for key in ("mean", "scale", "basis", "component_std"):
                setattr(self, key, getattr(self, key).to(device))

    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        coefficients = decode(self.net, n, seed) * self.component_std
        return TableSamples(coefficients, self.to_table, name=self.NAME)

    def to_table(self, coefficients: torch.Tensor) -> merl.MerlTable:
        """The full MERL table of one decoded coefficient vector (r,): the low-resolution
        values combined where the basis lives, the table built on the CPU."""
        low = self.mean.double() + float(self.scale) * chunked_combine(self.basis, coefficients)
        return low_to_table(low.view(3, -1).cpu())

    def sample_nbytes(self, n: int) -> int:
        r = self.recipe
        dim = (self.params["reduce_dim"] or 512) if self.basis is None else self.basis.shape[1]
        batch = min(n, DECODE_BATCH) * (r.layers * r.hidden + dim) * 4 * 2
        per_table = 3 * merl.N_CELLS * 8 * 6 + self.values_per_table() * 8 * 2
        return n * (r.latent + 2 * dim) * 4 + batch + per_table

    def state_dict(self) -> dict[str, torch.Tensor]:
        if self.net is None:
            return {}
        return {"mean": self.mean, "scale": self.scale, "basis": self.basis, "component_std": self.component_std,
                **net_state(self.net)}

    def metadata(self) -> dict[str, Any]:
        return {**self.info, **curve_entry(self.info)}

    @classmethod
    def from_state(cls, params, tensors, metadata) -> "VAEBRDF":
        model = cls(**params)
        if not tensors:
            return model
        owner = f"{cls.NAME} model"
        d = cls.values_per_table()
        std = check_tensor(owner, tensors, "component_std", (None,), torch.float32, nonnegative=True)
        r = std.shape[0]
        cap = model.params["reduce_dim"]
        if r < 1 or (cap is not None and r > cap):
            raise ModelFileError(f"{owner}: tensor 'component_std' has {r} components; params reduce_dim={cap}")
        model.component_std = std
        model.mean = check_tensor(owner, tensors, "mean", (d,), torch.float32)
        model.scale = check_tensor(owner, tensors, "scale", (1,), torch.float64, nonnegative=True)
        model.basis = check_tensor(owner, tensors, "basis", (d, r), torch.float32)
        model.net = load_net(owner, tensors, r, model.recipe)
        model.info = dict(metadata)
        return model


def curve_entry(info: dict[str, Any]) -> dict[str, Any]:
    """The fit's curves under the protocol's TRAINING_CURVE_KEY (reports plot them)."""
    curves = {"loss": info.get("train_loss"), "held-out loss": info.get("val_loss")}
    curves = {k: v for k, v in curves.items() if v}
    return {TRAINING_CURVE_KEY: curves} if curves else {}
