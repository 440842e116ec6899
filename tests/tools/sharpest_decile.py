"""Accuracy on the sharpest materials apart: seed 002 claims the learned warps help most on
sharp highlights, so a results store's per-material figures are split by the sharpness of
each target's specular lobe and each configuration's mean reported on the sharpest tenth
and on the rest.

Sharpness is the lobe half-width of constrained synthesis (`brdfbench_metrics.categories`,
seed 003 C.3: the θh at which ‖f(θh, 0, 0)‖∞ first halves); the narrowest lobes form the
decile (at least one material). Run against a results folder written by the accuracy
harness on one dataset:

    .venv/bin/python tests/tools/sharpest_decile.py RESULTS_DIR DATASET [KEY=VALUE ...]

(KEY=VALUE: the dataset's params, e.g. `subset=merl`.) Prints a Markdown table.
"""

from __future__ import annotations

import math
import sys

import brdfbench as bb
from brdfbench_metrics.categories import statistics

METRICS = ("l1_log_cos", "hdr_rmse")


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    folder, dataset_name, *pairs = argv
    params = dict(p.split("=", 1) for p in pairs)
    frame = bb.results(folder).frame()
    frame = frame[(frame.dataset == dataset_name) & (frame.status == "ok") & (frame.scope != "set")]
    if frame.empty:
        print(f"{folder}: no per-material rows of dataset {dataset_name!r}", file=sys.stderr)
        return 2
    dataset = bb.datasets(dataset_name, **params)
    names = sorted(set(frame.material))
    width = {}
    for i, name in enumerate(names):
        width[name] = statistics(dataset.load(name), index=i).half_width
        print(f"\r{i + 1}/{len(names)} lobes measured", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    ordered = sorted(names, key=lambda n: (math.isnan(width[n]), width[n]))
    decile = set(ordered[:max(1, len(ordered) // 10)])
    widths = ", ".join(f"{n} {width[n]:.3g}" for n in ordered[:len(decile)])
    print(f"Sharpest decile ({len(decile)} of {len(names)} materials; half-width in rad): {widths}\n")
    print("| configuration | " + " | ".join(f"{m} sharpest | {m} rest" for m in METRICS) + " |")
    print("|---|" + "---|---|" * len(METRICS))
    for label, rows in frame.groupby("representation"):
        cells = []
        for metric in METRICS:
            r = rows[rows.metric == metric]
            sharp = r[r.material.isin(decile)].value.mean()
            rest = r[~r.material.isin(decile)].value.mean()
            cells += [f"{sharp:.4g}", f"{rest:.4g}"]
        print(f"| `{label}` | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
