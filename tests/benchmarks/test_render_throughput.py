"""Render throughput of the Mitsuba adapter against a built-in Mitsuba BSDF (pytest-benchmark).

The same scene for every BSDF (`mitsuba_bsdf.sphere_scene`): the unit sphere at 256²,
perspective camera, box filter, one directional light and a constant ambient, Mitsuba's
`path` integrator with max_depth 2, 16 spp, llvm_ad_rgb. Adapters sample with the default
cosine sampler. Each timed render includes tracing (the kernel comes from the cache: one
warm-up render compiles it). Measure with

    python -m pytest tests/benchmarks/test_render_throughput.py --benchmark-enable

M samples/s (camera samples) is in `extra_info["msamples_per_s"]`.
"""

import time

import pytest
import torch

from brdfbench import mitsuba_env, registry
from brdfbench.testing.kit import reference_material

RESOLUTION, SPP = 256, 16
CASES = ["roughconductor", "merl", "nbrdf", "ggx", "cook_torrance"]

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")


@pytest.fixture(scope="module")
def mb():
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        from brdfbench.render import mitsuba_bsdf

        mitsuba_bsdf.register_plugins()
        yield mitsuba_bsdf


def bsdf(mb, name: str) -> dict:
    """Mitsuba's own rough conductor, or an adapter of a model of synthetic material 1
    (nbrdf with random weights: its cost does not depend on them)."""
    if name == "roughconductor":
        return {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}
    spec = registry.get("representations", name)
    if name == "nbrdf":
        from brdfbench_representations import mlp

        model = spec.create()
        model.weights = mlp.glorot_init(model.hidden, torch.Generator().manual_seed(0))
    elif name == "merl":
        model = spec.create().fit(reference_material())
    else:
        model = spec.create(n_samples=512, restarts=1).fit(reference_material())
    return mb.bsdf_dict(model, rep_name=name)


@pytest.mark.parametrize("name", CASES)
def test_render_throughput(benchmark, mb, name):
    scene = mb.load_dict(mb.sphere_scene(bsdf(mb, name), resolution=RESOLUTION, spp=SPP))
    mb.render(scene)  # compiles (or loads) the kernel
    times = []

    def run():
        start = time.perf_counter()
        mb.render(scene, seed=len(times) + 1)
        times.append(time.perf_counter() - start)

    benchmark.pedantic(run, rounds=3, iterations=1)
    rate = RESOLUTION * RESOLUTION * SPP / min(times) / 1e6
    benchmark.extra_info["msamples_per_s"] = round(rate, 2)
    print(f"{name}: {rate:.1f} M samples/s")
