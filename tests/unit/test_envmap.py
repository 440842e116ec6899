"""brdfbench.render.envmap: radiance as Mitsuba 3's `envmap` emitter, sampling, sky, files.

Mitsuba runs in float32 and applies to_world in float32, so its lookup coordinates carry
rounding (largest near the poles, where atan2 is ill-conditioned); the torch map runs in
float64 on the same float32 directions. Agreement is therefore stated relative to the
largest texel around the lookup: a convention error (half a texel, a flipped axis)
shows as a sizeable fraction of it on a noise map, rounding as ~1e-4 at most.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench.errors import DataError
from brdfbench.images import write_exr
from brdfbench.mitsuba_env import LLVM_VARIANT, choose_variant, mitsuba_variant
from brdfbench.render.envmap import (
    Envmap,
    direction_to_uv,
    load_envmap,
    luminance,
    procedural_sky,
    texel_directions,
)

SIGNIFICANCE = 0.01


def _rotation(ax: float, ay: float, az: float) -> np.ndarray:
    """Rz · Ry · Rx of angles in degrees."""
    ax, ay, az = (math.radians(a) for a in (ax, ay, az))
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


ROTATED = _rotation(30.0, -50.0, 110.0)


def _unit(n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(n, 3, generator=g, dtype=torch.float64)
    return d / d.norm(dim=-1, keepdim=True)


def _sphere_grid(nphi: int = 1536, nz: int = 768) -> torch.Tensor:
    """Midpoints of an equal-area (φ, cos θ) grid: Σ f · 4π/N is the midpoint rule for ∫ f dω."""
    phi = (torch.arange(nphi, dtype=torch.float64) + 0.5) * (2 * math.pi / nphi)
    z = 1 - (torch.arange(nz, dtype=torch.float64) + 0.5) * (2.0 / nz)
    zz, pp = torch.meshgrid(z, phi, indexing="ij")
    r = torch.sqrt(1 - zz * zz)
    return torch.stack((r * torch.cos(pp), r * torch.sin(pp), zz), dim=-1).reshape(-1, 3)


def _noise_map(h: int = 32, seed: int = 3) -> torch.Tensor:
    """High-contrast texels (most neighbours differ by ~100%): a convention error cannot hide."""
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(h, 2 * h, 3, generator=g) ** 4) * 10.0


@pytest.fixture(scope="module", autouse=True)
def _one_torch_thread():
    """Arrays here are ≲ 2e6 elements: a second thread gains little and costs much on busy cores."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def sky() -> torch.Tensor:
    return procedural_sky()


@pytest.fixture(scope="module")
def mi():
    with mitsuba_variant(choose_variant()) as mi:
        yield mi


# --------------------------------------------------------------------------- Mitsuba helpers


def _to_mi_vectors(mi, d: torch.Tensor):
    a = d.to(torch.float32).T.contiguous().numpy()
    return mi.Vector3f(a[0], a[1], a[2])


def _mitsuba_eval(mi, emitter, d: torch.Tensor) -> torch.Tensor:
    """Radiance of Mitsuba's emitter towards world directions d: Emitter.eval reads the
    direction as −si.wi (si.wi points back along a ray that escaped towards d)."""
    import drjit as dr

    if mi.variant().startswith("scalar"):
        out = []
        for row in d.tolist():
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = -mi.Vector3f(row)
            out.append(list(emitter.eval(si)))
        return torch.tensor(out, dtype=torch.float64)
    si = dr.zeros(mi.SurfaceInteraction3f, d.shape[0])
    si.wi = -_to_mi_vectors(mi, d)
    return torch.from_numpy(np.array(emitter.eval(si)).T.copy()).to(torch.float64)


def _mitsuba_pdf(mi, emitter, d: torch.Tensor) -> torch.Tensor:
    import drjit as dr

    if mi.variant().startswith("scalar"):
        out = []
        for row in d.tolist():
            ds = mi.DirectionSample3f()
            ds.d = mi.Vector3f(row)
            out.append(float(emitter.pdf_direction(mi.Interaction3f(), ds)))
        return torch.tensor(out, dtype=torch.float64)
    ds = dr.zeros(mi.DirectionSample3f, d.shape[0])
    ds.d = _to_mi_vectors(mi, d)
    return torch.from_numpy(np.array(emitter.pdf_direction(dr.zeros(mi.Interaction3f, d.shape[0]), ds)).copy()).to(torch.float64)


def _local_max(env: Envmap, d: torch.Tensor) -> torch.Tensor:
    """(N, 3) largest scaled texel of the 4 × 4 block around each lookup (bounds the interpolant's slope)."""
    uv = direction_to_uv(d.to(torch.float64) @ env.to_world)
    h, w = env.height, env.width
    i0 = torch.floor(uv[:, 0] * w - 0.5).long() % w
    j0 = torch.floor(uv[:, 1] * (h - 1)).long().clamp(0, h - 2)
    block = [env.image[(j0 + dj).clamp(0, h - 1), (i0 + di) % w] for dj in (-1, 0, 1, 2) for di in (-1, 0, 1, 2)]
    return torch.stack(block).amax(0).to(torch.float64) * env.scale


def _directions_for_comparison(env: Envmap, n: int) -> torch.Tensor:
    """Random directions, the texel directions (in world) and the six axes, rounded to float32."""
    texels = texel_directions(env.height, env.width).reshape(-1, 3) @ env.to_world.T
    axes = torch.cat([torch.eye(3), -torch.eye(3)]).to(torch.float64)
    return torch.cat([_unit(n, seed=11), texels[:: max(1, texels.shape[0] // 4096)], axes]).to(torch.float32).to(torch.float64)


# --------------------------------------------------------------------------- eval against Mitsuba


@pytest.mark.parametrize("to_world", [None, ROTATED], ids=["identity", "rotated"])
@pytest.mark.parametrize("which", ["sky", "noise"])
def test_eval_matches_mitsuba_envmap(mi, sky, which, to_world):
    image = sky if which == "sky" else _noise_map()
    env = Envmap(image, to_world, scale=1.7)
    emitter = mi.load_dict(env.mitsuba_dict())
    n = 2000 if mi.variant().startswith("scalar") else 50_000
    d = _directions_for_comparison(env, n)
    ref = _mitsuba_eval(mi, emitter, d)
    ours = env.eval(d)
    assert ours.dtype == d.dtype and ours.shape == ref.shape
    # Within 1e-4 rad of the map's poles the lookup is ill-conditioned (u is the azimuth of a
    # float32-rounded, nearly vertical vector); there both only need to read the pole's row.
    local = d @ env.to_world
    polar = local[:, 0] ** 2 + local[:, 2] ** 2 < 1e-8
    rows = env.image[[0, -1]].to(torch.float64) * env.scale  # (2, W, 3)
    for got in (ours[polar], ref[polar]):
        assert bool((got <= rows.amax((0, 1)) + 1e-5).all() and (got >= rows.amin((0, 1)) - 1e-5).all())
    ours, ref, d = ours[~polar], ref[~polar], d[~polar]
    rel = ((ours - ref).abs() / _local_max(env, d).clamp_min(1e-30)).amax(-1)
    worst = int(rel.argmax())
    print(f"{which}, {'rotated' if to_world is not None else 'identity'}: |torch − Mitsuba| / local max: "
          f"median {float(rel.median()):.2g}, 99% {float(torch.quantile(rel, 0.99)):.2g}, max {float(rel.max()):.2g}")
    assert float(rel.max()) < 5e-4, (
        f"max |torch − Mitsuba| / local max = {float(rel.max()):.3g} at d={d[worst].tolist()}: "
        f"{ours[worst].tolist()} vs {ref[worst].tolist()}")
    # Away from rounding-sensitive spots the two agree to float32 precision.
    assert float(rel.median()) < 1e-5 and float(torch.quantile(rel, 0.99)) < 3e-5


def test_texels_are_returned_at_their_directions(sky):
    """The documented convention: texel (j, i) is the radiance towards θ_j = πj/(H−1), φ_i = 2π(i + ½)/W."""
    env = Envmap(sky, scale=2.0)
    d = texel_directions(env.height, env.width).reshape(-1, 3)
    expected = 2.0 * sky.to(torch.float64).reshape(-1, 3)
    got = env.eval(d)
    interior = torch.ones(env.height, env.width, dtype=torch.bool)
    interior[[0, -1]] = False  # at the poles every column is the same direction (u read as 0)
    interior = interior.reshape(-1)
    torch.testing.assert_close(got[interior], expected[interior], rtol=1e-9, atol=1e-9)
    noise = Envmap(_noise_map())  # at a pole Mitsuba reads u = 0: halfway between the last and first columns
    poles = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]], dtype=torch.float64)
    expected = 0.5 * (noise.image[[0, -1], 0] + noise.image[[0, -1], -1]).double()
    torch.testing.assert_close(noise.eval(poles), expected)


def test_eval_keeps_dtype_and_rotation_moves_the_map(sky):
    env, turned = Envmap(sky), Envmap(sky, ROTATED)
    d = _unit(1000, seed=5)
    assert env.eval(d.float()).dtype == torch.float32
    torch.testing.assert_close(turned.eval(d @ torch.from_numpy(ROTATED).T), env.eval(d))
    with pytest.raises(ValueError, match="rotation"):
        Envmap(sky, np.diag([1.0, 2.0, 1.0]))
    with pytest.raises(ValueError, match="rotation"):
        Envmap(sky, np.diag([1.0, -1.0, 1.0]))
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = ROTATED, (5.0, -2.0, 1.0)  # translation: meaningless at infinity, ignored
    torch.testing.assert_close(Envmap(sky, m).eval(d), turned.eval(d))


# --------------------------------------------------------------------------- sampling


def test_sample_matches_pdf_chi2(mi, monkeypatch, tmp_path):
    """Pearson χ² of `sample` against `pdf` with mitsuba.chi2.ChiSquareTest over SphericalDomain;
    the cell integrals of the piecewise-constant pdf come from the project's adaptive cubature
    (a fixed 4 × 4 rule mis-integrates the sun's edges: rejected at ires = 4)."""
    if mi.variant() != LLVM_VARIANT:
        pytest.skip("ChiSquareTest needs a JIT variant (llvm_ad_rgb)")
    import time

    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    from brdfbench.sampling.cubature import tabulate_expected

    monkeypatch.chdir(tmp_path)  # a rejected test writes chi2_data.py into the working directory
    env = Envmap(procedural_sky(256, 128), ROTATED)
    wrong = Envmap(procedural_sky(256, 128, sun_radius_deg=2.5), ROTATED)  # a slightly different pdf

    def run(pdf_env: Envmap) -> tuple[bool, str]:
        class Adaptive(ChiSquareTest):
            def tabulate_pdf(self):
                self.histogram_start = time.time()
                expected, _ = tabulate_expected(lambda v: pdf_env.pdf(v), 101, self.sample_count, ires=4)
                self.pdf = mi.Float(expected.numpy())
                self.pdf_sum = mi.Float([float(expected.sum()) / self.sample_count])
                self.histogram_end = time.time()

        def sample_func(u):
            d, _ = env.sample(torch.from_numpy(np.array(u, dtype=np.float64).T.copy()))
            return _to_mi_vectors(mi, d)

        test = Adaptive(domain=SphericalDomain(), sample_func=sample_func, pdf_func=None,
                        sample_dim=2, sample_count=1_000_000, res=101, ires=4, seed=0)
        return bool(test.run(significance_level=SIGNIFICANCE, quiet=True)), test.messages

    passed, messages = run(env)
    assert passed, messages
    rejected, messages = run(wrong)
    assert not rejected, "the χ² test cannot tell a sun 2.5° wide from one 2° wide:\n" + messages


def test_pdf_integrates_to_one_and_agrees_with_sample():
    env = Envmap(procedural_sky(128, 64, sun_radius_deg=4.0), ROTATED)
    grid = _sphere_grid()
    integral = float(env.pdf(grid).sum()) * 4 * math.pi / grid.shape[0]
    assert abs(integral - 1.0) < 2e-3, integral
    # Importance sampling: E[1/p] is the measure of the support (the whole sphere here).
    d, p = env.sample(torch.rand(200_000, 2, generator=torch.Generator().manual_seed(1), dtype=torch.float64))
    assert torch.allclose(d.norm(dim=-1), torch.ones(1, dtype=torch.float64), atol=1e-12)
    assert bool((p > 0).all())
    estimate, sigma = float((1 / p).mean()), float((1 / p).std()) / math.sqrt(p.numel())
    assert abs(estimate - 4 * math.pi) < 5 * sigma + 1e-3, (estimate, sigma)
    same = env.pdf(d) == p
    assert float(same.double().mean()) > 0.9999  # the rest sit on cell boundaries (rounding)


def test_importance_sampled_integral_matches_mitsuba_and_quadrature(mi):
    """∫ L dω three ways: our sampler (L/p), Mitsuba's sample_direction weights, and quadrature of eval."""
    if mi.variant() != LLVM_VARIANT:
        pytest.skip("batched sample_direction needs a JIT variant")
    import drjit as dr

    env = Envmap(procedural_sky(128, 64, sun_radius_deg=4.0), ROTATED, scale=0.5)
    emitter = mi.load_dict(env.mitsuba_dict())
    n = 200_000
    u = torch.rand(n, 2, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    d, p = env.sample(u)
    ours = env.eval(d) / p[:, None]
    a = u.float().T.contiguous().numpy()
    _, weight = emitter.sample_direction(dr.zeros(mi.Interaction3f, n), mi.Point2f(a[0], a[1]))
    theirs = torch.from_numpy(np.array(weight).T.copy()).to(torch.float64)
    grid = _sphere_grid()
    quadrature = env.eval(grid).sum(0) * 4 * math.pi / grid.shape[0]
    for est in (ours, theirs):
        mean, sigma = est.mean(0), est.std(0) / math.sqrt(n)
        assert bool(((mean - quadrature).abs() < 5 * sigma + 2e-3 * quadrature).all()), (mean, sigma, quadrature)
    # Our sampler follows luminance closely: its estimator's relative noise is small.
    assert float((luminance(ours).std() / luminance(ours).mean())) < 0.5


def test_pdf_compared_with_mitsuba_pdf_direction(mi, sky):
    """Informative: Mitsuba's warp is bilinear over texels (∝ luminance · sin θ), ours piecewise
    constant over the same cells; the two densities agree closely away from sharp edges."""
    env = Envmap(sky, ROTATED)
    emitter = mi.load_dict(env.mitsuba_dict())
    n = 2000 if mi.variant().startswith("scalar") else 100_000
    d, p = env.sample(torch.rand(n, 2, generator=torch.Generator().manual_seed(4), dtype=torch.float64))
    d = d.to(torch.float32).to(torch.float64)
    ratio = env.pdf(d) / _mitsuba_pdf(mi, emitter, d)
    q = torch.quantile(ratio, torch.tensor([0.05, 0.5, 0.95], dtype=torch.float64))
    print(f"pdf ours / Mitsuba over our samples: 5% {q[0]:.4f}, median {q[1]:.5f}, 95% {q[2]:.4f}")
    assert abs(float(q[1]) - 1) < 1e-2 and 0.8 < float(q[0]) and float(q[2]) < 1.25


def test_pdf_positive_wherever_radiance_is():
    """A map lit on its top row (the zenith) and in one texel: weights luminance × sin θ_j
    give the zenith cap no mass (Mitsuba 3.9.1's pdf_direction is NaN there when that row is
    all that is lit); ours keeps pdf > 0 wherever eval > 0."""
    image = torch.zeros(16, 32, 3)
    image[0] = 3.0
    image[9, 20] = torch.tensor([0.0, 0.0, 5.0])
    env = Envmap(image, ROTATED)
    near_lit, _ = env.sample(torch.rand(50_000, 2, generator=torch.Generator().manual_seed(7), dtype=torch.float64))
    d = torch.cat([_unit(200_000, seed=6), near_lit])
    lit = env.eval(d).sum(-1) > 0
    assert bool(lit.any()) and bool((env.pdf(d)[lit] > 0).all())
    d_s, p_s = env.sample(torch.rand(50_000, 2, generator=torch.Generator().manual_seed(8), dtype=torch.float64))
    assert bool((p_s > 0).all()) and float((env.eval(d_s).sum(-1) > 0).double().mean()) > 0.999


@pytest.fixture(scope="module")
def sparse_env() -> Envmap:
    image = _noise_map(8, seed=9)
    image[image.sum(-1) < 2.0] = 0.0  # about half the texels dark
    return Envmap(image, ROTATED)


_coord = st.one_of(st.floats(-1.0, 1.0, allow_nan=False), st.sampled_from([0.0, -0.0, 1.0, -1.0, 1e-30, -1e-30]))
_unit_u = st.one_of(st.floats(0.0, 1.0, exclude_max=True), st.sampled_from([0.0, 0.5, 1.0 - 2.0**-53, 1.0 - 2.0**-24]))


@settings(max_examples=100, deadline=None)
@given(x=_coord, y=_coord, z=_coord, u0=_unit_u, u1=_unit_u, f32=st.booleans())
def test_property_pdf_eval_and_sample_are_sane(sparse_env, x, y, z, u0, u1, f32):
    dtype = torch.float32 if f32 else torch.float64
    v = torch.tensor([[x, y, z]], dtype=torch.float64)
    if float(v.norm()) > 1e-12:
        d = (v / v.norm()).to(dtype)
        p, radiance = sparse_env.pdf(d), sparse_env.eval(d)
        assert p.dtype == dtype and bool(torch.isfinite(p).all()) and float(p) >= 0
        assert bool(torch.isfinite(radiance).all()) and bool((radiance >= 0).all())
        if float(radiance.sum()) > 0:
            assert float(p) > 0
    s, ps = sparse_env.sample(torch.tensor([[u0, u1]], dtype=dtype))
    assert s.dtype == dtype and abs(float(s.double().norm()) - 1) < (1e-6 if f32 else 1e-12)
    assert bool(torch.isfinite(ps).all()) and float(ps) > 0


# --------------------------------------------------------------------------- the procedural sky


def test_procedural_sky_is_deterministic_finite_and_plausible(sky):
    again = procedural_sky()
    assert sky.shape == (256, 512, 3) and sky.dtype == torch.float32
    assert torch.equal(sky, again)
    assert bool(torch.isfinite(sky).all()) and bool((sky >= 0).all())
    lum = luminance(sky.double())
    d = texel_directions(256, 512)
    sun = torch.tensor([math.sin(math.radians(135)) * math.cos(math.radians(35)), math.sin(math.radians(35)),
                        -math.cos(math.radians(135)) * math.cos(math.radians(35))], dtype=torch.float64)
    far = torch.acos((d @ sun).clamp(-1, 1)) > math.radians(10)  # the sky away from sun and glow
    above, below = far & (d[..., 1] > 0.05), far & (d[..., 1] < -0.05)
    # the sun: the brightest texel lies within its disk, 300–3000× the mean of the sky
    j, i = divmod(int(lum.argmax()), 512)
    assert math.degrees(math.acos(float(d[j, i] @ sun))) < 2.0
    ratio = float(lum.max()) / float(lum[above].mean())
    assert 300 < ratio < 3000, ratio
    assert float(luminance(Envmap(sky).eval(sun[None]))) > 0.9 * 500 * float(luminance(torch.tensor([1.0, 0.95, 0.85])))
    # bluish zenith, brighter horizon, darker ground
    zenith = sky[0, 0].double()
    assert zenith[2] > zenith[0] and zenith[2] > zenith[1]
    horizon_row = int(round(0.5 * 255)) - 2  # just above the horizon
    horizon = lum[horizon_row][far[horizon_row]].mean()
    assert float(horizon) > float(lum[0, 0]) and float(lum[below].max()) < float(lum[above].min())


def test_procedural_sky_puts_the_sun_where_asked():
    sky = procedural_sky(128, 64, sun_elevation_deg=10.0, sun_azimuth_deg=90.0, sun_radius_deg=4.0)
    j, i = divmod(int(luminance(sky.double()).argmax()), 128)
    d = texel_directions(64, 128)[j, i]
    expected = torch.tensor([math.cos(math.radians(10)), math.sin(math.radians(10)), 0.0], dtype=torch.float64)  # +X
    assert math.degrees(math.acos(float(d @ expected))) < 4.0
    with pytest.raises(ValueError, match="lat-long"):
        procedural_sky(100, 64)


# --------------------------------------------------------------------------- files


def _write_raw_exr(path, rgb: np.ndarray) -> None:
    """An EXR write that, unlike write_exr, lets NaN through."""
    import OpenEXR

    channels = {c: np.ascontiguousarray(rgb[..., k].astype(np.float32)) for k, c in enumerate("RGB")}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels).write(str(path))


def test_load_envmap_roundtrip(tmp_path):
    sky = procedural_sky(64, 32)
    write_exr(tmp_path / "sky.exr", sky)
    env = load_envmap(tmp_path / "sky.exr", to_world=ROTATED, scale=2.0)
    assert torch.equal(env.image, sky) and env.scale == 2.0
    assert torch.equal(Envmap.from_file(tmp_path / "sky.exr").image, sky)


def _bad_nan(h, w):
    a = np.ones((h, w, 3), np.float32)
    a[3, 4, 1] = np.nan
    return a


def _bad_negative(h, w):
    a = np.ones((h, w, 3), np.float32)
    a[5, 6, 2] = -0.25
    return a


@pytest.mark.parametrize("case, match", [
    ("bytes", "not an OpenEXR file"),
    ("missing", "no such EXR file"),
    ("aspect", r"300×200 is not a lat-long environment map \(width must be twice the height\)"),
    ("nan", "NaN"),
    ("negative", r"1 texels have negative radiance, first at \(row 5, column 6\)"),
    ("zero", "every texel is zero"),
    ("small", r"8×4 is too small"),
    ("no_rgb", "lacks channel"),
    ("truncated", "cannot read EXR"),
])
def test_bad_exr_files_raise_naming_the_file(tmp_path, case, match):
    path = tmp_path / "sky.exr"
    if case == "bytes":
        path.write_bytes(b"this is not an EXR file at all")
    elif case == "aspect":
        write_exr(path, torch.ones(200, 300, 3))
    elif case == "nan":
        _write_raw_exr(path, _bad_nan(16, 32))
    elif case == "negative":
        write_exr(path, torch.from_numpy(_bad_negative(16, 32)))
    elif case == "zero":
        write_exr(path, torch.zeros(16, 32, 3))
    elif case == "small":
        write_exr(path, torch.ones(4, 8, 3))
    elif case == "no_rgb":
        import OpenEXR

        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     {"Y": np.ones((16, 32), np.float32)}).write(str(path))
    elif case == "truncated":
        write_exr(path, procedural_sky(64, 32))
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=match) as info:
        load_envmap(path)
    assert str(path) in str(info.value)


def test_bad_tensors_raise_value_errors():
    with pytest.raises(ValueError, match=r"my sky: 30×20 is not a lat-long"):
        Envmap(torch.ones(20, 30, 3), name="my sky")
    with pytest.raises(ValueError, match="float"):
        Envmap(torch.ones(16, 32, 3, dtype=torch.int32))
    with pytest.raises(ValueError, match=r"\(H, W, ≥3\)"):
        Envmap(torch.ones(16, 32))
    with pytest.raises(ValueError, match="not finite"):
        Envmap(torch.from_numpy(_bad_nan(16, 32)))
    with pytest.raises(ValueError, match="scale"):
        Envmap(torch.ones(16, 32, 3), scale=0.0)
    env = Envmap(torch.ones(16, 32, 4))  # an alpha channel is dropped
    assert env.image.shape == (16, 32, 3)
