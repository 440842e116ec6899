"""Lafortune, Foo, Torrance and Greenberg's generalised cosine lobes, "Non-linear
approximation of reflectance functions" (SIGGRAPH 1997), with more than one lobe:

f = k_d/π + k_s ⊙ (L₁ + Σ_{j≥2} w_j ⊙ L_j),

each L_j one isotropic lobe of `ngan_models.Lafortune` (its own C_xy, C_z and exponent,
with Ngan et al.'s normalisation (n + 2)/(2π max(C_xy², C_z²)^(n/2))). The paper sums
lobes with their own RGB albedos ρ_j; here lobe j's is k_s ⊙ w_j, an exact
reparameterisation (ρ₁ = k_s, w_j = ρ_j/ρ₁) that keeps the family's f = k_d/π + k_s ⊙ lobe
form, so the fitter, the kit and the kernels treat it like any analytic model. The paper fitted
measured materials with up to three lobes: `lafortune2` and `lafortune3`. No multi-lobe
fits of the MERL materials are published (Ngan et al.'s have one lobe: `lafortune`).
"""

from __future__ import annotations

from typing import ClassVar

import torch

from .analytic import Coefficient
from .ngan_models import _KD, _KS, Lafortune, lafortune_lobe, lafortune_terms

Tensor = torch.Tensor

#: The per-lobe shape coefficients of `Lafortune`, suffixed with the lobe's number from 2 on.
_SHAPE = ("cxy", "cz", "exponent")
#: FLOPS of each lobe after the first: the weighted sum y 7, the power 5, the RGB multiply-add 6.
_FLOPS_PER_EXTRA_LOBE = 7 + 5 + 6


def _suffix(j: int) -> str:
    return "" if j == 1 else str(j)


def _coefficients(lobes: int) -> tuple[Coefficient, ...]:
    first = {c.name: c for c in Lafortune.COEFFS}
    out = [_KD, _KS, first["cxy"], first["cz"], first["exponent"]]
    for j in range(2, lobes + 1):
        out += [Coefficient(f"weight{j}", 3, 0.1, 1e-6, 1e3, log=True),
                *(Coefficient(f"{c.name}{j}", c.size, c.default, c.lower, c.upper, c.log)
                  for c in (first[name] for name in _SHAPE))]
    return tuple(out)


class LafortuneLobes(Lafortune):
    """k_d/π + k_s ⊙ (L₁ + Σ w_j ⊙ L_j) over LOBES generalised cosine lobes. Coefficients: kd,
    ks (RGB), cxy, cz, exponent of lobe 1, then per lobe j ≥ 2 weight{j} (RGB, relative to
    k_s), cxy{j}, cz{j}, exponent{j}."""

    LOBES: ClassVar[int] = 2
    PUBLISHED_AS: ClassVar[tuple[str, ...]] = ()  # no published multi-lobe fits
    PUBLISHED_PARAMS: ClassVar[dict[str, str]] = {}

    @classmethod
    def lobe_constants(cls, c: dict[str, Tensor]) -> list[dict[str, Tensor]]:
        """`Lafortune.constants` of each lobe, in order."""
        return [Lafortune.constants({name: c[name + _suffix(j)] for name in _SHAPE}) for j in range(1, cls.LOBES + 1)]

    @classmethod
    def constants(cls, c):
        return {f"{k}{_suffix(j)}": v for j, p in enumerate(cls.lobe_constants(c), 1) for k, v in p.items()}

    @classmethod
    def lobe(cls, g, c):
        terms = lafortune_terms(g)
        lobes = [lafortune_lobe(p, terms) for p in cls.lobe_constants(c)]
        total = lobes[0][:, None].expand(-1, 3)
        for j, value in enumerate(lobes[1:], 2):
            total = total + value[:, None] * c[f"weight{j}"]
        return total

    @classmethod
    def init_shape(cls, alpha):
        """Lobe 1 as `Lafortune` starts; lobe 2 a wider forward lobe a quarter as strong; lobe 3
        a broad lobe tilted towards the normal (off-specular), a tenth as strong."""
        shape = dict(Lafortune.init_shape(alpha))
        extra = [{"weight": 0.25, "cxy": -0.95, "cz": 1.0, "exponent": max(shape["exponent"] / 10.0, 1.0)},
                 {"weight": 0.1, "cxy": -0.5, "cz": 1.0, "exponent": 3.0}]
        for j in range(2, cls.LOBES + 1):
            start = extra[min(j - 2, len(extra) - 1)]
            shape.update({f"{k}{j}": v for k, v in start.items()})
        return shape

    @classmethod
    def validate_shape(cls, bbm_name, shape):  # no published fits to validate
        return None

    def drjit_kernel(self):
        """The model in drjit operations, for the classes of this module only (a subclass
        elsewhere may change `lobe`); drjit is imported here, not with the representation."""
        if type(self).__module__ != __name__:
            return None
        from .lafortune_lobes_kernel import LafortuneLobesKernel  # lazy: drjit

        return LafortuneLobesKernel(self)


class Lafortune2(LafortuneLobes):
    """Two generalised cosine lobes (`LafortuneLobes`)."""

    NAME = "lafortune2"
    LOBES = 2
    COEFFS = _coefficients(2)
    FLOPS = Lafortune.FLOPS + _FLOPS_PER_EXTRA_LOBE


class Lafortune3(LafortuneLobes):
    """Three generalised cosine lobes (`LafortuneLobes`)."""

    NAME = "lafortune3"
    LOBES = 3
    COEFFS = _coefficients(3)
    FLOPS = Lafortune.FLOPS + 2 * _FLOPS_PER_EXTRA_LOBE


MODELS = {cls.NAME: cls for cls in (Lafortune2, Lafortune3)}
