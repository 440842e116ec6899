"""Image-space distances between material sets (`image_distances`): every entry of the fast
matrix against a slow reference that loops over pairs calling the single-image metrics of
`image_functional`; self-distances; bad input; and `render_set` on two fitted materials
(distinct images, one seed for every member, determinism, non-finite members named)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench.plugins import registry
from brdfbench.errors import RenderError
from brdfbench.testing.kit import reference_material
from brdfbench.distances import image as D
from brdfbench.distances import image_functional as F

# --------------------------------------------------------------------------- the slow reference


def common_range(a: torch.Tensor, b: torch.Tensor, kind: str) -> float:
    """HDR: the peak over both sets of what the metric compares (radiance, or log(1 + radiance) for SSIM)."""
    both = torch.cat([a, b]).double()
    return float(torch.log1p(both).max() if kind == "neg_ssim" else both.max())


def slow_matrix(a: torch.Tensor, b: torch.Tensor, kind: str, space: str = "ldr", exposure: float = 0.0,
                data_range: float | None = None) -> np.ndarray:
    """d[i, j] = the single-image metric of (a[i], b[j]), one call per pair."""
    if space == "hdr" and data_range is None:
        data_range = common_range(a, b, kind)
    out = np.empty((len(a), len(b)))
    for i in range(len(a)):
        for j in range(len(b)):
            p, t = a[i].double(), b[j].double()
            if kind == "rmse":
                v = F.rmse(p, t, space=space, exposure=exposure)
            elif kind == "neg_psnr":
                v = -F.psnr(p, t, space=space, exposure=exposure, data_range=data_range)
            else:
                v = -F.ssim(p, t, space=space, exposure=exposure, data_range=data_range)
            out[i, j] = float(v)
    return out


def images(n: int, h: int, w: int, seed: int, scale: float = 1.0) -> torch.Tensor:
    """Radiance with smooth structure (a tilted ramp), noise, and some values past white."""
    g = torch.Generator().manual_seed(seed)
    ramp = torch.linspace(0, 1, w).view(1, 1, w, 1) * torch.rand(n, 1, 1, 3, generator=g)
    return ((ramp + 0.5 * torch.rand(n, h, w, 3, generator=g)) * scale).to(torch.float32)


TOL = 1e-9  # fast vs slow: different summation orders in fp64 (PSNR in dB, others in their units)


# --------------------------------------------------------------------------- against the reference


@pytest.mark.parametrize("space", ["ldr", "hdr"])
@pytest.mark.parametrize("kind", D.KINDS)
def test_matrix_matches_slow_reference(kind, space):
    a, b = images(D.ROWS + 2, 17, 23, seed=1, scale=1.5), images(4, 17, 23, seed=2, scale=0.8)
    fast = D.image_distance_matrix(a, b, kind, space=space, block=3)
    assert fast.dtype == np.float64 and fast.shape == (D.ROWS + 2, 4)
    np.testing.assert_allclose(fast, slow_matrix(a, b, kind, space), rtol=0, atol=TOL)


@pytest.mark.parametrize("space", ["ldr", "hdr"])
@pytest.mark.parametrize("kind", D.KINDS)
def test_symmetric_case_matches_slow_reference(kind, space):
    a = images(D.ROWS + 3, 16, 16, seed=3, scale=2.0)  # more than one row block
    fast = D.image_distance_matrix(a, None, kind, space=space, block=4)
    np.testing.assert_array_equal(fast, fast.T)  # mirrored, not computed twice
    np.testing.assert_allclose(fast, slow_matrix(a, a, kind, space), rtol=0, atol=TOL)
    np.testing.assert_allclose(fast, D.image_distance_matrix(a, a, kind, space=space), rtol=0, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(na=st.integers(1, 4), nb=st.integers(1, 4), h=st.integers(11, 19), w=st.integers(11, 19),
       seed=st.integers(0, 2**16), scale=st.sampled_from([0.05, 1.0, 20.0]), exposure=st.sampled_from([-1.0, 0.0, 2.0]),
       block=st.integers(1, 5), kind=st.sampled_from(D.KINDS), space=st.sampled_from(["ldr", "hdr"]))
def test_matrix_matches_slow_reference_any_shape(na, nb, h, w, seed, scale, exposure, block, kind, space):
    a, b = images(na, h, w, seed, scale), images(nb, h, w, seed + 1, scale)
    fast = D.image_distance_matrix(a, b, kind, space=space, exposure=exposure, block=block)
    np.testing.assert_allclose(fast, slow_matrix(a, b, kind, space, exposure), rtol=0, atol=TOL)


def test_given_hdr_data_range_is_used():
    a, b = images(3, 12, 12, seed=4, scale=3.0), images(2, 12, 12, seed=5, scale=3.0)
    for kind in ("neg_psnr", "neg_ssim"):
        fast = D.image_distance_matrix(a, b, kind, space="hdr", data_range=10.0)
        np.testing.assert_allclose(fast, slow_matrix(a, b, kind, "hdr", data_range=10.0), rtol=0, atol=TOL)


def test_block_size_does_not_change_ssim():
    a, b = images(7, 13, 15, seed=6), images(5, 13, 15, seed=7)
    ref = D.image_distance_matrix(a, b, "neg_ssim", block=1)
    for block in (2, 3, 8):
        np.testing.assert_allclose(D.image_distance_matrix(a, b, "neg_ssim", block=block), ref, rtol=0, atol=1e-13)
        sym = D.image_distance_matrix(a, None, "neg_ssim", block=block)
        np.testing.assert_allclose(sym, D.image_distance_matrix(a, None, "neg_ssim", block=1), rtol=0, atol=1e-13)


def test_blur_matrix_is_the_ssim_filter():
    x = torch.rand(4, 19, 13, dtype=torch.float64)
    ours = D.blur_matrix(19) @ x @ D.blur_matrix(13).T
    np.testing.assert_allclose(ours, F._blur(x, F._gaussian_window()), rtol=0, atol=1e-15)


# --------------------------------------------------------------------------- a set against itself


def test_self_distances_are_minimal_on_the_diagonal():
    a = images(8, 24, 24, seed=8, scale=1.2)
    rmse = D.image_distance_matrix(a, kind="rmse")
    assert (np.diag(rmse) == 0).all() and (rmse[~np.eye(8, dtype=bool)] > 0).all()
    psnr = D.image_distance_matrix(a, kind="neg_psnr")
    assert (np.diag(psnr) == -F.PSNR_MAX_DB).all() and (psnr >= -F.PSNR_MAX_DB).all()
    ssim = D.image_distance_matrix(a, kind="neg_ssim")
    np.testing.assert_allclose(np.diag(ssim), -1.0, rtol=0, atol=1e-12)
    assert (ssim >= -1.0 - 1e-12).all()
    for d in (rmse, psnr, ssim):
        assert (d.argmin(axis=1) == np.arange(8)).all()


def test_distances_feed_the_distributional_metrics():
    from brdfbench_metrics import distributional

    r, s = images(4, 16, 16, seed=9), images(3, 16, 16, seed=10)
    for kind in D.KINDS:
        d_rs = D.image_distance_matrix(r, s, kind)
        assert distributional.one_nna(D.image_distance_matrix(r, kind=kind), D.image_distance_matrix(s, kind=kind),
                                      d_rs) >= 0
        assert distributional.mmd(D.image_distance_matrix(r, r, kind)) == pytest.approx(
            {"rmse": 0.0, "neg_psnr": -F.PSNR_MAX_DB, "neg_ssim": -1.0}[kind], abs=1e-12)


def test_progress_counts_to_the_end():
    calls = []

    def note(done, total):
        calls.append((done, total))

    D.image_distance_matrix(images(5, 12, 12, seed=11), kind="neg_ssim", block=2, progress=note)
    assert calls[-1][0] == calls[-1][1] == len(calls) == 6  # upper blocks of a 3 × 3 grid
    calls.clear()
    D.image_distance_matrix(images(D.ROWS + 1, 12, 12, seed=11), kind="rmse", progress=note)
    assert calls == [(1, 2), (2, 2)]


def test_numpy_and_float64_inputs():
    a = images(3, 12, 12, seed=12)
    ref = D.image_distance_matrix(a, kind="neg_ssim")
    np.testing.assert_allclose(D.image_distance_matrix(a.double().numpy(), kind="neg_ssim"), ref, rtol=0, atol=1e-15)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("call, message", [
    (lambda a: D.image_distance_matrix(a[:0]), "empty"),
    (lambda a: D.image_distance_matrix(a, a[:, :, :5]), "differ in image shape"),
    (lambda a: D.image_distance_matrix(a[0]), r"shape \(N, H, W, 3\)"),
    (lambda a: D.image_distance_matrix(a[..., :2]), r"shape \(N, H, W, 3\)"),
    (lambda a: D.image_distance_matrix((a * 255).to(torch.uint8)), "float tensor"),
    (lambda a: D.image_distance_matrix([1.0, 2.0]), "float tensor"),
    (lambda a: D.image_distance_matrix(a, kind="l2"), "unknown image distance 'l2'"),
    (lambda a: D.image_distance_matrix(a, space="log"), "unknown space 'log'"),
    (lambda a: D.image_distance_matrix(a[:, :10, :10], kind="neg_ssim"), "at least 11×11"),
    (lambda a: D.image_distance_matrix(-a, kind="neg_ssim", space="hdr"), "non-negative"),
    (lambda a: D.image_distance_matrix(a, kind="neg_psnr", space="hdr", data_range=0.0), "data_range"),
    (lambda a: D.image_distance_matrix(a * 0, kind="neg_psnr", space="hdr"), "no HDR data range"),
    (lambda a: D.image_distance_matrix(a, kind="neg_ssim", block=0), "block"),
])
def test_bad_input_is_named(call, message):
    with pytest.raises(ValueError, match=message):
        call(images(3, 12, 12, seed=13))


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_image_is_named(bad):
    a, b = images(3, 12, 12, seed=14), images(4, 12, 12, seed=15)
    b[2, 5, 5, 1] = bad
    with pytest.raises(ValueError, match="images_b: image 2 has non-finite"):
        D.image_distance_matrix(a, b)


# --------------------------------------------------------------------------- rendering sets


@pytest.fixture(scope="module")
def two_materials():
    material = reference_material()
    return [registry.get("representations", name).create().fit(material) for name in ("lambert", "ggx")]


SMALL = dict(width=32, height=32)


def test_render_set_gives_distinct_images(two_materials):
    out = D.render_set(two_materials, "sphere_directional", **SMALL)
    assert out.shape == (2, 32, 32, 3) and out.dtype == torch.float32 and torch.isfinite(out).all()
    assert float(out.max()) > 0
    assert float(D.image_distance_matrix(out, kind="rmse")[0, 1]) > 1e-3
    np.testing.assert_array_equal(np.diag(D.image_distance_matrix(out, kind="rmse")), 0)


def test_render_set_envmap_is_deterministic_for_a_seed(two_materials):
    keys = dict(spp=2, **SMALL)
    first = D.render_set(two_materials, "sphere_envmap", seed=3, **keys)
    again = D.render_set(two_materials, "sphere_envmap", seed=3, **keys)
    torch.testing.assert_close(first, again, rtol=0, atol=0)
    other = D.render_set(two_materials, "sphere_envmap", seed=4, **keys)
    assert not torch.equal(first, other)  # the seed is used
    # one seed for every member: a member's image does not depend on its place in the set
    alone = D.render_set(two_materials[1:], "sphere_envmap", seed=3, **keys)
    torch.testing.assert_close(alone[0], first[1], rtol=0, atol=0)


def test_render_with_one_simulator_for_several_sets(two_materials):
    sim = D.build_set_simulator("sphere_directional", **SMALL)
    calls = []
    a = D.render_with(sim, two_materials, progress=lambda d, n: calls.append((d, n)))
    b = D.render_with(sim, two_materials[::-1])
    assert calls == [(1, 2), (2, 2)]
    torch.testing.assert_close(a, b.flip(0), rtol=0, atol=0)


@pytest.mark.parametrize("backend", ["torch", None])
def test_render_set_names_a_non_finite_member(two_materials, backend):
    broken = registry.get("representations", "lambert").create()
    broken.albedo = torch.tensor([0.5, math.nan, 0.5], dtype=torch.float64)
    with pytest.raises(RenderError, match=r"member 1 \(broken-one\)"):
        D.render_set([two_materials[0], broken], "sphere_directional", backend=backend, labels=["ok", "broken-one"],
                     **SMALL)


def test_render_set_bad_input(two_materials):
    with pytest.raises(ValueError, match="empty"):
        D.render_set([], "sphere_directional")
    with pytest.raises(ValueError, match="2 labels for 1 members"):
        D.render_set(two_materials[:1], "sphere_directional", labels=["a", "b"])
    with pytest.raises(ValueError, match="seed"):
        D.render_set(two_materials, "sphere_directional", seed=-1)
    from brdfbench.errors import ConfigError

    with pytest.raises(ConfigError, match="scene.params.colour"):
        D.render_set(two_materials, "sphere_directional", colour=3)
