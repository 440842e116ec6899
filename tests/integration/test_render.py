"""Scenes, the camera and sphere geometry against Mitsuba, the closed form against
analytic radiance, and the render harness in the runner."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import mitsuba_env, scenes
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError, RenderError
from brdfbench.render import sphere
from brdfbench.render.camera import Camera
from brdfbench.render.closed_form import ClosedForm
from brdfbench.render.build import build_simulator
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.plugins.specs import RepresentationSpec
from brdfbench.store.sqlite import ResultsStore
from brdfbench_representations.lambert import Lambert

needs_llvm = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")


# --------------------------------------------------------------------------- scenes


def test_each_scene_gets_the_cheapest_exact_simulator():
    assert scenes.brdf_space().simulator() == "brdf_space"
    assert scenes.sphere_directional().simulator() == "closed_form"
    assert scenes.sphere_envmap().simulator() == "direct_mis"
    assert scenes.spheres_on_plane().simulator() == "path"
    # a convex object sees no other surface: environment plus directional lights is still direct lighting
    assert scenes.sphere_envmap(lights=[{"direction": [0, -1, 0]}]).simulator() == "direct_mis"
    assert scenes.sphere_directional().allowed_simulators() == ("closed_form", "path")
    assert scenes.spheres_on_plane().allowed_simulators() == ("path",)


@pytest.mark.parametrize("factory, params, match", [
    (scenes.sphere_directional, {"width": 0}, "scene.params.width=0"),
    (scenes.sphere_directional, {"fov": 190}, "scene.params.fov=190"),
    (scenes.sphere_directional, {"distance": 0.5}, "scene.params.distance=0.5"),
    (scenes.sphere_directional, {"lights": [{"direction": [0, 0, 0]}]}, r"lights\[0\].direction must not be zero"),
    (scenes.sphere_directional, {"lights": [{"direction": [0, 0, -1], "irradiance": -1}]}, "non-negative"),
    (scenes.sphere_directional, {"lights": [{"dir": [0, 0, -1]}]}, r"lights\[0\]"),
    (scenes.sphere_directional, {"lights": [{"direction": "up"}]}, r"lights\[0\].direction='up'"),
    (scenes.sphere_envmap, {"envmap": "/no/such/sky.exr"}, "/no/such/sky.exr"),
    (scenes.sphere_envmap, {"spp": 0}, "scene.params.spp=0"),
    (scenes.spheres_on_plane, {"xml": "/no/such/scene.xml"}, "/no/such/scene.xml"),
])
def test_bad_scene_params_name_the_key(factory, params, match):
    with pytest.raises(ConfigError, match=match):
        factory(**params)


def test_a_simulator_that_is_not_exact_for_the_scene_is_refused():
    with pytest.raises(ConfigError, match="harness.simulator='closed_form' cannot render scene 'sphere_envmap'"):
        build_simulator(scenes.sphere_envmap(), name="closed_form")
    with pytest.raises(ConfigError, match="'direct_mis' cannot render scene 'spheres_on_plane'"):
        build_simulator(scenes.spheres_on_plane(), name="direct_mis")


# --------------------------------------------------------------------------- camera and sphere against Mitsuba


@needs_llvm
def test_camera_rays_are_mitsubas_rays():
    cam = Camera(width=64, height=40, fov=35.0, origin=(1.0, 2.0, 5.0), target=(0.1, -0.2, 0.0), up=(0.0, 1.0, 0.0))
    film = torch.rand(500, 2, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    _, d = cam.rays(film)
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        sensor = mi.load_dict(cam.mitsuba_dict(spp=1))
        f = film.numpy().astype(np.float32)
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(f[:, 0], f[:, 1]), mi.Point2f(0.5, 0.5))
        md = np.stack([np.asarray(ray.d.x), np.asarray(ray.d.y), np.asarray(ray.d.z)], axis=1)
    np.testing.assert_allclose(d.numpy(), md, atol=2e-6)


@needs_llvm
def test_sphere_hits_and_shading_frames_are_mitsubas():
    g = torch.Generator().manual_seed(2)
    origin = torch.tensor([0.2, -0.3, 5.0], dtype=torch.float64).expand(400, 3)
    target = (torch.rand(400, 3, generator=g, dtype=torch.float64) - 0.5) * 1.6
    direction = (target - origin) / (target - origin).norm(dim=-1, keepdim=True)
    t, hit = sphere.intersect(origin, direction)
    assert hit.float().mean() > 0.5
    o, d = origin[hit], direction[hit]
    n = (o + t[hit, None] * d)
    frame = sphere.shading_frame(n / n.norm(dim=-1, keepdim=True))
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        scene = mi.load_dict({"type": "scene", "sphere": {"type": "sphere"}})
        of, df = o.numpy().astype(np.float32), d.numpy().astype(np.float32)
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*of.T), mi.Vector3f(*df.T)))
        mt = np.asarray(si.t)
        ms = np.stack([np.asarray(si.sh_frame.s.x), np.asarray(si.sh_frame.s.y), np.asarray(si.sh_frame.s.z)], 1)
        mn = np.stack([np.asarray(si.sh_frame.n.x), np.asarray(si.sh_frame.n.y), np.asarray(si.sh_frame.n.z)], 1)
    np.testing.assert_allclose(t[hit].numpy(), mt, rtol=1e-5)
    np.testing.assert_allclose(frame[:, 2].numpy(), mn, atol=1e-5)
    np.testing.assert_allclose(frame[:, 0].numpy(), ms, atol=1e-4)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1))
def test_shading_frames_are_orthonormal_everywhere_including_the_poles(x, y, z):
    n = torch.tensor([[x, y, z]], dtype=torch.float64)
    if float(n.norm()) < 1e-6:
        return
    n = n / n.norm()
    f = sphere.shading_frame(n)[0]
    assert torch.allclose(f @ f.T, torch.eye(3, dtype=torch.float64), atol=1e-9)
    assert torch.allclose(f[2], n[0])
    assert float(torch.det(f)) == pytest.approx(1.0, abs=1e-9)  # right-handed, as Mitsuba's


# --------------------------------------------------------------------------- closed form


def test_closed_form_matches_the_analytic_lambertian_sphere():
    """Radiance of a Lambertian sphere at a pixel fully inside it is ρ/π · E · max(0, n·l)."""
    scene = scenes.sphere_directional(width=33, height=33, supersample=1,
                                      lights=[{"direction": [-0.3, -0.5, -1.0], "irradiance": [2.0, 1.0, 0.5]}])
    model = Lambert()
    model.albedo = torch.tensor([0.8, 0.4, 0.2], dtype=torch.float64)
    image = ClosedForm(scene, dtype=torch.float64).render(model).double()
    # the same pixels' rays, hit points and normals, independently
    film = scene.camera.stratified_film(1)
    o, d = scene.camera.rays(film)
    t, hit = sphere.intersect(o, d)
    n = o + t[:, None] * d
    light = -torch.tensor([-0.3, -0.5, -1.0], dtype=torch.float64)
    cos = (n @ (light / light.norm())).clamp_min(0)
    expected = torch.tensor([0.8, 0.4, 0.2], dtype=torch.float64) / math.pi * torch.tensor([2.0, 1.0, 0.5], dtype=torch.float64) * cos[:, None]
    expected = torch.where(hit[:, None], expected, 0.0).reshape(33, 33, 3)
    torch.testing.assert_close(image, expected.float().double(), atol=1e-6, rtol=1e-6)
    assert image[0, 0].abs().sum() == 0  # the corner misses the sphere


class NaNInside(Lambert):
    """Returns NaN where ωo leans along +t: a broken plugin the renderer must not hide."""

    def _eval(self, wi, wo):
        out = super()._eval(wi, wo)
        return torch.where((wo[:, 1] > 0.3)[:, None], torch.nan, out)


def test_a_nan_inside_a_render_is_reported_with_the_material():
    scene = scenes.sphere_directional(width=24, height=24, supersample=1)
    with pytest.raises(RenderError, match=r"closed_form render of nan_inside on material gold-ish: \d+ of 576 pixels are NaN/Inf"):
        ClosedForm(scene).render(NaNInside(), material="gold-ish", label="nan_inside")


# --------------------------------------------------------------------------- the harness in the runner

RENDER = harness_config(kind="render", metrics=("psnr_ldr", "ssim_ldr", "flip_ldr", "rmse_hdr"))


def _cfg(tmp_path, synthetic_cache, name="lambert", **kw):
    return RunConfig(
        representation=name, representation_params={}, label=name, dataset="synthetic",
        dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, results_dir=tmp_path,
        limit=2, **kw,
    )


def test_render_harness_writes_image_metrics_and_images(tmp_path, synthetic_cache):
    cfg = _cfg(tmp_path, synthetic_cache, harness=RENDER, scene="sphere_directional",
               scene_params={"width": 48, "height": 48, "supersample": 2})
    counts = run(cfg)
    assert counts == {"done": 2, "skipped": 0, "failed": 0}
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert set(df.scene) == {"sphere_directional"}
    psnr = df[df.metric == "psnr_ldr"]
    assert len(psnr) == 2 and (psnr.unit == "dB").all() and psnr.higher_is_better.all()
    assert set(df.metric) >= {"psnr_ldr", "ssim_ldr", "flip_ldr", "rmse_hdr", "render_time", "render_samples_per_s"}
    exrs = sorted(p.relative_to(tmp_path).parts[-2].split("-")[0] for p in (tmp_path / "renders").rglob("*.exr"))
    assert exrs == ["lambert", "lambert", "reference", "reference"]  # lambert-<config hash>/, reference/
    assert len(list((tmp_path / "renders").rglob("*.png"))) == 4
    # another scene is another cell, not a skip; the same scene again is skipped
    assert run(_cfg(tmp_path, synthetic_cache, harness=RENDER, scene="sphere_directional",
                    scene_params={"width": 40, "height": 40, "supersample": 1}))["done"] == 2
    assert run(cfg)["skipped"] == 2


def test_merl_renders_its_own_reference_exactly(tmp_path, synthetic_cache):
    run(_cfg(tmp_path, synthetic_cache, "merl", harness=RENDER, scene="sphere_directional",
             scene_params={"width": 32, "height": 32, "supersample": 1}))
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert (df[df.metric == "rmse_hdr"].value == 0).all()
    assert (df[df.metric == "flip_ldr"].value == 0).all()


@pytest.mark.parametrize("harness, scene, match", [
    (harness_config(), "sphere_directional", "scene 'sphere_directional' is rendered: use harness=render"),
    (RENDER, "brdf_space", "harness=render needs a rendered scene"),
    (harness_config(metrics=("l1", "psnr_ldr")), "brdf_space", "'psnr_ldr' is measured on 'image'"),
    (harness_config(kind="render", metrics=("psnr_ldr", "l1_log")), "sphere_directional", "'l1_log' is measured on 'merl_grid'"),
])
def test_metrics_that_do_not_fit_the_harness_or_scene_stop_the_run_up_front(tmp_path, synthetic_cache, harness, scene, match):
    with pytest.raises(ConfigError, match=match):
        run(_cfg(tmp_path, synthetic_cache, harness=harness, scene=scene))
    assert not (tmp_path / "renders").exists()


def test_an_unknown_harness_kind_lists_the_harnesses():
    with pytest.raises(ConfigError, match="harness.kind 'sideways'.*Registered: accuracy, convergence, generation, render"):
        harness_config(kind="sideways")


def test_unknown_scene_params_are_refused(tmp_path, synthetic_cache):
    with pytest.raises(ConfigError, match="unknown key scene.params.colour"):
        run(_cfg(tmp_path, synthetic_cache, harness=RENDER, scene="sphere_directional", scene_params={"colour": 1}))


@pytest.fixture
def nan_plugin():
    spec = RepresentationSpec(name="nan_inside", description="test", target=f"{__name__}:NaNInside", tags=Lambert.tags)
    registry.register("representations", spec)
    yield "nan_inside"
    registry.unregister("representations", "nan_inside")


def test_a_nan_render_is_a_recorded_failure_naming_the_material(tmp_path, synthetic_cache, nan_plugin):
    counts = run(_cfg(tmp_path, synthetic_cache, nan_plugin, harness=RENDER, scene="sphere_directional",
                      scene_params={"width": 24, "height": 24, "supersample": 1}))
    assert counts["failed"] == 2
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    for material, message in zip(df.material, df.message):
        assert material in message and ("NaN/Inf" in message or "non-finite" in message)


# --------------------------------------------------------------------------- bad scene input


@pytest.mark.parametrize("text, match", [
    ("<scene version='3.0.0'><shape type='sphere'>", "not a well-formed XML scene"),
    ("<?xml version='1.0'?><bsdf type='diffuse'/>", r"root element is <bsdf>"),
    ("<scene version='3.0.0'><shape type='sphere'/></scene>", r'declares no <bsdf type="\$bsdf" id="material">'),
])
def test_a_broken_xml_scene_is_refused_naming_the_file(tmp_path, text, match):
    path = tmp_path / "mine.xml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        build_simulator(scenes.spheres_on_plane(xml=str(path)))
    assert str(path) in str(info.value)


@needs_llvm
def test_an_xml_scene_mitsuba_cannot_load_names_the_file(tmp_path):
    path = tmp_path / "typo.xml"
    path.write_text((scenes.XML_DIR / "spheres_on_plane.xml").read_text().replace('type="rectangle"', 'type="rectangel"'))
    sim = build_simulator(scenes.spheres_on_plane(xml=str(path), width=16, height=12, spp=1))
    with pytest.raises(ConfigError, match=f"{path}: cannot load this Mitsuba scene"):
        sim.render(Lambert(), material="m")


def test_an_exr_that_is_not_an_environment_map_is_refused(tmp_path):
    from brdfbench.errors import DataError
    from brdfbench.images import write_exr

    path = tmp_path / "portrait.exr"
    write_exr(path, torch.ones(40, 30, 3))
    with pytest.raises(DataError, match="portrait.exr"):
        build_simulator(scenes.sphere_envmap(envmap=str(path)))


@needs_llvm
def test_the_xml_scene_renders_every_kind_of_kernel():
    """Table gather, analytic and neural representations all render in the XML scene."""
    from brdfbench_representations.nbrdf import NBRDF

    scene = scenes.spheres_on_plane(width=24, height=18, spp=4)
    sim = build_simulator(scene)
    for model in (_lambert_model(), NBRDF()):
        if isinstance(model, NBRDF):
            from brdfbench.nbrdf.network import glorot_init

            model.weights = glorot_init(model.hidden, torch.Generator().manual_seed(0))
        image = sim.render(model, material="m")
        assert image.shape == (18, 24, 3) and bool(torch.isfinite(image).all()) and float(image.max()) > 0


def _lambert_model() -> Lambert:
    m = Lambert()
    m.albedo = torch.tensor([0.6, 0.5, 0.4], dtype=torch.float64)
    return m


@needs_llvm
@pytest.mark.parametrize("scene", [scenes.sphere_envmap(width=24, height=24, spp=8),
                                   scenes.sphere_directional(width=24, height=24)], ids=["envmap", "directional"])
def test_a_reused_scene_renders_what_a_fresh_one_renders(scene, small_dataset):
    """The Mitsuba simulators keep the loaded scene and swap the model in: no other change."""
    from brdfbench.harness.render import TableReference

    table = TableReference(small_dataset.load(small_dataset.materials[0]))
    warm = build_simulator(scene)
    warm.render(table, seed=5)
    reused = warm.render(_lambert_model(), seed=5)
    fresh = build_simulator(scene).render(_lambert_model(), seed=5)
    assert torch.equal(reused, fresh)
    assert not torch.equal(warm.render(table, seed=5), reused)


def test_two_configurations_of_one_label_keep_their_images_apart(tmp_path, synthetic_cache):
    """A sweep of one plugin's parameters shares the label; each configuration saves its own renders."""
    from dataclasses import replace

    base = _cfg(tmp_path, synthetic_cache, "merl", harness=RENDER, scene="sphere_directional",
                scene_params={"width": 16, "height": 16, "supersample": 1})
    run(base)
    run(replace(base, representation_params={"mode": "trilinear"}))
    folders = {p.parent.name for p in (tmp_path / "renders").rglob("*.exr") if p.parent.name != "reference"}
    assert len(folders) == 2 and all(f.startswith("merl-") for f in folders)
