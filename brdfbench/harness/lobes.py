"""In-plane lobe slices: a BRDF at fixed incident inclinations against the outgoing angle
in the plane of incidence, as the polar plots of BRDF Explorer and seed 001 (Figure 8)
draw them. A cell of the accuracy harness saves its model's slices beside its table's
(nearest-cell lookup, as the reference reader), for the report to plot.

Signed outgoing angle: positive on the mirror side (φo = φi + π), negative on the side of
the incident light (φo = φi); φi = 0.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from ..atomic import replacing

if TYPE_CHECKING:  # torch only where slices are computed: a report reads them without it
    import torch

THETA_I_DEG = (15.0, 45.0, 75.0)
THETA_O_DEG = tuple(float(t) for t in range(-89, 90))  # 1° steps, the horizon left out
FORMAT = "brdfbench-lobes-1"


def in_plane_pairs(theta_i_deg: float, dtype: "torch.dtype | None" = None) -> "tuple[torch.Tensor, torch.Tensor]":
    """(wi, wo) for one incident inclination and every signed outgoing angle of `THETA_O_DEG`."""
    import torch

    from ..coords import spherical_to_vector

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
