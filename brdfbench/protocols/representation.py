"""The BRDF representation protocol every representation plugin implements.

A representation evaluates RGB BRDF values (N, 3), not cosine-weighted, in MERL units
(1/sr), on unit direction pairs (N, 3) in the local shading frame (z = normal): ωi points
toward the light, ωo toward the viewer (MERL's θin / θout), both away from the surface. Pairs
with either direction at or below the horizon evaluate to 0. The output dtype follows
the input dtype (fp32 or fp64), and its device the inputs' device.

Devices: a representation runs on the CPU unless its class lists another device type in
`devices` and is moved there with `to(device)` (see `brdfbench.device.Placed`): then it
fits there and evaluates inputs that live there.

State for saving is a flat dict of tensors plus a JSON-able dict of metadata, so that
`brdfbench.modelio` can store it as safetensors and loading never runs code.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Iterable, Sequence

import torch

from ..coords import above_horizon
from ..device import Placed
from ..merl import MerlTable


@dataclass(frozen=True)
class Material:
    """A measured target material: a MERL-format table plus its identity."""

    name: str
    table: MerlTable
    category: str = "unknown"
    source: str = ""


FIT_LOSS_KEY = "fit_loss"


class Representation(Placed, ABC):
    """Base class for BRDF representations.

    Subclasses implement `_eval` (directions already known to be above the horizon),
    `fit`, `state_dict`/`from_state`, and `nbytes`. `params` are the constructor keyword
    arguments, recorded with saved models and results.
    """

    #: Capability tags the conformance kit reads (see brdfbench.testing).
    tags: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, **params: Any):
        self.params = dict(params)

    # -- evaluation --------------------------------------------------------------
    def eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """BRDF values (N, 3) at direction pairs; 0 where either direction is below the horizon."""
        if wi.ndim != 2 or wi.shape[-1] != 3 or wi.shape != wo.shape:
            raise ValueError(f"eval expects two (N, 3) tensors, got {tuple(wi.shape)} and {tuple(wo.shape)}")
        if wi.dtype != wo.dtype or not wi.dtype.is_floating_point:
            raise ValueError(f"eval expects matching floating dtypes, got {wi.dtype} and {wo.dtype}")
        mask = above_horizon(wi, wo)
        if bool(mask.all()):  # the common case: no masked copies
            return self._eval(wi, wo).to(wi.dtype)
        out = torch.zeros(wi.shape[0], 3, dtype=wi.dtype, device=wi.device)
        if mask.any():
            out[mask] = self._eval(wi[mask], wo[mask]).to(wi.dtype)
        return out

    @abstractmethod
    def _eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """Values at pairs that are both above the horizon."""

    # -- fitting -----------------------------------------------------------------
    @abstractmethod
    def fit(self, target: Material, *, seed: int = 0) -> "Representation":
        """Fit to a measured material; returns self."""

    # -- fitting many materials at once --------------------------------------------
    #: True where `fit` runs on one thread (or holds the GIL) and the class and its params
    #: pickle: the runner may then fit several materials side by side, one per process
    #: (run control `fit_workers`), each from `torch.manual_seed(seed)`: the same models.
    fits_in_parallel: ClassVar[bool] = False

    @property
    def fit_batch_size(self) -> int:
        """How many materials the runner passes to one `fit_many` call (1: one at a time)."""
        return 1

    def fit_many(self, targets: Sequence[Material], *, seed: int = 0, progress: bool | str = False) -> list["Representation"]:
        """One fitted model per target, in order; representations that fit several materials
        faster together (stacked networks) override this. `self` is left unfitted; the
        models fit on `self.device`."""
        return [self._unfitted().fit(t, seed=seed) for t in targets]

    def _unfitted(self) -> "Representation":
        """A new unfitted model with these params, on this model's device."""
        model = type(self)(**self.params)
        return model if self.device.type == "cpu" else model.to(self.device)

    # -- training (representations with state shared across materials) ------------
    #: True for representations that learn shared state (e.g. a PCA basis) from a
    #: training split before `fit` projects one material onto it. The runner then
    #: cross-validates: each material is fitted by a model trained without it.
    needs_training: ClassVar[bool] = False

    def train(self, materials: Iterable[Material], *, seed: int = 0) -> "Representation":
        """Learn the shared state from training materials (consumed one at a time); returns self."""
        raise NotImplementedError(f"{type(self).__name__} does not train on a split")

    def preflight(self) -> None:
        """Check what the parameters name outside this process (a file to start from) before
        any work, so a sweep's validation finds it; raise a BrdfbenchError naming the key."""

    # -- persistence -------------------------------------------------------------
    @abstractmethod
    def state_dict(self) -> dict[str, torch.Tensor]:
        """Every tensor needed to rebuild the fitted model."""

    def metadata(self) -> dict[str, Any]:
        """JSON-able extras saved beside the tensors (params are saved separately).

        A number under FIT_LOSS_KEY is the final value of the model's own fitting objective;
        the runner records it as the metric `fit_loss`.
        """
        return {}

    @classmethod
    @abstractmethod
    def from_state(cls, params: dict[str, Any], tensors: dict[str, torch.Tensor], metadata: dict[str, Any]) -> "Representation":
        """Rebuild a fitted model from `state_dict()` and `metadata()`."""

    # -- cost --------------------------------------------------------------------
    @property
    def nbytes(self) -> int:
        """Bytes of one fitted material's parameters (shared state excluded, see shared_nbytes)."""
        return sum(t.numel() * t.element_size() for t in self.state_dict().values())

    @property
    def shared_nbytes(self) -> int:
        """Bytes shared by every material (e.g. a PCA basis); not included in `nbytes`."""
        return 0

    @property
    def flops_per_eval(self) -> int | None:
        """Floating-point operations per (ωi, ωo) evaluation, where known."""
        return None
