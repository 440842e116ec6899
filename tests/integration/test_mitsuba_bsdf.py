"""The Mitsuba 3 BSDF adapter: every representation renders, native kernels equal the torch path."""

from __future__ import annotations

import functools
import gc
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch
from brdfbench_representations.lambert import Lambert

from brdfbench import mitsuba_env, modelio
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError, ModelFileError, RenderError
from brdfbench.sampling.builtin import Cosine
from brdfbench.plugins.specs import RepresentationSpec, SamplerSpec
from brdfbench.testing.kit import reference_material

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")

#: Built-ins that must render through a native drjit kernel.
LITERATURE = ("phong", "blinn_phong_ngan", "ward", "ward_duer", "lafortune", "lafortune2", "lafortune3",
              "ashikhmin_shirley", "ashikhmin_shirley_ior", "cook_torrance_beckmann", "cook_torrance_1982",
              "low_smooth", "low_microfacet", "sgd", "he")
NATIVE = ("merl", "pca", "lambert", "blinn_phong", "cook_torrance", "ggx", "nbrdf", "naive_mlp", "tripleplane",
          "triplane_gated", "published_fit", *LITERATURE)
#: Cheap fitting parameters: the adapter is under test here, not the fit.
CHEAP = {
    "blinn_phong": {"n_samples": 512, "restarts": 1},
    "cook_torrance": {"n_samples": 512, "restarts": 1},
    "ggx": {"n_samples": 512, "restarts": 1},
    "pca": {"k": 2},
    **{name: {"n_samples": 512, "restarts": 1} for name in LITERATURE},
    "published_fit": {"source": "bagher_sgd", "material": "alum-bronze"},
}
SAMPLERS = {
    "uniform": {}, "cosine": {}, "power_cosine": {"exponent": 20.0}, "blinn_phong": {"exponent": 50.0},
    "beckmann": {"alpha": 0.3}, "ggx": {"alpha": 0.3}, "ggx_vndf": {"alpha": 0.3},
    "ward": {"alpha_x": 0.2, "alpha_y": 0.45}, "ashikhmin_shirley": {"nu": 30.0, "nv": 300.0},
    "phong": {"exponent": 20.0}, "lafortune": {"cxy": -0.8, "cz": 0.6, "exponent": 20.0},
}


@pytest.fixture(scope="module")
def mi():
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        from brdfbench.render import mitsuba_bsdf

        mitsuba_bsdf.register_plugins()
        yield mi


@pytest.fixture(scope="module")
def mb(mi):
    from brdfbench.render import mitsuba_bsdf

    return mitsuba_bsdf


def random_mlp(model, seed: int):
    """An NBRDF-style model with random weights (positive outputs): no fit needed."""
    from brdfbench.nbrdf import network as nw

    weights = nw.glorot_init(model.hidden, torch.Generator().manual_seed(seed))
    weights[f"b{len(model.hidden) + 1}"] += 1.0
    model.weights = weights
    return model


def darker_material():
    """Synthetic material 1 at half the reflectance: a second material without generating one."""
    from brdfbench.merl import MerlTable

    ref = reference_material()
    return type(ref)(name="darker", table=MerlTable(ref.table.raw * 0.5), category=ref.category)


def make_model(fitted, name: str):
    """A model of `name` fitted to synthetic material 1 (the session's shared fit; neural
    ones: random weights, the adapter is under test here, not the fit)."""
    if name in ("nbrdf", "naive_mlp", "tripleplane", "triplane_gated"):
        return _random(name)
    return fitted(name, train=[reference_material(), darker_material()], **CHEAP.get(name, {}))


def random_tripleplane(model, seed: int):
    """A tripleplane with random textures and decoder (varied outputs): no fit needed. The
    textures vary by 0.1 between nodes, as smooth as a fitted one's; rougher ones turn fp32
    rounding of the read coordinates into larger differences than the test allows."""
    g = torch.Generator().manual_seed(seed)
    state = {k: torch.randn(s, generator=g) * (0.1 if k in ("H", "D", "D_pole") else 0.5)
             for k, s in model.shape.tensor_shapes().items()}
    for tex in ("h", "d") if model.shape.warps else ():  # triplane_gated: valid warps
        state[f"warp_{tex}_alpha"] = torch.linspace(0.6, 1.8, model.shape.warps)
        state[f"warp_{tex}_weight"] = torch.full((model.shape.warps,), 1.0 / model.shape.warps)
    return type(model).from_state(model.params, state, {})


@functools.lru_cache(maxsize=None)
def _random(name: str):
    model = registry.get("representations", name).create()
    if name in ("tripleplane", "triplane_gated"):
        return random_tripleplane(model, seed=len(name))
    return random_mlp(model, seed=len(name))


def directions(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Random (light, view) pairs, fp32; a tenth of each below the horizon."""
    g = torch.Generator().manual_seed(seed)
    light, view = (torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=1) for _ in range(2))
    light[:, 2] = light[:, 2].abs()
    view[:, 2] = view[:, 2].abs()
    light[::10, 2] *= -1
    view[5::10, 2] *= -1
    return light.float(), view.float()


def vec(mi, t: torch.Tensor):
    return mi.Vector3f(*(mi.Float(t[:, c].numpy().copy()) for c in range(3)))


def arr(v) -> np.ndarray:
    return np.stack([np.asarray(v[c]) for c in range(3)], axis=1)


def adapter_eval(mi, bsdf, light, view, mode=None):
    """bsdf.eval with si.wi = the viewer and wo = the light (radiance transport)."""
    si = mi.SurfaceInteraction3f()
    si.wi = vec(mi, view)
    ctx = mi.BSDFContext() if mode is None else mi.BSDFContext(mode)
    return arr(bsdf.eval(ctx, si, vec(mi, light)))


# --------------------------------------------------------------------------- eval


#: JIT compilation of the model's kernel takes half a minute here: the He kernel's agreement
#: with its torch twin is tested in test_he_model, and the adapter path by every other model
SLOW_EVAL = {"he"}


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW_EVAL else [])
                                  for n in registry.names("representations")])
def test_eval_matches_model(mi, mb, name, record_property, fitted):
    model = make_model(fitted, name)
    light, view = directions(4096, seed=1)
    expected = (model.eval(light, view) * light[:, 2:3]).numpy()
    native = mb.load_dict(mb.bsdf_dict(model, rep_name=name, material=f"test-{name}"))
    via_torch = mb.load_dict(mb.bsdf_dict(model, rep_name=name, kernel="torch"))
    record_property("kernel_path", native.adapter.kernel_path)
    print(f"{name}: kernel path {native.adapter.kernel_path}")
    if name in NATIVE:
        assert native.adapter.kernel_path == "native"
    np.testing.assert_allclose(adapter_eval(mi, native, light, view), expected, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(adapter_eval(mi, via_torch, light, view), expected, rtol=1e-6, atol=0)
    below = (light[:, 2] <= 0) | (view[:, 2] <= 0)
    assert not adapter_eval(mi, native, light, view)[below.numpy()].any()


def test_merl_kernel_picks_the_reference_cells(mi):
    from brdfbench import merl
    from brdfbench.render.drjit_kernels import merl_indices
    from brdfbench.testing import adversarial_pairs

    # Every family but ωi = ωo exactly, where φd is rounding noise in the reference too.
    pairs = [p for fam, p in adversarial_pairs(70_000, torch.float64, seed=3).items() if fam != "identical"]
    pairs.append(tuple(d[::5] for d in merl.grid_directions(torch.float64)))  # every 5th cell centre
    for wi, wo in pairs:
        wi, wo = wi.float(), wo.float()
        got = merl_indices(vec(mi, wi), vec(mi, wo))
        for ref, idx in zip(merl.cell_indices(wi, wo), got):
            assert np.array_equal(ref.numpy(), np.asarray(idx))


def test_importance_transport_swaps_the_roles(mi, mb, fitted):
    model = make_model(fitted, "naive_mlp")  # not reciprocal: the roles matter
    light, view = directions(512, seed=2)
    bsdf = mb.load_dict(mb.bsdf_dict(model, rep_name="naive_mlp"))
    got = adapter_eval(mi, bsdf, view, light, mode=mi.TransportMode.Importance)  # si.wi = light, wo = view
    np.testing.assert_allclose(got, (model.eval(light, view) * view[:, 2:3]).numpy(), rtol=2e-5, atol=1e-6)


# --------------------------------------------------------------------------- samplers


@pytest.mark.parametrize("name", list(SAMPLERS))
def test_sampler_twin_matches_torch(mi, name):
    from brdfbench.render.drjit_samplers import sampler_for

    sampler = registry.get("samplers", name).create(**SAMPLERS[name])
    twin = sampler_for(sampler)
    assert twin is not None, f"no drjit twin for the built-in sampler {name!r}"
    g = torch.Generator().manual_seed(3)
    wi, _ = directions(4096, seed=4)
    wi[:, 2] = wi[:, 2].abs().clamp(min=0.01)
    wi = torch.nn.functional.normalize(wi, dim=1)
    u = torch.rand(4096, 2, generator=g)
    u[:8] = torch.tensor([[0.0, 0.0], [1.0, 1.0], [1.0 - 2**-24, 0.5], [0.5, 1.0 - 2**-24]]).repeat(2, 1)
    wo = sampler.sample(wi, u)
    got = arr(twin.sample(vec(mi, wi), mi.Point2f(mi.Float(u[:, 0].numpy().copy()), mi.Float(u[:, 1].numpy().copy()))))
    np.testing.assert_allclose(got, wo.numpy(), atol=2e-5)
    light, view = directions(4096, seed=5)
    for a, b in ((wi, wo), (view, light)):
        np.testing.assert_allclose(np.asarray(twin.pdf(vec(mi, a), vec(mi, b))), sampler.pdf(a, b).numpy(), rtol=1e-4, atol=1e-6)


def test_sample_weight_is_eval_over_pdf(mi, mb, fitted):
    model = make_model(fitted, "ggx")
    bsdf = mb.load_dict(mb.bsdf_dict(model, rep_name="ggx", sampler="ggx", sampler_params={"alpha": 0.3}))
    _, view = directions(2048, seed=6)
    si = mi.SurfaceInteraction3f()
    si.wi = vec(mi, view)
    u = torch.rand(2048, 2, generator=torch.Generator().manual_seed(7)).numpy()
    ctx = mi.BSDFContext()
    bs, weight = bsdf.sample(ctx, si, mi.Float(0.5), mi.Point2f(mi.Float(u[:, 0]), mi.Float(u[:, 1])))
    value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
    pdf, bs_pdf, weight, value = np.asarray(pdf), np.asarray(bs.pdf), arr(weight), arr(value)
    np.testing.assert_allclose(bs_pdf, pdf, rtol=1e-6)
    ok = pdf > 0
    assert ok.mean() > 0.5 and not weight[~ok].any()
    np.testing.assert_allclose(weight[ok], value[ok] / pdf[ok, None], rtol=1e-5, atol=1e-6)


# --------------------------------------------------------------------------- rendering


def render(mi, mb, bsdf: dict, **kw) -> np.ndarray:
    scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=kw.pop("resolution", 32), spp=kw.pop("spp", 4), **kw))
    return np.asarray(mb.render(scene))


@pytest.mark.parametrize("mode", ["nearest", "trilinear"])
def test_native_merl_render_equals_torch_path(mi, mb, mode, fitted):
    model = make_model(fitted, "merl") if mode == "nearest" else registry.get("representations", "merl").create(
        mode=mode).fit(reference_material())
    native = render(mi, mb, mb.bsdf_dict(model, rep_name="merl"))
    via_torch = render(mi, mb, mb.bsdf_dict(model, rep_name="merl", kernel="torch"))
    assert np.isfinite(native).all() and native.mean() > 0.01
    np.testing.assert_allclose(native, via_torch, rtol=1e-4, atol=1e-6)


class ThirdPartyCosine(Cosine):
    """A sampler without a drjit twin: the adapter calls it in torch."""


class Diffuse(Lambert):
    """A third-party representation named like Mitsuba's own `diffuse` plugin."""


def test_a_name_mitsuba_has_is_registered_with_a_prefix(mi, mb):
    registry.register("representations", RepresentationSpec(
        name="diffuse", description="test plugin", target=f"{__name__}:Diffuse", tags=Lambert.tags))
    try:
        with pytest.warns(UserWarning, match="named like Mitsuba's own plugin 'diffuse'.*'brdfbench_diffuse'"):
            mb.register_plugins()
        assert mb.plugin_name("diffuse") == "brdfbench_diffuse" and mb.plugin_name("lambert") == "lambert"
        model = Diffuse()
        model.albedo = torch.tensor([0.8, 0.4, 0.2], dtype=torch.float64)
        bsdf = mb.bsdf_dict(model, rep_name="diffuse")
        assert bsdf["type"] == "brdfbench_diffuse"
        loaded = mb.load_dict(bsdf)
        assert loaded.adapter.rep_name == "diffuse" and loaded.adapter.kernel_path == "torch"  # a subclass: no twin
        light, view = directions(64, seed=11)
        expected = (model.eval(light, view) * light[:, 2:3]).numpy()
        np.testing.assert_allclose(adapter_eval(mi, loaded, light, view), expected, rtol=2e-5, atol=1e-6)
    finally:
        registry.unregister("representations", "diffuse")


def test_third_party_sampler_renders_through_torch(mi, mb, fitted):
    registry.register("samplers", SamplerSpec(
        name="test_cosine", description="test plugin", target=f"{__name__}:ThirdPartyCosine"))
    try:
        bsdf = mb.bsdf_dict(make_model(fitted, "merl"), rep_name="merl", sampler="test_cosine")
        scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=16, spp=4))
        adapter = mb.adapters_in(scene)[0]
        assert (adapter.kernel_path, adapter.sampler_path) == ("native", "torch") and mb.needs_evaluated_mode(scene)
        native = render(mi, mb, mb.bsdf_dict(make_model(fitted, "merl"), rep_name="merl"), resolution=16, spp=4)
        np.testing.assert_allclose(np.asarray(mb.render(scene)), native, rtol=1e-4, atol=1e-6)
    finally:
        registry.unregister("samplers", "test_cosine")


def _render_kernel(mi, mb, bsdf: dict) -> tuple[str, bool]:
    """Hash of the render's largest JIT kernel and whether it came from a cache."""
    import drjit as dr

    gc.collect()  # a BSDF left alive would add a target to Mitsuba's calls: another kernel
    scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=16, spp=1))
    assert not mb.needs_evaluated_mode(scene)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory):
        mb.render(scene)
        history = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    del scene
    gc.collect()
    biggest = max(history, key=lambda k: k["operation_count"])
    return biggest["hash"], bool(biggest["cache_hit"])


@pytest.mark.parametrize("name", ["merl", "nbrdf", "ggx", "tripleplane", "triplane_gated"])
def test_second_material_reuses_the_kernel(mi, mb, name, fitted):
    first = make_model(fitted, name)
    if name in ("tripleplane", "triplane_gated"):
        second = random_tripleplane(type(first)(), seed=99)
    elif name == "merl":
        second = type(first)().fit(darker_material())
    elif name == "ggx":
        second = type(first)().set_coefficients(kd=0.1, ks=0.7, alpha=0.05, f0=0.9)
    else:
        second = random_mlp(type(first)(), seed=99)
    hash_a, _ = _render_kernel(mi, mb, mb.bsdf_dict(first, rep_name=name))
    hash_b, hit_b = _render_kernel(mi, mb, mb.bsdf_dict(second, rep_name=name))
    assert hash_a == hash_b and hit_b, "a second material of the same architecture compiled a new kernel"


class NanAtGrazing(Lambert):
    """Lambert that returns NaN for grazing light: a broken third-party plugin (torch path)."""

    def _eval(self, wi, wo):
        out = super()._eval(wi, wo)
        return torch.where((wi[:, 2] < 0.3)[:, None], torch.full_like(out, float("nan")), out)


class NanKernelLambert(Lambert):
    """The same fault in a third-party drjit kernel (the `drjit_kernel` hook, native path)."""

    def drjit_kernel(self):
        import drjit as dr
        import mitsuba as mi

        rho = dr.opaque(mi.Float, float(self.albedo[0]) / np.pi)

        class Kernel:
            name = "nan_kernel"

            def eval(self, wi, wo):
                v = dr.select(wi.z < 0.3, dr.nan, rho)
                return mi.Color3f(v, v, v)

        return Kernel()


@pytest.mark.parametrize("cls, path", [(NanAtGrazing, "torch"), (NanKernelLambert, "native")])
def test_non_finite_values_raise_render_error(mi, mb, cls, path):
    name = f"test_{cls.__name__.lower()}"
    registry.register("representations", RepresentationSpec(
        name=name, description="test plugin", target=f"{__name__}:{cls.__name__}", tags=Lambert.tags))
    try:
        mb.register_plugins()
        bsdf = mb.bsdf_dict(cls(), rep_name=name, material="broken-paint")
        scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=16, spp=2))
        assert mb.adapters_in(scene)[0].kernel_path == path
        assert mb.needs_evaluated_mode(scene) == (path == "torch")
        with pytest.raises(RenderError, match=f"material 'broken-paint' \\(representation '{name}'\\)"):
            mb.render(scene)
        image = np.asarray(mb.render(scene, check=False))
        assert np.isfinite(image).all() and image.mean() > 0
        with pytest.raises(RenderError, match="non-finite"):
            mb.check_finite(scene)
        mb.check_finite(scene)  # counters were reset
    finally:
        registry.unregister("representations", name)


def test_torch_path_outside_render_mode_says_what_to_do(mi, mb, fitted):
    import drjit as dr

    bsdf = mb.bsdf_dict(make_model(fitted, "lambert"), rep_name="lambert", kernel="torch")
    scene = mb.load_dict(mb.sphere_scene(bsdf, resolution=8, spp=1))
    assert mb.needs_evaluated_mode(scene)
    with pytest.raises(Exception) as info:  # Mitsuba wraps it; the cause is ours
        dr.eval(mi.render(scene))
    cause = info.value
    while cause is not None and not isinstance(cause, RenderError):
        cause = cause.__cause__ or cause.__context__
    assert cause is not None and "render_mode" in str(cause)


# --------------------------------------------------------------------------- properties


def test_filename_loads_a_saved_model(mi, mb, tmp_path, fitted):
    model = make_model(fitted, "ggx")
    path = modelio.save(model, "ggx", tmp_path / "copper.safetensors")
    bsdf = mb.load_dict({"type": "ggx", "filename": str(path), "sampler": "ggx_vndf", "alpha": 0.2})
    assert bsdf.adapter.material == "copper" and bsdf.adapter.sampler.params == {"alpha": 0.2}
    light, view = directions(256, seed=8)
    np.testing.assert_allclose(adapter_eval(mi, bsdf, light, view), (model.eval(light, view) * light[:, 2:3]).numpy(),
                               rtol=2e-5, atol=1e-6)


def test_bad_properties_give_clear_errors(mi, mb, tmp_path, fitted):
    model = make_model(fitted, "lambert")
    ok = mb.bsdf_dict(model, rep_name="lambert")
    path = modelio.save(model, "lambert", tmp_path / "chalk.safetensors")
    cases = [
        ({"type": "lambert"}, ConfigError, "exactly one of 'filename'.*got neither"),
        ({**ok, "filename": str(path)}, ConfigError, "got both"),
        ({"type": "lambert", "filename": str(tmp_path / "nope.safetensors")}, ModelFileError, "nope.safetensors.*no such model file"),
        ({"type": "ggx", "filename": str(path)}, ConfigError, "holds a 'lambert' model; use type='lambert'"),
        ({"type": "lambert", "model_id": "missing"}, ConfigError, "model_id='missing' is unknown"),
        ({**ok, "sampler": "cosin"}, ConfigError, "sampler='cosin'.*Did you mean 'cosine'"),
        ({**ok, "sampler": "ggx", "beta": 0.3}, ConfigError, "does not take the parameter\\(s\\) 'beta'"),
        ({**ok, "sampler": "ggx", "alpha": -1.0}, ConfigError, "alpha=-1.0"),
        ({**ok, "kernel": "fast"}, ConfigError, "kernel='fast'"),
    ]
    for props, error, message in cases:
        with pytest.raises(error, match=message):
            mb.load_dict(props)
    with pytest.raises(RuntimeError, match="exactly one of 'filename'"):  # plain Mitsuba shows the same message
        mi.load_dict({"type": "lambert"})
    with pytest.raises(ConfigError, match="clashes"):
        mb.bsdf_dict(model, rep_name="lambert", sampler_params={"material": 1})


def test_render_mode_only_where_needed(mi, mb, fitted):
    import drjit as dr

    gc.collect()
    native = mb.load_dict(mb.bsdf_dict(make_model(fitted, "merl"), rep_name="merl"))
    assert not mb.needs_evaluated_mode([native])
    with mb.render_mode([native]) as changed:
        assert not changed and dr.flag(dr.JitFlag.SymbolicCalls)
    slow = mb.load_dict(mb.bsdf_dict(make_model(fitted, "merl"), rep_name="merl", kernel="torch"))
    assert slow.adapter.kernel_path == "torch"
    # A symbolic call would trace `slow` too, even for a scene without it.
    assert mb.needs_evaluated_mode([native]) and mb.needs_evaluated_mode()
    with mb.render_mode([native]) as changed:
        assert changed and not dr.flag(dr.JitFlag.SymbolicCalls) and not dr.flag(dr.JitFlag.SymbolicLoops)
    assert dr.flag(dr.JitFlag.SymbolicCalls)
    del slow
    gc.collect()
    assert not mb.needs_evaluated_mode([native])


# --------------------------------------------------------------------------- scalar_rgb

SCALAR_SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from brdfbench import mitsuba_env
    with mitsuba_env.mitsuba_variant("scalar_rgb") as mi:
        from brdfbench.render import mitsuba_bsdf as mb
        mb.register_plugins()
        out = {}
        for rep, path in json.loads(sys.argv[1]).items():
            scene = mb.load_dict(mb.sphere_scene({"type": rep, "filename": path, "sampler": "ggx", "alpha": 0.3},
                                                 resolution=6, spp=2))
            out[rep] = [float(np.asarray(mb.render(scene)).mean()), mb.adapters_in(scene)[0].kernel_path]
        print(json.dumps(out))
""")


def test_scalar_rgb_tiny_render(mb, tmp_path, fitted):
    files = {name: str(modelio.save(make_model(fitted, name), name, tmp_path / f"{name}.safetensors"))
             for name in ("merl", "ggx", "nbrdf")}
    env = {**os.environ, mitsuba_env.VARIANT_ENV: "scalar_rgb"}
    done = subprocess.run([sys.executable, "-c", SCALAR_SCRIPT, json.dumps(files)], capture_output=True, text=True,
                          timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    for name, (mean, path) in result.items():
        assert path == "torch" and np.isfinite(mean) and mean > 0, (name, mean, path)
