"""The project's one FLOP counter: the rules by which every representation counts the
arithmetic of one (ωi, ωo) evaluation, written once so that figures compare.

Rules (arithmetic only; memory reads are not counted):
- a multiply-add is 2 FLOPs, a bias add 1 (a dense layer in → out: 2·in·out + out);
- activations per unit: ReLU 1, SiLU 4 (exp, add, divide, multiply);
- exp / expm1 / log / sin / cos / atan2 / sqrt: 1 each, as an add is;
- a texture read of C channels, linear in one axis: the coordinate (scale, floor,
  fraction: 3) and one lerp per channel (b − a, × t, + a: 3), so 3 + 3·C;
- bilinear in two axes: 3 per axis for the coordinates, 2 more for a circular axis's
  wrap, and three lerps per channel, so 8 + 9·C (the four corner fetches are reads).

Timonen et al. count with a public PyTorch FLOP counter of its own choosing (its Table 3: 831 /
791 / 888 / 842); figures under these rules are ours and compare with each other, not with
those.
"""

from __future__ import annotations

from typing import Sequence

ACTIVATION_FLOPS = {"relu": 1, "silu": 4}
TRANSCENDENTAL = 1
LINEAR_READ_COORD = 3
BILINEAR_READ_COORD = 8
LERP = 3


def dense(n_in: int, n_out: int, bias: bool = True) -> int:
    """One dense layer."""
    return 2 * n_in * n_out + (n_out if bias else 0)


def activation(kind: str, units: int) -> int:
    if kind not in ACTIVATION_FLOPS:
        raise ValueError(f"no FLOP rule for activation {kind!r}; known: {', '.join(ACTIVATION_FLOPS)}")
    return ACTIVATION_FLOPS[kind] * units


def mlp(sizes: Sequence[int], kind: str) -> int:
    """Dense layers through `sizes` (inputs, hidden…, outputs), `kind` after every hidden one."""
    sizes = list(sizes)
    layers = sum(dense(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
    return layers + activation(kind, sum(sizes[1:-1]))


def linear_read(channels: int) -> int:
    """A texture read interpolated along one axis."""
    return LINEAR_READ_COORD + LERP * channels


def bilinear_read(channels: int) -> int:
    """A texture read interpolated bilinearly, one axis circular."""
    return BILINEAR_READ_COORD + 3 * LERP * channels
