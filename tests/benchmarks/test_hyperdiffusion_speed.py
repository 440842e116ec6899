"""Hyperdiffusion speed at NeuMERL's size (pytest-benchmark), with the generator's defaults:

    python -m pytest tests/benchmarks/test_hyperdiffusion_speed.py --benchmark-enable

- `test_training_epoch`: one training epoch (a fit with epochs=1: standardisation, the
  matched prior's SVD and ⌈2400 / batch_size⌉ steps) on 2400 × 675 weight vectors;
  `extra_info` extrapolates the default fit (its epochs × the median epoch);
- `test_sample_120`: 120 samples with the default DDIM steps (the test-set size of Zhou et al.);
- `test_sample_120_guided`: the same, category-conditioned with guidance 2 (two denoiser
  passes per step).

The vectors are perturbations of one fitted network (a published NBRDF where the release is
present, else Glorot weights): low-rank material variation plus small noise, so they look
aligned as NeuMERL's are. Speed does not depend on the values. Disabled (the default run),
they are skipped: tests/unit/test_hyperdiffusion.py checks what they run.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
import torch

from brdfbench.data.nbrdf_release import find_release_dir
from brdfbench.protocols.generator import TrainingData, WeightSet
from brdfbench.nbrdf import network as nw
from brdfbench.nbrdf.formats import read_network
from brdfbench.nbrdf.layouts import flatten
from brdfbench_generators.hyperdiffusion import HyperDiffusion

N_MATERIALS = 2400
N_SAMPLES = 120
CATEGORIES = ("metal", "plastic", "fabric", "paint", "rubber", "phenolic")


def _base_vector() -> np.ndarray:
    release = find_release_dir()
    files = sorted(release.glob("merl/*.h5")) if release else []
    if files:
        return flatten(read_network(files[0]).weights)
    return flatten(nw.glorot_init(nw.PUBLISHED_HIDDEN, torch.Generator().manual_seed(0)))


@pytest.fixture(scope="module")
def data() -> TrainingData:
    base = _base_vector()
    rng = np.random.default_rng(0)
    directions = rng.standard_normal((16, base.size)) * (0.1 * np.abs(base) + 0.01)
    vectors = base + rng.standard_normal((N_MATERIALS, 16)) @ directions
    vectors += 0.01 * rng.standard_normal(vectors.shape)
    names = tuple(f"material-{i:04d}" for i in range(N_MATERIALS))
    ws = WeightSet(names, vectors.astype(np.float32))
    return TrainingData(names=names, load=None, categories={n: CATEGORIES[i % len(CATEGORIES)] for i, n in enumerate(names)},
                        weight_source=lambda _: ws, dataset="perturbed")


def _default(key: str):
    return inspect.signature(HyperDiffusion).parameters[key].default


def test_training_epoch(enabled, data):
    fitted = []
    enabled.pedantic(lambda: fitted.append(HyperDiffusion(epochs=1).fit(data, seed=0)), rounds=3, iterations=1)
    epochs = _default("epochs")
    enabled.extra_info.update(materials=N_MATERIALS, width=675, default_epochs=epochs,
                              full_fit_s_extrapolated=enabled.stats.stats.median * epochs,
                              parameters=sum(p.numel() for p in fitted[-1].model.parameters()))


def test_sample_120(enabled, data):
    model = HyperDiffusion(epochs=1).fit(data, seed=0)
    seeds = iter(range(1000))
    enabled.pedantic(lambda: model.sample(N_SAMPLES, seed=next(seeds)), rounds=5, iterations=1)
    enabled.extra_info.update(n=N_SAMPLES, ddim_steps=model.params["ddim_steps"])


def test_sample_120_guided(enabled, data):
    model = HyperDiffusion(epochs=1, condition_on="category", guidance=2.0).fit(data, seed=0)
    seeds = iter(range(1000))
    enabled.pedantic(lambda: model.sample(N_SAMPLES, condition="metal", seed=next(seeds)), rounds=5, iterations=1)
    enabled.extra_info.update(n=N_SAMPLES, ddim_steps=model.params["ddim_steps"], guidance=2.0)
