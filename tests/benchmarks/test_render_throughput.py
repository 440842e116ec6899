"""Render throughput of the Mitsuba adapter against Mitsuba's own BSDFs (pytest-benchmark).

The same scene for every BSDF (`mitsuba_bsdf.sphere_scene`): the unit sphere at 256²,
perspective camera, box filter, one directional light and a constant ambient, 16 spp,
llvm_ad_rgb, rendered by two integrators:

- `path`: Mitsuba's path tracer at max_depth 2 — the plugin as it runs in any Mitsuba
  scene, behind Mitsuba's BSDF dispatch (a symbolic virtual call: per-material data are
  call data, gathered per lane);
- `direct_mis`: brdfbench's direct-lighting integrator for convex objects, the one the
  render harness uses for environment-lit spheres; it calls the scene's only BSDF
  directly, so per-material data are kernel parameters.

Adapters sample with the default cosine sampler; Mitsuba's BSDFs with their own. Each
timed render includes tracing (the kernel comes from drjit's cache: one warm-up render
compiles it). Measure with

    python -m pytest tests/benchmarks/test_render_throughput.py --benchmark-enable -s

`test_render_throughput` gives pytest-benchmark's statistics per (integrator, BSDF);
`test_throughput_ratios` renders every BSDF in turn, six cycles over (one scene alive
at a time: a symbolic call traces every live BSDF), and reports each one's best
M samples/s and its ratios to `roughconductor` and `merl` in `extra_info`, so that the
ratios come from one interleaved run.
"""

import gc
import time

import pytest
import torch

from brdfbench import mitsuba_env
from brdfbench.plugins import registry
from brdfbench.testing.kit import reference_material

RESOLUTION, SPP = 256, 16
CASES = ("roughconductor", "merl", "merl_trilinear", "nbrdf", "naive_mlp", "tripleplane", "triplane_gated", "ggx",
         "cook_torrance", "lambert")
INTEGRATORS = ("path", "direct_mis")
ROUNDS, CYCLES = 5, 6

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")


@pytest.fixture(scope="module")
def mb():
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        from brdfbench.render import mitsuba_bsdf

        mitsuba_bsdf.register_plugins()
        yield mitsuba_bsdf
        mitsuba_bsdf.forget_models()


@pytest.fixture(scope="module")
def bsdfs(mb) -> dict[str, dict]:
    """Mitsuba's rough conductor, and adapters of models of the reference material (the
    MLPs with Glorot weights, the triplane models with random textures: their cost does not
    depend on the values)."""
    from brdfbench.nbrdf import network as nw

    out = {"roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}}
    for name in CASES[1:]:
        rep = "merl" if name == "merl_trilinear" else name
        spec = registry.get("representations", rep)
        if name in ("nbrdf", "naive_mlp"):
            model = spec.create()
            model.weights = nw.glorot_init(model.hidden, torch.Generator().manual_seed(0))
        elif name in ("tripleplane", "triplane_gated"):  # random textures: the cost does not depend on them
            model = spec.create()
            g = torch.Generator().manual_seed(0)
            state = {k: torch.randn(s, generator=g) * 0.1 for k, s in model.shape.tensor_shapes().items()}
            for tex in ("h", "d") if model.shape.warps else ():
                state[f"warp_{tex}_alpha"] = torch.linspace(0.8, 1.2, model.shape.warps)
                state[f"warp_{tex}_weight"] = torch.full((model.shape.warps,), 1.0 / model.shape.warps)
            model = type(model).from_state(model.params, state, {})
        elif name == "merl_trilinear":
            model = spec.create(mode="trilinear").fit(reference_material())
        elif name in ("merl", "lambert"):
            model = spec.create().fit(reference_material())
        else:
            model = spec.create(n_samples=512, restarts=1).fit(reference_material())
        out[name] = mb.bsdf_dict(model, rep_name=rep)
    return out


def _scene(mb, bsdf: dict, integrator: str):
    scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=RESOLUTION, spp=SPP, integrator=integrator))
    mb.render(scene)  # compiles (or loads) the kernel
    return scene


def _rate(seconds: float) -> float:
    return RESOLUTION * RESOLUTION * SPP / seconds / 1e6


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("name", CASES)
def test_render_throughput(benchmark, mb, bsdfs, name, integrator):
    scene = _scene(mb, bsdfs[name], integrator)
    seeds = iter(range(1, 1000))
    benchmark.pedantic(lambda: mb.render(scene, seed=next(seeds)), rounds=ROUNDS, iterations=1)
    if benchmark.enabled:  # disabled (the default test run): one render, no statistics
        benchmark.extra_info["msamples_per_s"] = round(_rate(benchmark.stats.stats.min), 2)
    scene = None  # drop the scene (the lambda holds it) before collecting
    gc.collect()


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_throughput_ratios(benchmark, mb, bsdfs, integrator):
    cycles, rounds = (CYCLES, ROUNDS) if benchmark.enabled else (1, 2)  # disabled: a smoke run

    def sweep() -> dict[str, float]:
        best = {name: float("inf") for name in CASES}
        for _ in range(cycles):
            for name in CASES:
                scene = _scene(mb, bsdfs[name], integrator)
                for seed in range(1, rounds):
                    start = time.perf_counter()
                    mb.render(scene, seed=seed)
                    best[name] = min(best[name], time.perf_counter() - start)
                del scene
                gc.collect()
        return best

    best = benchmark.pedantic(sweep, rounds=1, iterations=1)
    rates = {name: _rate(seconds) for name, seconds in best.items()}
    print(f"\n{integrator}: M samples/s (x roughconductor, x merl)")
    for name, rate in rates.items():
        to_rc, to_merl = rate / rates["roughconductor"], rate / rates["merl"]
        benchmark.extra_info[name] = {"msamples_per_s": round(rate, 2), "x_roughconductor": round(to_rc, 3),
                                      "x_merl": round(to_merl, 3)}
        print(f"  {name:15s} {rate:6.1f}   {to_rc:5.2f}   {to_merl:5.2f}")
