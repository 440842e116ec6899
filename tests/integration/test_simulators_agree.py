"""The cheap simulators agree with Mitsuba's path tracer where both apply, within Monte
Carlo error; the Mitsuba and torch backends of each cheap simulator agree with each other.

Agreement is tested on 8×8-pixel blocks of pixels the sphere covers entirely (the closed
form's strata and the path tracer's box filter differ only at the silhouette): each
block's mean over K independently seeded renders against the other simulator's, by
Welch's t-test (one-sample t-test against the noise-free closed form), at family-wise
significance 0.01 with the Šidák correction over blocks × channels.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import stats

from brdfbench import mitsuba_env, scenes
from brdfbench.render.camera import Camera
from brdfbench.render.build import build_simulator
from brdfbench.render.simulator import sphere_hits
from brdfbench_representations.analytic import GGX
from brdfbench_representations.lambert import Lambert

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
SIGNIFICANCE = 0.01
BLOCK = 8
SIZE = 48
SEEDS = 8


def _interior(camera: Camera, strata: int = 4) -> torch.Tensor:
    """(H, W) mask of pixels whose every stratum hits the sphere."""
    hits = sphere_hits(camera, camera.stratified_film(strata))
    count = torch.zeros(camera.width * camera.height * strata * strata)
    count[hits.index] = 1
    return count.reshape(camera.height, camera.width, -1).all(dim=-1)


def _blocks(image: torch.Tensor, mask: torch.Tensor) -> np.ndarray:
    """(n_blocks, 3) means of the fully interior BLOCK×BLOCK blocks."""
    h, w = mask.shape
    out = []
    for y in range(0, h - BLOCK + 1, BLOCK):
        for x in range(0, w - BLOCK + 1, BLOCK):
            if bool(mask[y:y + BLOCK, x:x + BLOCK].all()):
                out.append(image[y:y + BLOCK, x:x + BLOCK].reshape(-1, 3).mean(0).numpy())
    return np.array(out)


def _renders(simulator, model, seeds=SEEDS, base=1000) -> list[torch.Tensor]:
    return [simulator.render(model, seed=base + s, material="test") for s in range(seeds)]


def _sidak(p: np.ndarray) -> float:
    return 1 - (1 - SIGNIFICANCE) ** (1 / p.size)


def _ggx() -> GGX:
    return GGX().set_coefficients(kd=[0.2, 0.5, 0.3], ks=[0.4, 0.4, 0.4], alpha=[0.25])


def _lambert() -> Lambert:
    m = Lambert()
    m.albedo = torch.tensor([0.8, 0.5, 0.3], dtype=torch.float64)
    return m


@pytest.mark.parametrize("model", [_lambert, _ggx], ids=["lambert", "ggx"])
def test_closed_form_agrees_with_the_path_tracer(model):
    scene = scenes.sphere_directional(width=SIZE, height=SIZE, supersample=4)
    exact = build_simulator(scene).render(model(), material="test")
    noisy = _renders(build_simulator(scene, name="path", spp=64), model())
    mask = _interior(scene.camera)
    ref = _blocks(exact, mask)
    samples = np.stack([_blocks(img, mask) for img in noisy])  # (K, blocks, 3)
    assert ref.shape[0] >= 9
    p = stats.ttest_1samp(samples, ref, axis=0).pvalue
    assert p.min() > _sidak(p), f"min p={p.min():.3g}, level {_sidak(p):.3g}"


SUN = [{"direction": [-0.3, -1.0, -0.5], "irradiance": [2.0, 1.8, 1.5]}]


@pytest.mark.parametrize("lights", [[], SUN], ids=["environment", "environment+sun"])
@pytest.mark.parametrize("model", [_lambert, _ggx], ids=["lambert", "ggx"])
def test_direct_mis_agrees_with_the_path_tracer(model, lights):
    """Independent seeds: the path tracer samples one emitter per bounce where direct MIS
    takes the environment sample and every directional light in closed form."""
    scene = scenes.sphere_envmap(width=SIZE, height=SIZE, spp=64, lights=lights)
    mask = _interior(scene.camera)
    a = np.stack([_blocks(img, mask) for img in _renders(build_simulator(scene), model())])
    b = np.stack([_blocks(img, mask) for img in _renders(build_simulator(scene, name="path"), model(), base=5000)])
    p = stats.ttest_ind(a, b, axis=0, equal_var=False).pvalue
    assert p.min() > _sidak(p), f"min p={p.min():.3g}, level {_sidak(p):.3g}"


def test_direct_mis_is_the_path_tracers_estimator_without_its_rays():
    """Under the environment alone, Mitsuba's path tracer at max_depth 2 draws the same
    numbers in the same order (environment, then BSDF) and weights them by the same power
    heuristic; for a convex object its shadow ray and second ray change nothing. So at one
    seed the two images agree pixel by pixel: direct MIS only skips the tracing."""
    scene = scenes.sphere_envmap(width=SIZE, height=SIZE, spp=16)
    a = build_simulator(scene).render(_ggx(), seed=7)
    b = build_simulator(scene, name="path").render(_ggx(), seed=7)
    assert float(a.mean()) > 0.01
    torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-4)


def test_a_biased_simulator_is_caught():
    """The negative control: 3 % more light in the closed form is rejected."""
    scene = scenes.sphere_directional(width=SIZE, height=SIZE, supersample=4)
    exact = build_simulator(scene).render(_lambert(), material="test") * 1.03
    mask = _interior(scene.camera)
    samples = np.stack([_blocks(img, mask) for img in _renders(build_simulator(scene, name="path", spp=64), _lambert())])
    p = stats.ttest_1samp(samples, _blocks(exact, mask), axis=0).pvalue
    assert p.min() < _sidak(p)


@pytest.mark.parametrize("model", [_lambert, _ggx], ids=["lambert", "ggx"])
def test_closed_form_backends_agree_to_fp32(model):
    scene = scenes.sphere_directional(width=SIZE, height=SIZE, supersample=2)
    a = build_simulator(scene, backend="mitsuba").render(model())
    b = build_simulator(scene, backend="torch").render(model())
    torch.testing.assert_close(a, b, atol=2e-4, rtol=2e-3)


def test_direct_mis_backends_agree_within_monte_carlo_error():
    scene = scenes.sphere_envmap(width=SIZE, height=SIZE, spp=32)
    mask = _interior(scene.camera)
    a = np.stack([_blocks(img, mask) for img in _renders(build_simulator(scene, backend="mitsuba"), _ggx())])
    b = np.stack([_blocks(img, mask) for img in _renders(build_simulator(scene, backend="torch"), _ggx(), seeds=4)])
    p = stats.ttest_ind(a, b, axis=0, equal_var=False).pvalue
    assert p.min() > _sidak(p), f"min p={p.min():.3g}, level {_sidak(p):.3g}"


@pytest.mark.parametrize("kind", ["closed_form", "direct_mis"])
def test_the_direct_bsdf_call_renders_as_the_virtual_call(kind, monkeypatch, fitted):
    """A one-shape scene calls its BSDF directly (no dispatch); forcing Mitsuba's per-lane
    virtual call instead renders the same image, for a table, an MLP and an analytic model."""
    from brdfbench.render import mitsuba_integrators

    table, mlp = fitted("merl"), fitted("nbrdf", epochs=1, n_samples=20_000)
    scene = (scenes.sphere_directional(width=SIZE, height=SIZE, supersample=2) if kind == "closed_form"
             else scenes.sphere_envmap(width=SIZE, height=SIZE, spp=8, lights=SUN))
    models = {"merl": table, "nbrdf": mlp, "ggx": _ggx()}
    direct = {name: build_simulator(scene, name=kind).render(m, seed=3) for name, m in models.items()}
    monkeypatch.setattr(mitsuba_integrators, "scene_bsdf", lambda scene, si, ray: si.bsdf(ray))
    for name, m in models.items():
        virtual = build_simulator(scene, name=kind).render(m, seed=3)
        assert float(virtual.mean()) > 0.001, name
        torch.testing.assert_close(direct[name], virtual, atol=1e-6, rtol=1e-5, msg=name)
