"""A store frame for report tests, as `Store.frame()` returns it: a reference (`merl`
nearest), three ranked configurations whose errors grow with the sharpness of the
material's lobe, costs in every unit the report scales, and the machine that ran them."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

#: (label, plugin, params, base error, fit time s, bytes, sharpness sensitivity)
CONFIGS = (
    ("merl", "merl", {"mode": "nearest", "downsample": 1}, 1e-9, 4e-5, 34_992_000, 0.0),
    ("nbrdf", "nbrdf", {}, 0.02, 1.5, 2700, 1.0),
    ("ggx", "ggx", {}, 0.05, 0.4, 64, 2.0),
    ("lambert", "lambert", {}, 0.26, 0.2, 24, 4.0),
)
CATEGORIES = ("metal", "plastic", "fabric", "rubber")


def frame(n_materials: int = 8, configs=CONFIGS, shared: dict[str, float] | None = None,
          platform: str = "Linux x86_64 Python 3.11.7 torch 2.13.0+cpu") -> pd.DataFrame:
    """A store frame as `Store.frame()` returns it: errors that grow with lobe sharpness."""
    rng = np.random.default_rng(0)
    rows = []
    for i in range(n_materials):
        material = f"mat-{i:02d}"
        width = 0.01 * (i + 1)  # mat-00 has the sharpest lobe
        for label, plugin, params, err, fit, size, sens in configs:
            cell = dict(representation=label, config_hash=f"h-{label}", plugin=plugin,
                        params=json.dumps({"params": params}), material=material,
                        category=CATEGORIES[i % len(CATEGORIES)])
            value = err * (1 + sens / (width * 10)) * (1 + 0.05 * rng.random())
            rows += [dict(cell, metric="l1_log_cos", value=value, unit="log(1+1/sr)", higher_is_better=False),
                     dict(cell, metric="l1", value=value * 3, unit="1/sr", higher_is_better=False),
                     dict(cell, metric="fit_time", value=fit, unit="s", higher_is_better=False),
                     dict(cell, metric="evals_per_s", value=5.8e6, unit="evals/s", higher_is_better=True),
                     dict(cell, metric="model_bytes", value=float(size), unit="B", higher_is_better=False),
                     dict(cell, metric="peak_rss_fit", value=9.536e8, unit="B", higher_is_better=False),
                     dict(cell, metric="target_lobe_half_width", value=width, unit="rad", higher_is_better=False)]
            if shared and label in shared:
                rows.append(dict(cell, metric="shared_bytes", value=shared[label], unit="B", higher_is_better=False))
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"] = "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    df["scene"], df["harness"], df["sampler"], df["spp"], df["concurrent_jobs"] = "brdf_space", "accuracy", "", 0, 1
    df["host"], df["cpu_model"], df["cpu_count"], df["threads"] = "box", "AMD EPYC 9654", 2, 2
    df["device_detail"], df["platform"] = "cpu", platform
    return df
