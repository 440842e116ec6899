"""PCA of tabulated BRDFs after Nielsen, Jensen and Ramamoorthi (2015).

Each training material's MERL values are mapped log-relative to a reference BRDF (the
per-cell, per-channel median of the training set), cosine-weighted:

    x = ln((ρ·w + ε) / (ρ_ref·w + ε)),  w = cosθi·cosθo,  ε = 1e-3,

over the cells where both directions are above the horizon. As in Nielsen et al., each
colour channel is one observation, so n training materials give 3n vectors; the basis is
the top-k principal directions of those (mean removed), computed from their Gram matrix.
A material is represented by 3·k coefficients (k per channel) plus the shared basis,
mean and reference. `fit` projects a material by least squares on its valid cells, and
evaluation looks up the reconstructed table (nearest cell, as the reference reader).

On a GPU (`to(device)`) training (the median reference, the mapping, the Gram matrix and
the basis) and the projection run there; the eigendecomposition of the small n × n Gram
matrix and the reconstructed table stay on the host, and so does evaluation, which is the
reference reader's lookup (values returned on the inputs' device).
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import torch

from brdfbench import logrel, merl
from brdfbench.errors import ConfigError, DataError
from brdfbench.protocols.representation import Material, Representation
from brdfbench.state_checks import expect_tensor

from .merl import NEAREST_FLOPS

EPSILON = logrel.EPSILON
DEFAULT_MAX_K = 300  # Nielsen et al. (2015) and Hu 2026 keep 300 components
_CHUNK = 1 << 17


_domain = logrel.domain


def values_on_domain(material: Material) -> tuple[torch.Tensor, torch.Tensor]:
    """(3, P) float64 values and (P,) validity of a material on the PCA domain."""
    cells, _ = _domain()
    values = torch.from_numpy(material.table.values.reshape(3, -1))[:, cells]
    if not torch.isfinite(values).all():
        raise DataError(f"material {material.name!r}: non-finite values")
    valid = torch.from_numpy(material.table.valid.reshape(-1))[cells]
    if not valid.any():
        raise DataError(f"material {material.name!r}: every cell is invalid, nothing to fit")
    return values, valid


def _weights(device: torch.device) -> torch.Tensor:
    """The domain's w = cosθi·cosθo on `device` (kept per device)."""
    w = _domain()[1]
    if device.type == "cpu":
        return w
    if device not in _WEIGHTS:
        _WEIGHTS[device] = w.to(device)
    return _WEIGHTS[device]


_WEIGHTS: dict[torch.device, torch.Tensor] = {}


def _chunked_project(centred: torch.Tensor, basis: torch.Tensor) -> torch.Tensor:
    """centred (3, P) fp64 @ basis (P, k) fp32, block by block in fp32, summed in fp64.

    Avoids an fp64 copy of the basis (P·k·8 bytes: 2 GB at k = 224).
    """
    out = torch.zeros(centred.shape[0], basis.shape[1], dtype=torch.float64, device=basis.device)
    for i in range(0, basis.shape[0], _CHUNK):
        out += (centred[:, i : i + _CHUNK].float() @ basis[i : i + _CHUNK]).double()
    return out


def _chunked_reconstruct(coefficients: torch.Tensor, basis: torch.Tensor) -> torch.Tensor:
    """coefficients (3, k) @ basis.T, block by block of cells, in fp32; returns fp64 (3, P)."""
    c = coefficients.float()
    return torch.cat([c @ basis[i : i + _CHUNK].T for i in range(0, basis.shape[0], _CHUNK)], dim=1).double()


class PCA(Representation):
    tags = frozenset({"isotropic", "reciprocal", "fittable", "tabulated", "needs_training"})
    needs_training = True
    devices = frozenset({"cpu", "cuda"})

    def __init__(self, k: int | None = None):
        if k is not None and (not isinstance(k, int) or k < 1):
            raise ConfigError(f"pca: k must be a positive integer or null, got {k!r}")
        super().__init__(k=k)
        self.reference: torch.Tensor | None = None  # (3, P) float32
        self.mean: torch.Tensor | None = None  # (P,) float32
        self.basis: torch.Tensor | None = None  # (P, k) float32, orthonormal columns
        self.coefficients: torch.Tensor | None = None  # (3, k) float64
        self._table: merl.MerlTable | None = None

    # -- shared state ---------------------------------------------------------
    def _map(self, values: torch.Tensor) -> torch.Tensor:
        return logrel.to_mapped(values, self.reference.double(), _weights(values.device))

    def _unmap(self, mapped: torch.Tensor) -> torch.Tensor:
        return logrel.from_mapped(mapped, self.reference.double(), _weights(mapped.device))

    def _move(self, device: torch.device) -> None:
        for name in ("reference", "mean", "basis", "coefficients"):
            value = getattr(self, name)
            if value is not None:  # an unfitted model holds nothing (and initialises no device)
                setattr(self, name, value.to(device))

    def train(self, materials: Iterable[Material], *, seed: int = 0) -> "PCA":
        columns, valid_masks, names = [], [], []
        for material in materials:
            values, valid = values_on_domain(material)
            columns.append(values.float())
            valid_masks.append(valid)
            names.append(material.name)
        if len(columns) < 2:
            raise ConfigError(f"pca: needs at least 2 training materials, got {len(columns)}")
        device = self.device
        stacked = torch.stack(columns).to(device)  # (n, 3, P) float32
        valid = torch.stack(valid_masks).to(device)  # (n, P)
        # Reference: per-cell, per-channel median over the training materials' valid values.
        masked = torch.where(valid[:, None, :], stacked, torch.full_like(stacked, float("nan")))
        reference = torch.nanmedian(masked, dim=0).values
        self.reference = torch.nan_to_num(reference, nan=0.0).clamp_min(0.0)
        del masked
        # Observations: one per (material, channel), mapped in place; invalid cells sit at the reference (x = 0).
        for i in range(stacked.shape[0]):
            stacked[i] = torch.where(valid[i], self._map(stacked[i].double()), 0.0).float()
        x = stacked.reshape(-1, stacked.shape[-1])
        self.mean = x.mean(dim=0)
        x -= self.mean
        rank = x.shape[0] - 1
        k = self.params["k"]
        if k is not None and k > rank:
            raise ConfigError(
                f"pca: k={k} is larger than the {rank} components that {len(names)} training materials "
                f"({x.shape[0]} channel vectors, mean removed) can give; lower representation.params.k"
            )
        k = min(DEFAULT_MAX_K, rank) if k is None else k
        # Gram matrix and basis in fp64, a block of cells at a time (x itself stays fp32).
        chunks = [slice(i, i + _CHUNK) for i in range(0, x.shape[1], _CHUNK)]
        gram = torch.zeros(x.shape[0], x.shape[0], dtype=torch.float64, device=device)
        for c in chunks:
            block = x[:, c].double()
            gram += block @ block.T
        eigvals, eigvecs = logrel.top_eigen(gram.cpu(), k)  # n × n: on the host, as LAPACK orders it
        scale = (eigvecs / eigvals.clamp_min(1e-30).sqrt()).to(device)
        self.basis = torch.empty(x.shape[1], k, dtype=torch.float32, device=device)  # (P, k), orthonormal columns
        for c in chunks:
            self.basis[c] = (x[:, c].double().T @ scale).float()
        self.coefficients, self._table = None, None
        return self

    # -- per material ---------------------------------------------------------
    def fit(self, target: Material, *, seed: int = 0) -> "PCA":
        if self.basis is None:
            raise RuntimeError("pca: train() on a split of materials before fit()")
        values, valid = (t.to(self.device) for t in values_on_domain(target))
        centred = torch.where(valid, self._map(values) - self.mean.double(), 0.0)  # (3, P); invalid cells drop out
        rhs = _chunked_project(centred, self.basis)  # (3, k) = centred @ basis over valid cells
        invalid = ~valid
        if invalid.any():  # least squares on the valid cells: B_v'B_v = I - B_inv'B_inv
            b_inv = self.basis[invalid].double()
            gram = torch.eye(self.basis.shape[1], dtype=torch.float64, device=b_inv.device) - b_inv.T @ b_inv
            # Symmetric positive definite while the valid cells determine the coefficients; a
            # Cholesky solve is also deterministic, where LAPACK's threaded lstsq is not.
            factor, info = torch.linalg.cholesky_ex(gram)
            if info:
                raise DataError(f"material {target.name!r}: too few valid cells to determine {self.basis.shape[1]} PCA coefficients")
            self.coefficients = torch.cholesky_solve(rhs.T, factor).T
        else:
            self.coefficients = rhs
        self._table = None
        _ = self.table  # reconstruct now, so fit time covers all the work evaluation depends on
        return self

    @property
    def table(self) -> merl.MerlTable:
        """The reconstructed MERL table (built once per fit)."""
        if self._table is None:
            if self.coefficients is None:
                raise RuntimeError("pca: evaluate after fit() or load")
            cells, _ = _domain()
            mapped = self.mean.double() + _chunked_reconstruct(self.coefficients, self.basis)  # (3, P)
            values = np.full((3, merl.N_CELLS), merl.INVALID_RAW, dtype=np.float64)
            values[:, cells.numpy()] = self._unmap(mapped).cpu().numpy()
            valid = np.zeros(merl.N_CELLS, dtype=bool)
            valid[cells.numpy()] = True
            self._table = merl.MerlTable.from_values(values.reshape(3, *merl.SHAPE), valid.reshape(merl.SHAPE))
        return self._table

    def _eval(self, wi, wo):
        if wi.device.type != "cpu":  # the reference reader's lookup runs on the host
            return self.table.lookup(wi.cpu(), wo.cpu(), "nearest").clamp_min(0.0).to(wi.device)
        return self.table.lookup(wi, wo, "nearest").clamp_min(0.0)

    # -- persistence and cost -------------------------------------------------
    def state_dict(self):
        state = {}
        for name in ("reference", "mean", "basis", "coefficients"):
            value = getattr(self, name)
            if value is not None:
                state[name] = value
        return state

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        cells, _ = _domain()
        p = cells.numel()
        owner = "pca model"
        got = {name: expect_tensor(tensors, name, shape, owner=owner, required=False)
               for name, shape in (("reference", (3, p)), ("mean", (p,)), ("basis", (p, None)))}
        k = None if got["basis"] is None else got["basis"].shape[1]
        got["coefficients"] = expect_tensor(tensors, "coefficients", (3, k), owner=owner, required=False)
        model.reference, model.mean, model.basis, model.coefficients = (
            got["reference"], got["mean"], got["basis"], got["coefficients"])
        return model

    @property
    def nbytes(self) -> int:
        c = self.coefficients
        return 0 if c is None else c.numel() * c.element_size()

    @property
    def shared_nbytes(self) -> int:
        return sum(t.numel() * t.element_size() for t in (self.reference, self.mean, self.basis) if t is not None)

    @property
    def flops_per_eval(self) -> int:
        return NEAREST_FLOPS  # a nearest-cell lookup of the table reconstructed at fit time

    def drjit_kernel(self):
        """The reconstructed table's lookup in drjit operations, for this exact class only (a subclass may change
        `_eval`); drjit is imported here, not with the representation."""
        if type(self) is not PCA:
            return None
        from .drjit_kernels import pca_kernel  # lazy: drjit

        return pca_kernel(self)
