"""In-plane lobe slices: a BRDF at fixed incident inclinations against the outgoing angle
in the plane of incidence, as the polar plots of BRDF Explorer and Sztrajman et al. 2021 (Figure 8)
draw them. A cell of the accuracy harness saves its model's slices beside its table's
(nearest-cell lookup, as the reference reader), for the report to plot. And the width
of a target's specular lobe (Zhou et al.'s lobe half-width), by which the report sets the
sharpest tenth of a dataset's materials apart.

Signed outgoing angle: positive on the mirror side (φo = φi + π), negative on the side of
the incident light (φo = φi); φi = 0.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..atomic import replacing

if TYPE_CHECKING:  # torch only where slices are computed: a report reads them without it
    import torch

    from ..merl import MerlTable

THETA_I_DEG = (15.0, 45.0, 75.0)
THETA_O_DEG = tuple(float(t) for t in range(-89, 90))  # 1° steps, the horizon left out
FORMAT = "brdfbench-lobes-1"


def in_plane_pairs(theta_i_deg: float, dtype: "torch.dtype | None" = None) -> "tuple[torch.Tensor, torch.Tensor]":
    """(wi, wo) for one incident inclination and every signed outgoing angle of `THETA_O_DEG`."""
    import torch

    from ..coords import spherical_to_vector  # lazy: torch

    dtype = dtype or torch.float64
    signed = torch.tensor(THETA_O_DEG, dtype=torch.float64) * (math.pi / 180)
    theta_o = signed.abs()
    phi_o = torch.where(signed >= 0, torch.full_like(signed, math.pi), torch.zeros_like(signed))
    wo = spherical_to_vector(theta_o, phi_o)
    wi = spherical_to_vector(torch.full_like(signed, theta_i_deg * math.pi / 180), torch.zeros_like(signed))
    return wi.to(dtype), wo.to(dtype)


def slices(evaluate: "Callable[[torch.Tensor, torch.Tensor], torch.Tensor]",
           dtype: "torch.dtype | None" = None) -> list[list[list[float]]]:
    """`evaluate(wi, wo)` (N, 3) at every slice: [θi][θo][rgb] in 1/sr."""
    import torch

    out = []
    for theta_i in THETA_I_DEG:
        wi, wo = in_plane_pairs(theta_i, dtype)
        with torch.no_grad():
            values = evaluate(wi, wo).to(torch.float64)
        out.append([[float(f"{float(v):.7g}") for v in row] for row in values])  # 7 digits: fp32 precision
    return out


def write(path: Path, model: list, table: list, label: str, material: str) -> None:
    """One cell's slices, with its table's, as JSON (atomically)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"format": FORMAT, "label": label, "material": material, "theta_i_deg": list(THETA_I_DEG),
           "theta_o_deg": list(THETA_O_DEG), "unit": "1/sr", "model": model, "table": table}
    with replacing(path) as tmp:
        tmp.write_text(json.dumps(doc, separators=(",", ":"), allow_nan=True), encoding="utf-8")


def read(path: Path) -> dict | None:
    """A lobes file, or None where it is missing, unreadable or not this format."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        return None
    return doc


# --------------------------------------------------------------------------- the target's lobe width

#: MERL's θh resolution (brdfbench.merl.RES_THETA_H), here so that a report needs no torch
RES_THETA_H = 90


def theta_h_centres() -> np.ndarray:
    """θh of the 90 MERL cell centres (square-root warped axis: dense at the specular peak)."""
    i = (np.arange(RES_THETA_H) + 0.5) / RES_THETA_H
    return i * i * (math.pi / 2)


def lobe_half_width(theta_h, values) -> float:
    """w: the θh at which f(θh, θd = 0, φd = 0) first drops to half of its peak f(0, 0, 0).

    `values` (one per ascending θh sample, NaN = invalid, skipped) are ‖f‖∞, the largest
    channel: the same norm as the other rules, and free of channel scales (luminance would
    weigh a coloured lobe by its colour). The peak is the first valid sample (the first
    MERL θh centre is 5e-5 rad). w is interpolated linearly in θh between the last sample
    above half and the first at or below it. The first crossing, as Zhou et al. (C.3) word
    it, not Hu 2026's "and remains smaller thereafter": f rises again at grazing
    backscatter (θh → 90° with θi = θo) in measured and physically based data alike (the
    synthetic gold climbs back above half its peak at θh = 89°), which would make every
    such lobe infinitely wide. inf when f never drops to half (a flat, diffuse row); NaN
    when no valid sample or the peak is not positive.
    """
    theta_h = np.asarray(theta_h, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    ok = ~np.isnan(values)
    theta_h, values = theta_h[ok], values[ok]
    if values.size == 0 or not values[0] > 0:
        return math.nan
    half = values[0] / 2
    below = np.flatnonzero(values <= half)
    if below.size == 0:
        return math.inf
    j = int(below[0])  # >= 1: the peak itself is above half
    t = (values[j - 1] - half) / (values[j - 1] - values[j])
    return float(theta_h[j - 1] + t * (theta_h[j] - theta_h[j - 1]))


#: The metric under which the accuracy harness stores `table_half_width` (rad): a property
#: of the target, not a figure of the model; the report reads it by this name.
TARGET_HALF_WIDTH = "target_lobe_half_width"


def peak_row(table: "MerlTable") -> np.ndarray:
    """A table's θd = φd = 0 row (cell 0 of each), (90, 3) float64 in 1/sr, NaN where invalid."""
    row = np.asarray(table.values[:, :, 0, 0], dtype=np.float64).T.copy()
    row[~np.asarray(table.valid[:, 0, 0])] = np.nan
    return row


def table_half_width(table: "MerlTable") -> float | None:
    """The lobe half-width (rad) of a table's θd = φd = 0 row (cell 0 of each, ‖f‖∞ over the
    channels, invalid cells skipped): π/2 where f never drops to half (no lobe within the θh
    range), None where the row has no valid cell or no positive peak. Stored by the accuracy
    harness as `target_lobe_half_width`, which the report's sharpest-decile table ranks."""
    width = lobe_half_width(theta_h_centres(), np.max(peak_row(table), axis=1))
    if math.isnan(width):
        return None
    return min(width, math.pi / 2)
