"""Cost of the image-space inputs of the generation benchmark (pytest-benchmark): rendering
a set of 24 materials (`render_set`'s default size and spp, one simulator for the set; on
the default backend and on torch, the fallback where Mitsuba's LLVM backend is missing), a
240 × 240 image distance matrix of each kind on 64 × 64 renders (a set against itself, as
1-NNA needs), and the InceptionV3 features of 120 such renders (what one FID side costs).

    python -m pytest tests/benchmarks/test_image_distance_speed.py --benchmark-enable

Members are GGX models with random coefficients (no fit: only rendering is timed).
`extra_info` records the simulator, backend, image size, spp and torch threads. Disabled
(the default run) every test is skipped: they time, and tests/unit/test_image_distances.py
and tests/unit/test_fid.py check what they run.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench_metrics import fid as FD
from brdfbench.distances import image as D

N_RENDER, N_MATRIX, N_FID = 24, 240, 120


def ggx_members(n: int, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    return [registry.get("representations", "ggx").create().set_coefficients(
        kd=rng.uniform(0.02, 0.6, 3), ks=rng.uniform(0.05, 1.0, 3), alpha=float(np.exp(rng.uniform(-4.0, -0.5))),
        f0=float(rng.uniform(0.02, 0.9))) for _ in range(n)]


@pytest.fixture(scope="module")
def renders():
    """N_MATRIX closed-form renders at the default size (made only when a timing runs)."""
    return D.render_set(ggx_members(N_MATRIX, seed=1), "sphere_directional")


@pytest.mark.parametrize("backend", [None, "torch"])  # None: Mitsuba where LLVM loads (build_simulator)
@pytest.mark.parametrize("scene", ["sphere_envmap", "sphere_directional"])
def test_render_set(enabled, scene, backend):
    members = ggx_members(N_RENDER)
    sim = D.build_set_simulator(scene, backend=backend)
    D.render_with(sim, members[:1])  # kernels compiled and the scene loaded: the steady state of a set
    images = enabled.pedantic(lambda: D.render_with(sim, members), rounds=1 if sim.backend == "torch" else 3,
                              iterations=1)
    assert images.shape == (N_RENDER, D.DEFAULT_SIZE, D.DEFAULT_SIZE, 3)
    enabled.extra_info.update(n=N_RENDER, simulator=sim.name, backend=sim.backend, size=D.DEFAULT_SIZE,
                              spp=getattr(sim, "spp", None), threads=torch.get_num_threads())


@pytest.mark.parametrize("kind", D.KINDS)
def test_distance_matrix(enabled, renders, kind):
    d = enabled.pedantic(lambda: D.image_distance_matrix(renders, kind=kind), rounds=2 if kind == "neg_ssim" else 3,
                         iterations=1)
    assert d.shape == (N_MATRIX, N_MATRIX) and np.isfinite(d).all()
    enabled.extra_info.update(n=N_MATRIX, size=D.DEFAULT_SIZE, pairs=N_MATRIX * (N_MATRIX + 1) // 2)


def test_fid_features(enabled, renders):
    FD.load_inception()  # the network loads once per process; time the features
    f = enabled.pedantic(lambda: FD.inception_features(renders[:N_FID]), rounds=1, iterations=1)
    assert f.shape == (N_FID, FD.FEATURES)
    enabled.extra_info.update(n=N_FID, size=D.DEFAULT_SIZE, batch=FD.BATCH, threads=FD.THREADS)
