"""The NBRDF multilayer perceptron: weights layout, input encodings, forward pass, `Network`.

Weights are a dict of tensors (or arrays) in the published Keras layout: `W1`, `b1`, …,
`WL`, `bL`, kernels stored (in, out), so a layer is y = x @ W + b. Hidden layers use ReLU;
the last layer's value z maps to a BRDF value by expm1(min(z, MAX_LOG_VALUE)), clamped at 0
and scaled per channel: ones for networks in 1/sr (the published release's), the MERL
channel scales for networks trained on raw MERL units (`raw_units`).

Input encodings of a direction pair, (N, 6):
- "rusinkiewicz" (NBRDF, Sztrajman et al. 2021): h = (sin θh, 0, cos θh) and
  d = (sin θd cos φd, sin θd sin φd, cos θd), angles from `coords.to_half_diff` (φd in
  [0, 2π)); φh is dropped, so the network is isotropic;
- "directions" (the naive baseline of Timonen et al.): (ωi, ωo) as they come.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import torch

from .. import coords, flops, merl

FEATURES = ("rusinkiewicz", "directions")
N_INPUTS = 6
N_OUTPUTS = 3
#: The published release's hidden widths (6 → 21 → 21 → 3, 675 weights).
PUBLISHED_HIDDEN = (21, 21)

#: The pre-exp value is clamped here so exp() stays finite even in fp32 (exp(80) ≈ 5.5e34
#: < fp32 max ≈ 3.4e38). Real materials never come near: a BRDF value of 1e6 is exp(13.8).
MAX_LOG_VALUE = 80.0

#: Arithmetic of the Rusinkiewicz encoding per pair, counted as merl.py counts: half
#: vector 12, ωi rotated into the half-vector frame 18, θh, θd, φd 6, and the five
#: sines and cosines plus two products of the input vector 7.
RUSINKIEWICZ_FLOPS = 12 + 18 + 6 + 7


# --------------------------------------------------------------------------- layout


def layer_sizes(hidden) -> list[int]:
    return [N_INPUTS, *hidden, N_OUTPUTS]


def weight_shapes(hidden) -> dict[str, tuple[int, ...]]:
    """name -> shape of every weight, in layer order (W1, b1, W2, b2, …)."""
    sizes = layer_sizes(hidden)
    shapes = {}
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
        shapes[f"W{i}"] = (n_in, n_out)
        shapes[f"b{i}"] = (n_out,)
    return shapes


def n_weights(hidden) -> int:
    return sum(math.prod(s) for s in weight_shapes(hidden).values())


def n_layers(weights: Mapping) -> int:
    return sum(1 for k in weights if k.startswith("W"))


def hidden_of(weights: Mapping) -> list[int]:
    """Hidden sizes of a weight dict in this layout (W1 … WL)."""
    return [int(weights[f"W{i}"].shape[1]) for i in range(1, n_layers(weights))]


def glorot_init(hidden, generator: torch.Generator) -> dict[str, torch.Tensor]:
    """Glorot-uniform kernels and zero biases (Keras' default, as the published networks used)."""
    out = {}
    for name, shape in weight_shapes(hidden).items():
        if name.startswith("W"):
            limit = math.sqrt(6.0 / (shape[0] + shape[1]))
            out[name] = (torch.rand(shape, generator=generator, dtype=torch.float32) * 2 - 1) * limit
        else:
            out[name] = torch.zeros(shape, dtype=torch.float32)
    return out


def units_scale(raw_units: bool) -> torch.Tensor:
    """The per-channel output scale (3,) float32: MERL's channel scales for raw units, else ones."""
    return torch.tensor(merl.CHANNEL_SCALES if raw_units else (1.0, 1.0, 1.0), dtype=torch.float32)


# --------------------------------------------------------------------------- inputs


def rusinkiewicz_from_angles(theta_h: torch.Tensor, theta_d: torch.Tensor, phi_d: torch.Tensor) -> torch.Tensor:
    """The Rusinkiewicz input (N, 6) from the angles (θh, θd, φd)."""
    st_h, st_d = torch.sin(theta_h), torch.sin(theta_d)
    return torch.stack(
        (st_h, torch.zeros_like(st_h), torch.cos(theta_h), st_d * torch.cos(phi_d), st_d * torch.sin(phi_d), torch.cos(theta_d)),
        dim=-1,
    )


def rusinkiewicz_input(wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """The Rusinkiewicz input (N, 6) = [hx, hy, hz, dx, dy, dz] of direction pairs, in their dtype."""
    hd = coords.to_half_diff(wi, wo)
    return rusinkiewicz_from_angles(hd.theta_h, hd.theta_d, hd.phi_d)


def encode(wi: torch.Tensor, wo: torch.Tensor, features: str) -> torch.Tensor:
    """Network inputs (N, 6) of direction pairs in the encoding `features`, in their dtype."""
    if features == "directions":
        return torch.cat((wi, wo), dim=-1)
    if features != "rusinkiewicz":
        raise ValueError(f"unknown MLP input encoding {features!r}; expected one of {', '.join(FEATURES)}")
    return rusinkiewicz_input(wi, wo)


# --------------------------------------------------------------------------- the forward pass


def last_layer(weights: Mapping, x: torch.Tensor) -> torch.Tensor:
    """z (N, 3): the last layer's value, before the exponential, computed in x's dtype."""
    layers = n_layers(weights)
    h = x
    for i in range(1, layers + 1):
        w = torch.as_tensor(weights[f"W{i}"]).to(device=x.device, dtype=x.dtype)
        b = torch.as_tensor(weights[f"b{i}"]).to(device=x.device, dtype=x.dtype)
        h = h @ w + b
        if i < layers:
            h = torch.relu(h)
    return h


def to_value(z: torch.Tensor, output_scale: torch.Tensor | None = None) -> torch.Tensor:
    """BRDF values from z: expm1(min(z, MAX_LOG_VALUE)) clamped at 0 (expm1: no cancellation
    near 0; the clamp keeps fp32 finite), times the channel scales."""
    out = torch.clamp(torch.expm1(torch.clamp(z, max=MAX_LOG_VALUE)), min=0.0)
    return out if output_scale is None else out * output_scale.to(device=z.device, dtype=z.dtype)


def forward(weights: Mapping, x: torch.Tensor, output_scale: torch.Tensor | None = None) -> torch.Tensor:
    """RGB BRDF values (N, 3) for network inputs x (N, 6), computed in x's dtype."""
    if x.ndim != 2 or x.shape[-1] != N_INPUTS or not x.dtype.is_floating_point:
        raise ValueError(f"NBRDF input must be a floating (N, {N_INPUTS}) tensor, got {tuple(x.shape)} {x.dtype}")
    return to_value(last_layer(weights, x), output_scale)


def mlp_flops(hidden) -> int:
    """Arithmetic per evaluation of the network alone: multiply-adds, biases, ReLUs, expm1,
    clamp and channel scale."""
    return flops.mlp(layer_sizes(hidden), "relu") + 3 * N_OUTPUTS


# --------------------------------------------------------------------------- the network


@dataclass(frozen=True)
class Network:
    """Weights in the Keras layout, their input encoding, their units, and where they came
    from (`source`: the file they were read from, if any)."""

    weights: dict[str, torch.Tensor]
    features: str = "rusinkiewicz"
    raw_units: bool = False
    source: str | None = None

    @property
    def hidden(self) -> list[int]:
        return hidden_of(self.weights)

    @property
    def output_scale(self) -> torch.Tensor:
        return units_scale(self.raw_units)

    def eval(self, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
        """BRDF values (N, 3) at direction pairs (the protocol's masking is the caller's)."""
        return forward(self.weights, encode(wi, wo, self.features), self.output_scale)
