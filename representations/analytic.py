"""Analytic BRDF baselines: Cook-Torrance (Hu 2026), GGX with height-correlated Smith,
and normalised Blinn-Phong. Each is f = k_d/π + k_s ⊙ lobe(ωi, ωo), RGB k_d and k_s.

These are the baselines every neural model is measured against, so their terms
(`analytic_terms.py`) stay accurate and finite in fp32 as well as fp64, down to GGX
α = 1e-3 and Blinn-Phong exponents up to 1e6; outputs are clamped to [0, finfo.max].
The same torch code serves `_eval` (in the input dtype) and the fit (float64 with
autograd, `fitting.py`); the drjit kernels (`drjit_kernels.py`) are its twins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import torch

from brdfbench import reused
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.representation import Material, Representation
from brdfbench.state_checks import expect_tensor

from .fit_losses import DEFAULT_LOSS, FIT_LOSSES
from .analytic_terms import (ALPHA_MIN, Geometry, blinn_phong_lobe, geometry, ggx_ndf, ior_to_f0, schlick_fresnel,
                             schlick_g_over_4cc, smith_g2_over_4cc)

Tensor = torch.Tensor

TAGS = frozenset({"isotropic", "reciprocal", "fittable", "analytic"})
INV_PI = 1.0 / math.pi


# --------------------------------------------------------------------------- the models


@dataclass(frozen=True)
class Coefficient:
    """One fitted coefficient: its size, default, fit bounds, and whether it is fitted in log space."""

    name: str
    size: int
    default: float
    lower: float
    upper: float
    log: bool = False


_KD = Coefficient("kd", 3, 0.5, 0.0, 2.0)
_KS = Coefficient("ks", 3, 1.0, 1e-8, 1e3, log=True)


def _check_int(model: str, name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ConfigError(f"{model}: {name} must be an integer >= {lo}, got {value!r}")
    return value


class AnalyticBRDF(Representation):
    """f = k_d/π + k_s ⊙ lobe; subclasses define COEFFS (after kd, ks), `lobe` and `init_shape`.

    Constructor params only steer the fit: `n_samples` valid MERL cells (or direction
    pairs) drawn (seeded) to fit on, `restarts` roughness initialisations (at most 8
    distinct ones; the best fit is kept), and `loss`, the fitting objective (`fitting.py`:
    the benchmark's L1-log-cos by default, or the metric a published fit was made with). The fitted coefficients live in `coeffs` (float64 tensors, also readable
    as attributes: `model.kd`, `model.alpha`, ...); after a fit `fit_loss` is the true
    L1-log-cos on the fit subsample and `fit_info` the rest of `metadata()`.
    """

    tags: ClassVar[frozenset[str]] = TAGS
    #: the fit runs on one torch thread with scipy's L-BFGS loop holding the GIL: the runner
    #: fits several materials side by side, one per process
    fits_in_parallel: ClassVar[bool] = True
    #: evaluates on a GPU; the fit (bounded L-BFGS-B through scipy on 2^15 cells) runs on the
    #: CPU wherever the model is, and its coefficients then move to the model's device
    devices = frozenset({"cpu", "cuda"})
    NAME: ClassVar[str] = "analytic"
    COEFFS: ClassVar[tuple[Coefficient, ...]] = (_KD, _KS)
    FLOPS: ClassVar[int] = 0

    def __init__(self, n_samples: int = 32768, restarts: int = 4, loss: str = DEFAULT_LOSS):
        _check_int(self.NAME, "n_samples", n_samples, 16)
        _check_int(self.NAME, "restarts", restarts, 1)
        if loss not in FIT_LOSSES:
            raise ConfigError(f"{self.NAME}: loss must be one of {', '.join(FIT_LOSSES)}, got {loss!r}")
        # the default loss is left out of params, so configurations written before the key stay the same
        super().__init__(n_samples=n_samples, restarts=restarts, **({} if loss == DEFAULT_LOSS else {"loss": loss}))
        self.n_samples = n_samples
        self.restarts = restarts
        self.loss = loss
        self.coeffs: dict[str, Tensor] = {c.name: torch.full((c.size,), c.default, dtype=torch.float64) for c in self.COEFFS}
        self.fit_loss: float | None = None
        self.fit_info: dict[str, Any] = {}

    # -- coefficients ----------------------------------------------------------------
    def set_coefficients(self, **values: Any) -> "AnalyticBRDF":
        """Set coefficients by name (scalars broadcast to RGB where the size is 3); returns self."""
        sizes = {c.name: c.size for c in self.COEFFS}
        for name, value in values.items():
            if name not in sizes:
                raise ConfigError(f"{self.NAME}: unknown coefficient {name!r}; expected one of {', '.join(sizes)}")
            t = torch.as_tensor(value, dtype=torch.float64).reshape(-1)
            if t.numel() == 1:
                t = t.expand(sizes[name])
            if t.numel() != sizes[name] or not bool(torch.isfinite(t).all()):
                raise ConfigError(f"{self.NAME}: coefficient {name!r} needs {sizes[name]} finite value(s), got {value!r}")
            self.coeffs[name] = t.clone()
        return self

    def __getattr__(self, name: str) -> Tensor:
        coeffs = self.__dict__.get("coeffs")
        if coeffs is not None and name in coeffs:
            return coeffs[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # -- the model -------------------------------------------------------------------
    @classmethod
    def lobe(cls, g: Geometry, c: dict[str, Tensor]) -> Tensor:
        """Specular lobe for k_s = 1: (N,), or (N, 3) where a shape coefficient is RGB; `c` holds
        the shape coefficients as `shape_of` gives them."""
        raise NotImplementedError

    @classmethod
    def init_shape(cls, alpha: float) -> dict[str, float]:
        """Shape coefficients for an initial GGX-equivalent roughness α (Fresnel at its default)."""
        raise NotImplementedError

    @classmethod
    def shape_of(cls, values: dict[str, Tensor]) -> dict[str, Tensor]:
        """The shape coefficients `lobe` takes: 0-d tensors for scalar ones, (3,) for RGB ones."""
        sizes = {c.name: c.size for c in cls.COEFFS}
        return {k: (v if sizes[k] > 1 else v[0]) for k, v in values.items() if k not in ("kd", "ks")}

    @classmethod
    def combine(cls, kd: Tensor, ks: Tensor, lobe: Tensor) -> Tensor:
        """k_d/π + k_s ⊙ lobe; a lobe is (N,) or, where a shape coefficient is RGB, (N, 3)."""
        return kd * INV_PI + (lobe[:, None] if lobe.dim() == 1 else lobe) * ks

    def _eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        dtype = wi.dtype
        c = {k: v.to(dtype) for k, v in self.coeffs.items()}
        shape = self.shape_of(c)
        out = self.combine(c["kd"], c["ks"], self.lobe(reused.derived(geometry, wi, wo), shape))
        return out.clamp(0.0, torch.finfo(dtype).max)

    def fit(self, target: Material, *, seed: int = 0) -> "AnalyticBRDF":
        from .fitting import fit_analytic  # lazy: scipy; scipy, only when fitting

        result = fit_analytic(self, target, seed=seed)
        self.set_coefficients(**result.coefficients)
        self._move(self.device)
        self.fit_loss = result.loss
        self.fit_info = result.info
        return self

    def _move(self, device) -> None:
        self.coeffs = {k: v.to(device) for k, v in self.coeffs.items()}

    # -- persistence and cost --------------------------------------------------------
    def state_dict(self) -> dict[str, Tensor]:
        return {k: v.clone() for k, v in self.coeffs.items()}

    def metadata(self) -> dict[str, Any]:
        if self.fit_loss is None:
            return {}
        return {"fit_loss": self.fit_loss, **self.fit_info}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        model = cls(**params)
        for c in cls.COEFFS:  # finite, of the coefficient's size, and not below its fit bound's sign
            value = expect_tensor(tensors, c.name, None, owner=f"{cls.NAME} model", nonneg=c.lower >= 0)
            if value.numel() != c.size:
                raise ModelFileError(f"{cls.NAME} model: tensor {c.name!r} has {value.numel()} value(s), expected {c.size}")
            model.coeffs[c.name] = value.double().reshape(c.size).clone()
        if metadata.get("fit_loss") is not None:
            model.fit_loss = float(metadata["fit_loss"])
            model.fit_info = {k: v for k, v in metadata.items() if k != "fit_loss"}
        return model

    @property
    def flops_per_eval(self) -> int:
        return self.FLOPS


# Counting each add, multiply, divide, sqrt, exp or log as one operation, with per-model
# constants (α², F0, k, (n+8)/(8π), k_d/π) hoisted: half vector h = (ωi+ωo)/|ωi+ωo| 12,
# cosθd from the same norm 1, h_z² and sin²θh 4; the RGB combine k_d/π + k_s·lobe 6.
_COMMON_FLOPS = 12 + 1 + 4 + 6


class CookTorrance(AnalyticBRDF):
    """Cook-Torrance as in Hu 2026 (§3.1.1, eqs. 3.1-3.4).

    f = k_d/π + k_s · D·G·F / (4 cosθi cosθo) with
    D = GGX / Trowbridge-Reitz with α = roughness²;
    F = Schlick with F0 = ((IoR − 1)/(IoR + 1))²;
    G = G1(ωi) G1(ωo), separable Schlick-GGX G1(v) = n·v / ((n·v)(1 − k) + k) with
    k = α²/2 exactly as Hu 2026 writes it (its "k_IBL"; note this is roughness⁴/2, much
    smaller than the usual UE4 k = α/2, so G is close to 1 except at grazing).

    Hu 2026 writes the diffuse term as (n·v)/π, a slip: Lambert's is k_d/π, used here.
    Coefficients: kd (RGB), ks (RGB), roughness, ior.
    """

    NAME = "cook_torrance"
    COEFFS = (
        _KD,
        _KS,
        Coefficient("roughness", 1, 0.5, math.sqrt(1e-3), 1.0, log=True),
        Coefficient("ior", 1, 1.5, 1.05, 50.0, log=True),
    )
    # D 5 + Schlick-GGX G/(4cc) 6 + Fresnel 6 + D·G·F 2
    FLOPS = _COMMON_FLOPS + 5 + 6 + 6 + 2

    @classmethod
    def lobe(cls, g, c):
        alpha = (c["roughness"] * c["roughness"]).clamp(min=ALPHA_MIN)
        k = 0.5 * alpha * alpha
        return ggx_ndf(alpha, g) * schlick_g_over_4cc(k, g) * schlick_fresnel(ior_to_f0(c["ior"]), g.cos_d)

    @classmethod
    def init_shape(cls, alpha):
        return {"roughness": math.sqrt(alpha), "ior": 1.5}

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        if type(self) is not CookTorrance:
            return None
        from .drjit_kernels import CookTorranceKernel  # lazy: drjit

        return CookTorranceKernel(self)


class GGX(AnalyticBRDF):
    """Isotropic GGX microfacet model with height-correlated Smith shadowing-masking.

    f = k_d/π + k_s · D_GGX(α) · G2 · F_Schlick(F0) / (4 cosθi cosθo), G2 = 1/(1 + Λ(ωi) + Λ(ωo)),
    Λ = (√(1 + α² tan²θ) − 1)/2 (Heitz 2014). Coefficients: kd (RGB), ks (RGB), alpha, f0.
    """

    NAME = "ggx"
    COEFFS = (
        _KD,
        _KS,
        Coefficient("alpha", 1, 0.3, 1e-3, 1.0, log=True),
        Coefficient("f0", 1, 0.04, 1e-3, 1.0),
    )
    # D 5 + height-correlated Smith G2/(4cc) 14 + Fresnel 6 + D·G·F 2
    FLOPS = _COMMON_FLOPS + 5 + 14 + 6 + 2

    @classmethod
    def lobe(cls, g, c):
        alpha = c["alpha"].clamp(min=ALPHA_MIN)
        return ggx_ndf(alpha, g) * smith_g2_over_4cc(alpha, g) * schlick_fresnel(c["f0"], g.cos_d)

    @classmethod
    def init_shape(cls, alpha):
        return {"alpha": alpha, "f0": 0.04}

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        if type(self) is not GGX:
            return None
        from .drjit_kernels import GGXKernel  # lazy: drjit

        return GGXKernel(self)


class BlinnPhong(AnalyticBRDF):
    """Normalised Blinn-Phong: f = k_d/π + k_s (n + 8)/(8π) cos^n θh.

    (n + 8)/(8π) is the usual energy normalisation (Akenine-Möller et al., Real-Time
    Rendering): at normal incidence the albedo of the lobe is n(n + 8)/((n + 2)(n + 4)),
    within 7 % of 1 for every n and → 1 as n grows. The exponent is fitted as log n.
    Coefficients: kd (RGB), ks (RGB), exponent.
    """

    NAME = "blinn_phong"
    COEFFS = (
        _KD,
        _KS,
        Coefficient("exponent", 1, 50.0, 0.1, 1e6, log=True),
    )
    # log1p 1 + n/2·log 2 + exp 1 + (n+8)/(8π)· 1 + horizon select 1
    FLOPS = _COMMON_FLOPS + 6

    @classmethod
    def lobe(cls, g, c):
        return blinn_phong_lobe(c["exponent"].clamp(min=0.0), g)

    @classmethod
    def init_shape(cls, alpha):
        # Beckmann-equivalent exponent n = 2/α² − 2 (Walter et al. 2007).
        return {"exponent": 2.0 / (alpha * alpha) - 2.0}

    def drjit_kernel(self):
        """The model in drjit operations, for this exact class only (a subclass may change
        `lobe`); drjit is imported here, not with the representation."""
        if type(self) is not BlinnPhong:
            return None
        from .drjit_kernels import BlinnPhongKernel  # lazy: drjit

        return BlinnPhongKernel(self)
