"""PCA-A and PCA-N: the PCA baselines of Zhou et al.'s Table 1 (Sec. 4.3, A.1, B.4).

Both fit a principal subspace to the training set (one observation per material) and
sample from a Gaussian in it: coefficient j ~ N(0, λ_j), λ_j the training variance of
component j (Zhou et al., A.1; Sec. 4.3's "random linear interpolation" is not specified
further, so A.1's Gaussian is what is built), then mean + basis · coefficients.

- `pca_brdf` (PCA-A) learns from MERL tables. A material is one vector: its three
  channels on the cells with both directions above the horizon, mapped log-relative,
  cosine-weighted (`brdfbench.logrel`) to a reference BRDF, the per-cell, per-channel
  median of the training set's valid values; invalid cells sit at the reference (x = 0).
  k = 300 components by default (Zhou et al., B.4), capped at n − 1 for n materials.
- `pca_nbrdf` (PCA-N) learns from aligned NBRDF weight vectors (675 values for
  6-21-21-3), k = 100 by default (B.4), capped at N − 1 and at the width.

The principal directions come from the n × n Gram matrix in fp64 (n ≪ the dimension),
accumulated over blocks of coordinates so the observations stay fp32 and no fp64 copy
of them is made. Each component's sign is fixed (largest training score positive) so a
fit does not depend on the eigensolver's sign choice.

Devices: both run on "cpu" and "cuda" (`to`): the Gram matrix, the eigendecomposition and the
basis are computed on the generator's device and the fitted tensors live there. PCA-A's
tables stay on the host (read one at a time, they can outgrow a GPU) and go to the device a
block of cells at a time; its medians select values, so its reference is the same on any
device. Sampling draws its coefficients from a CPU generator (the same numbers on every
device); a table is combined on the device and unmapped on the CPU.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from brdfbench import logrel, merl
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import Generator, ResourceError, SampleSet, TrainingData, WeightSet, available_memory
from brdfbench.protocols.generator_state import check_layout, check_tensor, read_layout, weight_layout
from brdfbench_representations.pca import values_on_domain

from .samples import TableSamples, WeightSamples

log = logging.getLogger(__name__)

#: Share of the available memory a fit may plan to use (the fit is a cell's one big job).
FIT_MEMORY_SHARE = 0.8
#: Bytes a fit needs besides its arrays: one table being read and mapped, the cached grid.
FIT_OVERHEAD = 600 << 20
#: Components whose variance is below this share of the largest are numerically zero.
RANK_TOLERANCE = 1e-10
#: Sampled log-relative values are clamped to ±this, so exp() stays finite (a safety net:
#: training values lie within about ±20).
MAX_MAPPED = 40.0
#: Target size of one fp64 block of observations in the chunked products.
_BLOCK_BYTES = 64 << 20


# --------------------------------------------------------------------------- parameters


def positive_int(owner: str, key: str, value: Any, *, optional: bool = False) -> int | None:
    """`value` as a positive int (None allowed when optional), else a ConfigError naming the key."""
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        what = "a positive integer or null" if optional else "a positive integer"
        raise ConfigError(f"{owner}: {key}={value!r} must be {what}")
    return int(value)


def size(n: float) -> str:
    """Bytes in human units (GiB, MiB)."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"


def check_fit_memory(owner: str, need: int, lower: str) -> None:
    """Refuse a fit whose planned peak exceeds FIT_MEMORY_SHARE of the free memory."""
    free = available_memory()
    if need > FIT_MEMORY_SHARE * free:
        raise ResourceError(
            f"{owner}: the fit needs about {size(need)}, more than {FIT_MEMORY_SHARE:.0%} of the "
            f"{size(free)} this machine has free; lower {lower}"
        )


def select_names(owner: str, data: TrainingData, max_materials: int | None, seed: int) -> tuple[str, ...]:
    """The training names, or a seeded subsample of max_materials of them (in the split's order)."""
    names = tuple(data.names)
    if len(names) < 2:
        raise ConfigError(f"{owner}: needs at least 2 training materials (a principal component needs 2), "
                          f"got {len(names)}")
    if max_materials is None or max_materials >= len(names):
        return names
    if max_materials < 2:
        raise ConfigError(f"{owner}: max_materials={max_materials} must be at least 2")
    keep = torch.randperm(len(names), generator=torch.Generator().manual_seed(seed))[:max_materials]
    return tuple(names[i] for i in sorted(keep.tolist()))


def block_columns(n_rows: int, n_cols: int) -> list[slice]:
    """Column blocks whose fp64 copy of n_rows rows takes about _BLOCK_BYTES."""
    width = max(1024, _BLOCK_BYTES // (8 * max(1, n_rows)))
    return [slice(i, min(i + width, n_cols)) for i in range(0, n_cols, width)]


# --------------------------------------------------------------------------- the decomposition


def gram_pca(x: torch.Tensor, k: int, owner: str = "pca",
             device: torch.device | str | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, float]:
    """Principal directions of centred observations x (n, D) through their Gram matrix.

    Returns (eigenvalues (k',) fp64 descending, scores (n, k') fp64, basis (D, k') with
    orthonormal columns in x's dtype, total = trace of the Gram matrix). k' ≤ k drops
    components with a numerically zero eigenvalue. Scores are x @ basis (the training
    coefficients): column j has squared norm eigenvalue j.

    `device` (default: x's) is where the products run and the results live: x may stay
    on the host, each block of columns going to the device as it is needed.
    """
    n, d = x.shape
    device = x.device if device is None else torch.device(device)
    blocks = block_columns(n, d)
    gram = torch.zeros(n, n, dtype=torch.float64, device=device)
    for c in blocks:
        block = x[:, c].to(device).double()
        gram += block @ block.T
    eigvals, eigvecs = logrel.top_eigen(gram, min(k, n))
    keep = int((eigvals > RANK_TOLERANCE * eigvals[0].clamp_min(1e-300)).sum()) if eigvals.numel() else 0
    if keep < min(k, n):
        log.info("%s: %d of %d requested components have a numerically zero variance; keeping %d",
                 owner, min(k, n) - keep, k, keep)
    if keep == 0:
        raise ConfigError(f"{owner}: the training observations are identical: no variance to model")
    eigvals, eigvecs = eigvals[:keep], eigvecs[:, :keep]
    # Fix each sign: the training material with the largest |score| scores positive.
    rows = eigvecs.abs().argmax(dim=0)
    eigvecs = eigvecs * torch.sign(eigvecs[rows, torch.arange(keep, device=device)])
    scale = eigvecs / eigvals.sqrt()
    basis = torch.empty(d, keep, dtype=x.dtype, device=device)
    for c in blocks:
        basis[c] = (x[:, c].to(device).double().T @ scale).to(x.dtype)
    return eigvals, eigvecs * eigvals.sqrt(), basis, float(gram.trace())


def gaussian_coefficients(n: int, std: torch.Tensor, seed: int) -> torch.Tensor:
    """(n, k) fp64 coefficients, column j ~ N(0, std_j²), from a CPU generator seeded by
    `seed` (the same draw on every device), on std's device."""
    g = torch.Generator().manual_seed(int(seed))
    return torch.randn(n, std.numel(), generator=g, dtype=torch.float64).to(std.device) * std.double()


def chunked_combine(basis: torch.Tensor, coefficients: torch.Tensor) -> torch.Tensor:
    """basis (D, k) @ coefficients (k,), a block of rows at a time in the basis dtype; fp64
    (D,) on the basis' device."""
    c = coefficients.to(device=basis.device, dtype=basis.dtype)
    out = torch.empty(basis.shape[0], dtype=torch.float64, device=basis.device)
    for rows in block_columns(basis.shape[1], basis.shape[0]):
        out[rows] = (basis[rows] @ c).double()
    return out


def domain_table(on_domain: torch.Tensor) -> merl.MerlTable:
    """A MERL table from BRDF values (3, P) on the logrel domain; the other cells invalid."""
    cells = logrel.domain()[0].numpy()
    values = np.zeros((3, merl.N_CELLS), dtype=np.float64)
    values[:, cells] = on_domain.numpy()
    valid = np.zeros(merl.N_CELLS, dtype=bool)
    valid[cells] = True
    return merl.MerlTable.from_values(values.reshape(3, *merl.SHAPE), valid.reshape(merl.SHAPE))


def check_components(owner: str, tensors: dict, k_max: int, name: str = "std") -> int:
    """The number of components a saved model holds (from tensor `name`), at most k_max."""
    if name not in tensors:
        raise ModelFileError(f"{owner}: the model file lacks tensor {name!r}")
    k = tensors[name].shape[0] if tensors[name].ndim == 1 else -1
    if not 1 <= k <= k_max:
        raise ModelFileError(f"{owner}: tensor {name!r} has shape {tuple(tensors[name].shape)}: expected "
                             f"(k,) with 1 ≤ k ≤ {k_max} (params k)")
    return k


# --------------------------------------------------------------------------- PCA-A




def _median_reference(x: torch.Tensor, valid: torch.Tensor, device: torch.device | None = None) -> torch.Tensor:
    """(3, P) fp32 on the CPU: per cell and channel, the median of the materials' valid values
    (0 where none is valid).

    Block by block of cells, so the masked copy that nanmedian sorts stays small; each block
    is sorted on `device` (default: x's). A median selects one of the values (the lower
    middle one), so the result is the same on every device.
    """
    n, _, p = x.shape
    device = x.device if device is None else device
    reference = torch.empty(3, p, dtype=torch.float32)
    for c in block_columns(3 * n, p):
        block = torch.where(valid[:, None, c].to(device), x[:, :, c].to(device), float("nan"))
        reference[:, c] = torch.nanmedian(block, dim=0).values.cpu()
    return torch.nan_to_num(reference, nan=0.0).clamp_min(0.0)


class PCABRDF(Generator):
    """PCA-A: Gaussian in the principal space of log-relative MERL tables (see the module docstring)."""

    learns_from = "tables"
    NAME = "pca_brdf"
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, k: int = 300, max_materials: int | None = None):
        k = positive_int(self.NAME, "k", k)
        max_materials = positive_int(self.NAME, "max_materials", max_materials, optional=True)
        super().__init__(k=k, max_materials=max_materials)
        self.reference: torch.Tensor | None = None  # (3, P) fp32
        self.mean: torch.Tensor | None = None  # (3P,) fp32
        self.basis: torch.Tensor | None = None  # (3P, k) fp32, orthonormal columns
        self.std: torch.Tensor | None = None  # (k,) fp64: each component's training standard deviation
        self.info: dict[str, Any] = {}

    # -- memory --------------------------------------------------------------
    @staticmethod
    def fit_nbytes(n: int, k: int) -> int:
        """Planned peak bytes of a fit on n materials with k components."""
        p = logrel.domain()[0].numel()
        observations = n * 3 * p * 4 + n * p  # fp32 values, validity
        basis = 3 * p * k * 4
        gram = n * n * 8 * 3 + 2 * _BLOCK_BYTES  # Gram, eigenvectors, fp64 blocks
        return observations + basis + gram + 2 * 3 * p * 4 + FIT_OVERHEAD

    # -- fit -----------------------------------------------------------------
    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "PCABRDF":
        start = time.perf_counter()
        names = select_names(self.NAME, data, self.params["max_materials"], seed)
        n = len(names)
        k = min(self.params["k"], n - 1)
        if k < self.params["k"]:
            log.info("%s: k=%d capped at n - 1 = %d (%d training materials, mean removed)",
                     self.NAME, self.params["k"], k, n)
        need = self.fit_nbytes(n, k)
        check_fit_memory(self.NAME, need, f"max_materials (now {self.params['max_materials']}, {n} used) or k")
        x, valid = self._load(data, names, progress)
        read_seconds = time.perf_counter() - start
        # The tables stay on the host (they are read one at a time and can outgrow a GPU); the
        # medians, the Gram matrix and the basis are computed on self.device, block by block,
        # and the fitted tensors live there. The medians and the mapping are the same on any
        # device; the products differ in the last bits between devices.
        device = self.device
        reference = _median_reference(x, valid, device)
        self._map_in_place(x, valid, reference)
        del valid
        x = x.reshape(n, -1)
        mean = x.mean(dim=0)
        x -= mean
        eigvals, _, basis, total = gram_pca(x, k, self.NAME, device=device)
        del x
        self.reference, self.mean, self.basis = reference.to(device), mean.to(device), basis
        self.std = (eigvals / (n - 1)).sqrt()
        self.info = {
            "n_materials": n, "k": int(eigvals.numel()),
            "explained_variance": (eigvals / total).tolist(),
            "fit_seconds": time.perf_counter() - start, "read_seconds": read_seconds, "planned_peak_bytes": need,
            "training_materials": list(names),
        }
        return self

    def _load(self, data: TrainingData, names: tuple[str, ...], progress) -> tuple[torch.Tensor, torch.Tensor]:
        """(n, 3, P) fp32 values and (n, P) validity of the materials on the logrel domain."""
        p = logrel.domain()[0].numel()
        x = torch.empty(len(names), 3, p, dtype=torch.float32)
        valid = torch.empty(len(names), p, dtype=torch.bool)
        label = progress if isinstance(progress, str) else f"{self.NAME} read"
        for i, name in enumerate(tqdm(names, desc=label, unit="table", disable=not progress, leave=False)):
            values, ok = values_on_domain(data.load(name))
            x[i], valid[i] = values, ok
        return x, valid

    @staticmethod
    def _map_in_place(x: torch.Tensor, valid: torch.Tensor, reference: torch.Tensor) -> None:
        """Each material's values → log-relative to the reference; invalid cells at x = 0."""
        _, w = logrel.domain()
        ref = reference.double()
        for i in range(x.shape[0]):
            mapped = logrel.to_mapped(x[i].double(), ref, w)
            x[i] = torch.where(valid[i], mapped, 0.0).float()

    # -- sampling ------------------------------------------------------------
    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        return TableSamples(gaussian_coefficients(n, self.std, seed), self.to_table, name=self.NAME)

    def _move(self, device: torch.device) -> None:
        if self.basis is not None:
            for key in ("reference", "mean", "basis", "std"):
                setattr(self, key, getattr(self, key).to(device))

    def to_table(self, coefficients: torch.Tensor) -> merl.MerlTable:
        """The full MERL table of one coefficient vector (k,); cells below the horizon invalid.
        Combined where the basis lives, unmapped on the CPU."""
        _, w = logrel.domain()
        mapped = (self.mean.double() + chunked_combine(self.basis, coefficients)).clamp(-MAX_MAPPED, MAX_MAPPED)
        return domain_table(logrel.from_mapped(mapped.view(3, -1).cpu(), self.reference.double().cpu(), w))

    def sample_nbytes(self, n: int) -> int:
        k = self.params["k"] if self.std is None else self.std.numel()
        p = logrel.domain()[0].numel()
        per_table = 3 * p * 8 * 3 + 3 * merl.N_CELLS * 8 * 4  # mapped and unmapped; values, raw, lookups
        return 2 * n * k * 8 + per_table  # coefficients and the normal draw; one table built at a time

    # -- persistence ---------------------------------------------------------
    def state_dict(self) -> dict[str, torch.Tensor]:
        if self.basis is None:
            return {}
        return {"reference": self.reference, "mean": self.mean, "basis": self.basis, "std": self.std}

    def metadata(self) -> dict[str, Any]:
        return dict(self.info)

    @classmethod
    def from_state(cls, params, tensors, metadata) -> "PCABRDF":
        model = cls(**params)
        if not tensors:
            return model
        owner = f"{cls.NAME} model"
        p = logrel.domain()[0].numel()
        k = check_components(owner, tensors, model.params["k"])
        model.std = check_tensor(owner, tensors, "std", (k,), torch.float64, nonnegative=True)
        model.reference = check_tensor(owner, tensors, "reference", (3, p), torch.float32, nonnegative=True)
        model.mean = check_tensor(owner, tensors, "mean", (3 * p,), torch.float32)
        model.basis = check_tensor(owner, tensors, "basis", (3 * p, k), torch.float32)
        model.info = dict(metadata)
        return model


# --------------------------------------------------------------------------- PCA-N


def training_vectors(owner: str, expected: dict[str, Any] | None, data: TrainingData) -> WeightSet:
    """The split's weight vectors, in the layout a fitted or loaded model holds and at least
    two of them (a principal direction, or a held-out loss, needs two)."""
    ws = data.weights()
    check_layout(owner, expected, ws)
    if ws.vectors.shape[0] < 2:
        raise ConfigError(f"{owner}: needs at least 2 training weight vectors, got {ws.vectors.shape[0]}")
    return ws


def weight_samples(array: torch.Tensor, layout: dict[str, Any]) -> WeightSamples:
    return WeightSamples(array, hidden=layout["hidden"], features=layout["features"], raw_units=layout["raw_units"])


class PCANBRDF(Generator):
    """PCA-N: Gaussian in the principal space of aligned NBRDF weight vectors."""

    learns_from = "nbrdf"
    NAME = "pca_nbrdf"
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, k: int = 100):
        super().__init__(k=positive_int(self.NAME, "k", k))
        self.mean: torch.Tensor | None = None  # (W,) fp64
        self.basis: torch.Tensor | None = None  # (W, k) fp64, orthonormal columns
        self.std: torch.Tensor | None = None  # (k,) fp64
        self.layout: dict[str, Any] | None = None
        self.info: dict[str, Any] = {}

    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "PCANBRDF":
        start = time.perf_counter()
        ws = training_vectors(self.NAME, self.layout, data)
        n, width = ws.vectors.shape
        k = min(self.params["k"], n - 1, width)
        if k < self.params["k"]:
            log.info("%s: k=%d capped at %d (%d training vectors, mean removed; %d weights each)",
                     self.NAME, self.params["k"], k, n, width)
        x = torch.from_numpy(np.ascontiguousarray(ws.vectors)).double().to(self.device)
        if bool((x == x[0]).all()):
            raise ConfigError(f"{self.NAME}: the {n} training weight vectors are identical: no variance to model")
        mean = x.mean(dim=0)
        eigvals, _, basis, total = gram_pca(x - mean, k, self.NAME)
        self.mean, self.basis, self.std = mean, basis, (eigvals / (n - 1)).sqrt()
        self.layout = weight_layout(ws)
        self.info = {"n_materials": n, "k": int(eigvals.numel()), "explained_variance": (eigvals / total).tolist(),
                     "fit_seconds": time.perf_counter() - start}
        return self

    def _move(self, device: torch.device) -> None:
        if self.basis is not None:
            self.mean, self.basis, self.std = self.mean.to(device), self.basis.to(device), self.std.to(device)

    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        c = gaussian_coefficients(n, self.std, seed)
        return weight_samples((self.mean + c @ self.basis.T).float(), self.layout)

    def sample_nbytes(self, n: int) -> int:
        width = 675 if self.mean is None else self.mean.numel()
        k = self.params["k"] if self.std is None else self.std.numel()
        return n * (2 * k * 8 + width * (8 + 8 + 4))  # draw, coefficients, fp64 vectors, fp32 array

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {} if self.basis is None else {"mean": self.mean, "basis": self.basis, "std": self.std}

    def metadata(self) -> dict[str, Any]:
        return {**self.info, "layout": self.layout}

    @classmethod
    def from_state(cls, params, tensors, metadata) -> "PCANBRDF":
        model = cls(**params)
        if not tensors:
            return model
        owner = f"{cls.NAME} model"
        layout = read_layout(owner, metadata.get("layout"))
        w = layout["width"]
        k = check_components(owner, tensors, min(model.params["k"], w))
        model.std = check_tensor(owner, tensors, "std", (k,), torch.float64, nonnegative=True)
        model.mean = check_tensor(owner, tensors, "mean", (w,), torch.float64)
        model.basis = check_tensor(owner, tensors, "basis", (w, k), torch.float64)
        model.layout = layout
        model.info = {key: v for key, v in metadata.items() if key != "layout"}
        return model

