"""The small MLP shared by the neural BRDF representations: inputs, forward pass, output.

Weights are a dict of tensors in the published NBRDF (Keras) layout: `W1`, `b1`, …, `WL`,
`bL` with kernels stored (in, out), so a layer is y = x @ W + b. Hidden layers use ReLU;
the last layer's value z is mapped to a BRDF value by expm1(z), clamped at 0 and scaled
per channel (`output_scale`: ones for networks in 1/sr, the MERL channel scales for
networks trained on raw MERL units).

Two input encodings of a direction pair:
- "rusinkiewicz" (NBRDF, Sztrajman et al. 2021): h = (sin θh, 0, cos θh) and
  d = (sin θd cos φd, sin θd sin φd, cos θd); φh is dropped, so the model is isotropic;
- "directions" (the naive baseline of Timonen et al.): (ωi, ωo) as they come.
"""

from __future__ import annotations

import math
from typing import Mapping

import torch

from brdfbench.data.nbrdf_h5 import MAX_LOG_VALUE, nbrdf_input, nbrdf_input_from_angles

FEATURES = ("rusinkiewicz", "directions")
N_INPUTS = 6
N_OUTPUTS = 3

#: Arithmetic of the Rusinkiewicz encoding per pair, counted as merl.py counts: half
#: vector 12, ωi rotated into the half-vector frame 18, θh, θd, φd 6, and the five
#: sines and cosines plus two products of the input vector 7.
RUSINKIEWICZ_FLOPS = 12 + 18 + 6 + 7


def layer_sizes(hidden: list[int] | tuple[int, ...]) -> list[int]:
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


def hidden_of(weights: Mapping[str, torch.Tensor]) -> list[int]:
    """Hidden sizes of a weight dict in this layout (W1 … WL)."""
    n_layers = sum(1 for k in weights if k.startswith("W"))
    return [int(weights[f"W{i}"].shape[1]) for i in range(1, n_layers)]


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


def encode(wi: torch.Tensor, wo: torch.Tensor, features: str) -> torch.Tensor:
    """Network inputs (N, 6) of direction pairs, in their dtype."""
    if features == "directions":
        return torch.cat((wi, wo), dim=-1)
    if features != "rusinkiewicz":
        raise ValueError(f"unknown MLP input encoding {features!r}; expected one of {', '.join(FEATURES)}")
    return nbrdf_input(wi, wo)


#: The Rusinkiewicz encoding (N, 6) from the angles (θh, θd, φd).
encode_angles = nbrdf_input_from_angles


def last_layer(weights: Mapping[str, torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """z (N, 3): the last layer's value, before the exponential, in x's dtype."""
    n_layers = sum(1 for k in weights if k.startswith("W"))
    h = x
    for i in range(1, n_layers + 1):
        h = h @ weights[f"W{i}"].to(x.dtype) + weights[f"b{i}"].to(x.dtype)
        if i < n_layers:
            h = torch.relu(h)
    return h


def to_value(z: torch.Tensor, output_scale: torch.Tensor | None = None) -> torch.Tensor:
    """BRDF values from z: expm1(min(z, MAX_LOG_VALUE)) clamped at 0, times the channel scales."""
    out = torch.clamp(torch.expm1(torch.clamp(z, max=MAX_LOG_VALUE)), min=0.0)
    return out if output_scale is None else out * output_scale.to(z.dtype)


def mlp_flops(hidden) -> int:
    """Arithmetic per evaluation of the network alone: multiply-adds, biases, ReLUs, expm1,
    clamp and channel scale."""
    sizes = layer_sizes(hidden)
    dense = sum(2 * a * b + b for a, b in zip(sizes[:-1], sizes[1:]))
    relus = sum(hidden)
    return dense + relus + 3 * N_OUTPUTS
