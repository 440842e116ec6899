"""The importance-sampler protocol: draw ωo given ωi, and say with what density.

A sampler is a plugin (group `brdfbench.samplers`, spec `brdfbench.plugins.specs.SamplerSpec`)
built from keyword parameters. `sample(wi, u)` maps uniform variates u ∈ [0, 1)², shape
(N, 2), to directions ωo (N, 3); `pdf(wi, wo)` is the solid-angle density (N,) of ωo
given ωi. Both keep the input dtype (fp32 or fp64), are finite, and pdf is ≥ 0 and exactly
0 where ωi or ωo is at or below the horizon (z ≤ 0). A sampler may return a direction
below the horizon (a microfacet sampler reflecting about a tilted half vector does): it
is a valid sample of density 0, which a caller weights 0. The conformance kit
(`brdfbench.testing.samplers`) checks all of this, and `sample` against `pdf` with a
χ² test.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from torch import Tensor

# torch is imported on first use, not here: entry points name `brdfbench.sampling.specs`,
# and listing plugins must import no heavy code (tests/unit/test_registry.py).
_HELPERS = ("cartesian_to_spherical", "direction", "reflect", "spherical_to_cartesian")

__all__ = ["Sampler", *_HELPERS]


def __getattr__(name: str):
    if name in _HELPERS:
        from . import directions  # lazy: attribute

        return getattr(directions, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class Sampler(ABC):
    """Base class of importance samplers of the outgoing direction.

    Subclasses implement `_sample` (u already clamped into [0, 1)) and `_pdf` (called only
    for pairs both above the horizon). `params` are the constructor keyword arguments.

    Tags the conformance kit reads: `hemisphere` (ωo does not depend on ωi and is always
    above the horizon) and `microfacet` (ωo is ωi reflected about a sampled half vector).
    """

    tags: ClassVar[frozenset[str]] = frozenset()
    #: "module:Class" of a built-in sampler's drjit twin (render/drjit_samplers.py or
    #: drjit_lobe_samplers.py), for the class that declares it only (a subclass may change
    #: `sample` or `pdf`); None: it renders in torch. A third-party sampler overrides
    #: `drjit_sampler` instead.
    DRJIT_TWIN: ClassVar[str | None] = None

    def __init__(self, **params: Any):
        self.params = dict(params)

    @classmethod
    def roughness_params(cls, alpha: float) -> dict[str, float] | None:
        """Constructor parameters that give this sampler a lobe of roughness α, for sweeps
        over roughness; None when it has no roughness parameter."""
        return None

    # -- the protocol ------------------------------------------------------------
    def sample(self, wi: Tensor, u: Tensor) -> Tensor:
        """Directions ωo (N, 3) for incident directions ωi (N, 3) and variates u (N, 2) in [0, 1)²."""
        if wi.ndim != 2 or wi.shape[-1] != 3 or u.ndim != 2 or u.shape[-1] != 2 or u.shape[0] != wi.shape[0]:
            raise ValueError(f"sample expects wi (N, 3) and u (N, 2), got {tuple(wi.shape)} and {tuple(u.shape)}")
        _check_dtypes("sample", wi, u)
        import torch

        below_one = torch.nextafter(torch.ones((), dtype=u.dtype), torch.zeros((), dtype=u.dtype))
        u = u.clamp(min=0.0).minimum(below_one)  # 1 itself is outside [0, 1)
        return self._sample(wi, u).to(wi.dtype)

    def pdf(self, wi: Tensor, wo: Tensor) -> Tensor:
        """Solid-angle density (N,) of ωo given ωi; 0 where either is at or below the horizon."""
        if wi.ndim != 2 or wi.shape[-1] != 3 or wi.shape != wo.shape:
            raise ValueError(f"pdf expects two (N, 3) tensors, got {tuple(wi.shape)} and {tuple(wo.shape)}")
        _check_dtypes("pdf", wi, wo)
        import torch

        from ..coords import above_horizon  # lazy: torch

        mask = above_horizon(wi, wo)
        if bool(mask.all()):
            return self._pdf(wi, wo).to(wi.dtype)
        out = torch.zeros(wi.shape[0], dtype=wi.dtype)
        if mask.any():
            out[mask] = self._pdf(wi[mask], wo[mask]).to(wi.dtype)
        return out

    def drjit_sampler(self):
        """The drjit twin named by DRJIT_TWIN where this exact class declares it, else None
        (render/drjit_samplers.py reads this hook; drjit is imported only here)."""
        twin = type(self).__dict__.get("DRJIT_TWIN")
        if twin is None:
            return None
        # imported by name (not through importlib), so that the import rules see them
        from ..render import drjit_lobe_samplers, drjit_samplers  # lazy: drjit, torch

        module, name = twin.split(":")
        modules = {"drjit_samplers": drjit_samplers, "drjit_lobe_samplers": drjit_lobe_samplers}
        if module not in modules:
            raise ValueError(f"{type(self).__name__}.DRJIT_TWIN={twin!r}: not a module of brdfbench.render's twins "
                             f"({', '.join(modules)})")
        return getattr(modules[module], name)(self)

    @abstractmethod
    def _sample(self, wi: Tensor, u: Tensor) -> Tensor:
        """Directions for u in [0, 1)²."""

    @abstractmethod
    def _pdf(self, wi: Tensor, wo: Tensor) -> Tensor:
        """Densities of pairs both above the horizon."""

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"


def _check_dtypes(what: str, a: Tensor, b: Tensor) -> None:
    if a.dtype != b.dtype or not a.dtype.is_floating_point:
        raise ValueError(f"{what} expects matching floating dtypes, got {a.dtype} and {b.dtype}")
