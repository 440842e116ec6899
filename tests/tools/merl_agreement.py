"""Mismatch counts of the project's MERL cells against the reference reader's, per adversarial set.

    .venv/bin/python tests/tools/merl_agreement.py [N]      # N pairs a set (default 140000)

For each set of tests/unit/test_merl_reference_agreement.py (ωi = ωo, exact specular given
as angles, θo = 0, in-plane, equal polar angles, points on θh / θd / φd cell edges) and each
entry point (brdfbench.merl on the reader's own vectors and on torch-made unit vectors, the
angle entry point, the drjit kernel on fp32 vectors), it prints how many lookups land in
another cell than the oracle's (tests/unit/merl_reference.py, the reader's arithmetic step
by step), split into: within 1e-9 cells of an edge / degenerate (θh or θd below 1e-6 rad) /
other. The kernel is compared with the reader's arithmetic on the very fp32 vectors it is
given. The issue-17 figures came from this script.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "unit"))

import test_merl_reference_agreement as agreement  # noqa: E402

from brdfbench import merl, mitsuba_env  # noqa: E402

ref = agreement.ref  # the oracle: tests/unit/merl_reference.py


def classify(got: np.ndarray, want: np.ndarray, coordinates: np.ndarray, degenerate: np.ndarray) -> tuple[int, ...]:
    wrong = (got != want).any(1)
    edge = (np.abs(coordinates - np.round(coordinates)) < agreement.EDGE_TOL).any(1)
    return (int(wrong.sum()), int((wrong & edge & ~degenerate).sum()), int((wrong & degenerate).sum()),
            int((wrong & ~edge & ~degenerate).sum()))


def kernel_cells(wi: torch.Tensor, wo: torch.Tensor) -> np.ndarray | None:
    if not mitsuba_env.llvm_usable():
        return None
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        import mitsuba as mi

        from brdfbench.render import drjit_kernels as dk

        vec = [mi.Vector3f(*(mi.Float(np.ascontiguousarray(w[:, c].numpy())) for c in range(3))) for w in (wi, wo)]
        flat = np.asarray(dk.merl_cell(*vec)).astype(np.int64)
    return np.stack([flat // (merl.RES_THETA_D * merl.RES_PHI_D), flat // merl.RES_PHI_D % merl.RES_THETA_D,
                     flat % merl.RES_PHI_D], 1)


def main(n: int) -> None:
    columns = ("reader's vectors", "torch unit vectors", "angle entry", "drjit kernel (fp32)")
    print(f"{n} pairs a set; lookups in another cell than the reader's: total (share) edge/degenerate/other")
    print(f"{'set':16} {'n':>7} | " + " | ".join(f"{c:>32}" for c in columns))
    totals = {c: np.zeros(4, dtype=np.int64) for c in columns}
    count = 0
    for name, angles in agreement.adversarial_sets(n).items():
        want, coordinates, thetas = agreement.oracle(angles)
        degenerate = ~((thetas[:, 0] >= agreement.DEGENERATE) & (thetas[:, 1] >= agreement.DEGENERATE))
        row = {}
        wi, wo = agreement.reader_vectors(angles)
        row[columns[0]] = classify(agreement.cells(merl.cell_indices(wi, wo)), want, coordinates, degenerate)
        ti, to = agreement.torch_unit_vectors(angles)
        row[columns[1]] = classify(agreement.cells(merl.cell_indices(ti, to)), want, coordinates, degenerate)
        a = torch.from_numpy(angles)
        row[columns[2]] = classify(agreement.cells(merl.angle_cell_indices(a[:, 0], a[:, 1], a[:, 2], a[:, 3])),
                                   want, coordinates, degenerate)
        w32i, w32o = wi.float(), wo.float()
        got = kernel_cells(w32i, w32o)
        if got is not None:
            hd = [ref.half_diff_from_vectors(x, y) for x, y in zip(w32i.double().tolist(), w32o.double().tolist())]
            k_want = np.array([ref.indices(th, td, pd) for th, _, td, pd in hd])
            k_coord = np.array([ref.cell_coordinates(th, td, pd) for th, _, td, pd in hd])
            k_degen = np.array([not (th >= agreement.DEGENERATE and td >= agreement.DEGENERATE) for th, _, td, _ in hd])
            row[columns[3]] = classify(got, k_want, k_coord, k_degen)
        count += len(angles)
        cells = []
        for c in columns:
            if c not in row:
                cells.append(f"{'-':>32}")
                continue
            totals[c] += row[c]
            t, e, d, o = row[c]
            cells.append(f"{t:>7} ({t / len(angles):7.3%}) {e:>6}/{d:>6}/{o:>6}")
        print(f"{name:16} {len(angles):>7} | " + " | ".join(cells), flush=True)
    print(f"{'all':16} {count:>7} | " + " | ".join(
        f"{t[0]:>7} ({t[0] / count:7.3%}) {t[1]:>6}/{t[2]:>6}/{t[3]:>6}" for t in totals.values()))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 140_000)
