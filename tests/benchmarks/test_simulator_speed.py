"""What effect-aware rendering saves (pytest-benchmark): the cheap simulators against
Mitsuba's path tracer on the scenes where both are exact, end to end (scene load, render,
read-back), 256², the synthetic material 0's table as the BSDF (MERL gather kernel).

- `sphere_directional`: the closed form (one BRDF evaluation per pixel and light) against
  `path` at 64 spp;
- `sphere_envmap`: direct MIS against `path` at equal RMSE, from efficiency
  1 / (RMSE² · time) at 64 spp, RMSE against a 1024-spp direct-MIS reference. Under the
  environment alone both draw the same numbers at one seed, so their RMSEs are equal and
  the ratio is the time direct MIS saves by tracing nothing after the camera ray.

    python -m pytest tests/benchmarks/test_simulator_speed.py --benchmark-enable

Ratios are in `extra_info`.
"""

import time

import pytest

from brdfbench import mitsuba_env, scenes
from brdfbench.harness.render import TableReference
from brdfbench.render.build import build_simulator

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="the Mitsuba backends need libLLVM >= 19")
SIZE = 256


@pytest.fixture(scope="module")
def model(small_dataset):
    return TableReference(small_dataset.load(small_dataset.materials[0]))


def _best_time(sim, model, repeats=7, seed=0):
    """Best of `repeats` renders at one seed, as the render harness renders (reference and
    model at the job's seed: the loaded scene is reused)."""
    sim.render(model, seed=seed)  # compiles (or loads) the kernels
    best, image = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        image = sim.render(model, seed=seed)
        best = min(best, time.perf_counter() - t0)
    return image, best


def test_closed_form_against_path(benchmark, model):
    scene = scenes.sphere_directional(width=SIZE, height=SIZE)
    _, path_s = _best_time(build_simulator(scene, name="path", spp=64), model)
    closed = build_simulator(scene)
    closed.render(model)
    benchmark(closed.render, model)
    _, closed_s = _best_time(closed, model)
    benchmark.extra_info.update(closed_form_s=closed_s, path_64spp_s=path_s, speedup=path_s / closed_s)


def test_direct_mis_against_path_at_equal_rmse(benchmark, model):
    scene = scenes.sphere_envmap(width=SIZE, height=SIZE)
    reference = build_simulator(scene, spp=1024).render(model, seed=12345)
    efficiency = {}
    for name in ("direct_mis", "path"):
        image, seconds = _best_time(build_simulator(scene, name=name, spp=64), model)
        rmse = float((image - reference).pow(2).mean().sqrt())
        efficiency[name] = 1.0 / (rmse**2 * seconds)
        benchmark.extra_info[f"{name}_s"], benchmark.extra_info[f"{name}_rmse"] = seconds, rmse
    benchmark.extra_info["speedup_at_equal_rmse"] = efficiency["direct_mis"] / efficiency["path"]
    benchmark(build_simulator(scene, spp=64).render, model)
