"""Image metrics (MSE, RMSE, PSNR, SSIM, FLIP in LDR and HDR), tone mapping and image files."""

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image
from scipy.ndimage import gaussian_filter

from brdfbench import images
from brdfbench.plugins import registry
from brdfbench.errors import DataError
from brdfbench_metrics import image as IM
from brdfbench.distances import image_functional as IF

REPO = Path(__file__).resolve().parents[2]
FUNCTIONAL = {"mse": IF.mse, "rmse": IF.rmse, "psnr": IF.psnr, "ssim": IF.ssim, "flip": IF.flip}
IMAGE_METRICS = [f"{m}_{s}" for m in FUNCTIONAL for s in IF.SPACES]


def _images(n=None, h=16, w=16, seed=0, scale=2.0):
    g = torch.Generator().manual_seed(seed)
    shape = (h, w, 3) if n is None else (n, h, w, 3)
    return torch.rand(shape, generator=g, dtype=torch.float64) * scale


def _noisy(target, amount, seed=1):
    g = torch.Generator().manual_seed(seed)
    return target * (1 + amount * torch.rand(target.shape, generator=g, dtype=target.dtype))


# --------------------------------------------------------------------------- tone mapping


def test_tonemap_is_exposure_clamp_and_the_srgb_curve():
    x = torch.tensor([-1.0, 0.0, 0.002, 0.0031308, 0.18, 0.5, 1.0, 7.0], dtype=torch.float64)
    by_hand = [0.0, 0.0, 12.92 * 0.002, 12.92 * 0.0031308, 1.055 * 0.18 ** (1 / 2.4) - 0.055,
               1.055 * 0.5 ** (1 / 2.4) - 0.055, 1.0, 1.0]
    assert images.tonemap(x).tolist() == pytest.approx(by_hand, abs=1e-12)
    assert images.tonemap(x, exposure=1.0)[5] == pytest.approx(1.0)  # 0.5 · 2^1 = 1
    assert images.tonemap(x, exposure=-1.0)[6] == pytest.approx(1.055 * 0.5 ** (1 / 2.4) - 0.055)
    # the two pieces of the sRGB curve meet at the knee
    knee = torch.tensor([0.0031308], dtype=torch.float64)
    assert float(images.srgb_oetf(knee)) == pytest.approx(1.055 * 0.0031308 ** (1 / 2.4) - 0.055, abs=1e-7)
    with pytest.raises(ValueError, match="float image"):
        images.tonemap(torch.ones(2, 2, 3, dtype=torch.uint8))


# --------------------------------------------------------------------------- known values


@pytest.mark.parametrize("space", IF.SPACES)
def test_identical_images_score_best(space):
    t = _images(n=2, h=24, w=20)
    assert float(IF.mse(t, t, space=space)) == 0.0
    assert float(IF.rmse(t, t, space=space)) == 0.0
    assert float(IF.psnr(t, t, space=space)) == IF.PSNR_MAX_DB == 100.0  # documented cap, not inf
    value, smap = IF.ssim(t, t, space=space, return_map=True)
    assert float(value) == 1.0 and torch.all(smap == 1.0)
    value, fmap = IF.flip(t, t, space=space, return_map=True)
    assert float(value) == 0.0 and torch.all(fmap == 0.0)


def test_psnr_of_a_constant_offset_by_hand():
    t = _images(h=12, w=12, scale=1.0)
    # HDR: MSE = 0.1² exactly; data range given, then the target's max
    assert float(IF.psnr(t + 0.1, t, space="hdr", data_range=1.0)) == pytest.approx(20.0)
    assert float(IF.psnr(t + 0.1, t, space="hdr")) == pytest.approx(10 * math.log10(float(t.max()) ** 2 / 0.01))
    assert float(IF.mse(t + 0.1, t, space="hdr")) == pytest.approx(0.01)
    assert float(IF.rmse(t + 0.1, t, space="hdr")) == pytest.approx(0.1)
    # LDR: a black target against a grey whose sRGB code value is 0.1 -> 20 dB
    grey = ((0.1 + 0.055) / 1.055) ** 2.4
    assert float(IF.psnr(torch.full((8, 8, 3), grey), torch.zeros(8, 8, 3), space="ldr")) == pytest.approx(20.0)
    assert float(IF.rmse(torch.full((8, 8, 3), grey), torch.zeros(8, 8, 3), space="ldr")) == pytest.approx(0.1)
    # exposure acts before the clamp: at +1 stop the grey's code value changes
    assert float(IF.psnr(torch.full((8, 8, 3), grey / 2), torch.zeros(8, 8, 3), space="ldr", exposure=1.0)) == \
        pytest.approx(20.0)


def _reference_ssim(x: np.ndarray, y: np.ndarray, data_range: float) -> tuple[float, np.ndarray]:
    """Straightforward SSIM (Wang et al. 2004) with scipy: Gaussian σ = 1.5 truncated at 5 taps, mirror borders."""
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    maps = []
    for c in range(3):
        a, b = x[..., c], y[..., c]

        def blur(z):
            return gaussian_filter(z, sigma=1.5, truncate=5 / 1.5, mode="mirror")

        mu_a, mu_b = blur(a), blur(b)
        s_aa, s_bb, s_ab = blur(a * a) - mu_a**2, blur(b * b) - mu_b**2, blur(a * b) - mu_a * mu_b
        maps.append(((2 * mu_a * mu_b + c1) * (2 * s_ab + c2)) / ((mu_a**2 + mu_b**2 + c1) * (s_aa + s_bb + c2)))
    m = np.mean(maps, axis=0)
    return float(m.mean()), m


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ssim_matches_an_independent_scipy_implementation(seed):
    t = _images(h=23, w=31, seed=seed, scale=1.5)
    p = _noisy(t, 0.5, seed=seed + 10)
    # LDR: on the tone-mapped images, data range 1
    value, smap = IF.ssim(p, t, space="ldr", return_map=True)
    ref_value, ref_map = _reference_ssim(images.tonemap(p).numpy(), images.tonemap(t).numpy(), 1.0)
    assert float(value) == pytest.approx(ref_value, abs=1e-10)
    np.testing.assert_allclose(smap.numpy(), ref_map, atol=1e-10)
    # HDR: on log(1 + x), data range = the target's max of log(1 + x)
    lp, lt = np.log1p(p.numpy()), np.log1p(t.numpy())
    ref_value, _ = _reference_ssim(lp, lt, float(lt.max()))
    assert float(IF.ssim(p, t, space="hdr")) == pytest.approx(ref_value, abs=1e-10)


def test_ssim_map_shape_and_range():
    t = _images(n=3, h=17, w=13)
    p = _noisy(t, 3.0)
    value, smap = IF.ssim(p, t, space="ldr", return_map=True)
    assert smap.shape == (3, 17, 13)
    assert float(smap.min()) >= -1.0 and float(smap.max()) <= 1.0 and float(smap.min()) < 0.99
    assert float(value) == pytest.approx(float(smap.mean()))
    single_value, single_map = IF.ssim(p[1], t[1], space="ldr", return_map=True)
    assert single_map.shape == (17, 13)
    torch.testing.assert_close(single_map, smap[1])
    anti = IF.ssim(1.0 - images.tonemap(t), images.tonemap(t), space="ldr")  # inverted image: far from 1
    assert float(anti) < 0.2


def test_flip_uses_the_package_as_documented():
    import flip_evaluator

    t = _images(h=20, w=20, scale=1.0)
    p = _noisy(t, 0.3)
    value, fmap = IF.flip(p, t, space="ldr", return_map=True)
    direct, _, used = flip_evaluator.evaluate(images.tonemap(t).float().numpy(), images.tonemap(p).float().numpy(),
                                              "LDR", applyMagma=False, parameters={"ppd": 67.0})
    assert used["ppd"] == 67.0
    np.testing.assert_array_equal(fmap.numpy(), direct[..., 0])
    assert fmap.shape == (20, 20) and 0 <= float(fmap.min()) and float(fmap.max()) <= 1
    assert float(value) == pytest.approx(float(fmap.double().mean()))
    hdr_value, hdr_map = IF.flip(p * 4, t * 4, space="hdr", return_map=True)
    assert hdr_map.shape == (20, 20) and 0 < float(hdr_value) < 1
    assert float(IF.flip(p, t, space="ldr", ppd=20.0)) != pytest.approx(float(value))


def test_hdr_flip_survives_black_images():
    """The library exits the process on a black HDR reference; the wrapper must not."""
    black, lit = torch.zeros(12, 12, 3), _images(h=12, w=12)
    assert float(IF.flip(black, black, space="hdr")) == 0.0
    assert 0 < float(IF.flip(lit, black, space="hdr")) <= 1
    assert 0 < float(IF.flip(black, lit, space="hdr")) <= 1


# --------------------------------------------------------------------------- properties

_seeds = st.integers(0, 2**16)


@settings(max_examples=25, deadline=None)
@given(_seeds, st.sampled_from(IF.SPACES))
def test_mse_and_ssim_are_symmetric(seed, space):
    a, b = _images(h=12, w=14, seed=seed), _images(h=12, w=14, seed=seed + 1)
    assert float(IF.mse(a, b, space=space)) == float(IF.mse(b, a, space=space))
    kw = {"data_range": 2.0} if space == "hdr" else {}  # the default HDR range is the target's: asymmetric
    assert float(IF.ssim(a, b, space=space, **kw)) == pytest.approx(float(IF.ssim(b, a, space=space, **kw)), abs=1e-12)


@settings(max_examples=25, deadline=None)
@given(_seeds, st.floats(1e-3, 1.0), st.floats(1.1, 10.0))
def test_psnr_decreases_as_noise_grows(seed, small, factor):
    t = _images(h=10, w=10, seed=seed)
    g = torch.Generator().manual_seed(seed + 7)
    noise = torch.randn(t.shape, generator=g, dtype=torch.float64)
    low = float(IF.psnr(t + small * noise, t, space="hdr"))
    high = float(IF.psnr(t + small * factor * noise, t, space="hdr"))
    assert low > high
    ldr_low = float(IF.psnr(_noisy(t, small, seed), t, space="ldr"))
    ldr_high = float(IF.psnr(_noisy(t, small * factor, seed), t, space="ldr"))
    assert ldr_low >= ldr_high


@settings(max_examples=10, deadline=None)
@given(_seeds, st.sampled_from(sorted(FUNCTIONAL)), st.sampled_from(IF.SPACES), st.integers(1, 4))
def test_a_batch_scores_the_mean_of_its_images(seed, name, space, n):
    fn = FUNCTIONAL[name]
    t = _images(n=n, h=11, w=12, seed=seed)
    p = _noisy(t, 0.8, seed=seed + 1)
    singles = [float(fn(p[i], t[i], space=space)) for i in range(n)]
    assert float(fn(p, t, space=space)) == pytest.approx(sum(singles) / n, rel=1e-12)
    torch.testing.assert_close(fn(p, t, space=space, reduction="none"), torch.tensor(singles, dtype=torch.float64))


@settings(max_examples=10, deadline=None)
@given(_seeds, st.sampled_from(IMAGE_METRICS), st.lists(st.integers(1, 3), min_size=1, max_size=4))
def test_chunked_streaming_equals_one_shot(seed, name, chunks):
    spec = registry.get("metrics", name)
    n = sum(chunks)
    t = _images(n=n, h=11, w=11, seed=seed)
    p = _noisy(t, 0.5, seed=seed + 1)
    whole, parts = spec.load()(), spec.load()()
    whole.update(p, t)
    start = 0
    for size in chunks:
        if size == 1:
            parts.update(p[start], t[start])  # a single image (H, W, 3)
        else:
            parts.update(p[start:start + size], t[start:start + size])
        start += size
    assert parts.compute() == pytest.approx(whole.compute(), rel=1e-12)
    fn = FUNCTIONAL[name.rsplit("_", 1)[0]]
    assert whole.compute() == pytest.approx(float(fn(p, t, space=name.rsplit("_", 1)[1])), rel=1e-12)


# --------------------------------------------------------------------------- registration


@pytest.mark.parametrize("name", IMAGE_METRICS)
def test_image_metrics_are_registered_as_image_domain(name):
    spec = registry.get("metrics", name)
    metric = spec.load()()
    assert spec.tags == frozenset({"image"}) and metric.domain == "image"
    assert metric.unit == spec.unit and metric.higher_is_better == spec.higher_is_better
    assert spec.higher_is_better == name.startswith(("psnr", "ssim"))
    with pytest.raises(ValueError, match="before any update"):
        metric.compute()


def test_harness_configs_name_metrics_of_their_kind():
    """Accuracy harnesses evaluate on BRDF values (no image metric); the render harness on images only."""
    from omegaconf import OmegaConf

    from brdfbench.pipeline.config import harness_config

    by_kind: dict[str, set[str]] = {"accuracy": set(harness_config().metrics)}
    for path in (REPO / "conf" / "harness").glob("*.yaml"):
        cfg = OmegaConf.load(path)
        by_kind.setdefault(cfg.get("kind", "accuracy"), set()).update(cfg.get("metrics", []))
    assert by_kind["accuracy"] and by_kind["render"]
    assert not [m for m in by_kind["accuracy"] if "image" in registry.get("metrics", m).tags]
    assert all("image" in registry.get("metrics", m).tags for m in by_kind["render"])


def test_a_metric_class_needs_a_space():
    with pytest.raises(TypeError, match="no space"):
        IM.PSNR()
    m = IM.PSNRHDR(data_range=1.0)
    t = _images(h=12, w=12, scale=1.0)
    m.update(t + 0.1, t)
    assert m.compute() == pytest.approx(20.0)


# --------------------------------------------------------------------------- image files


def test_exr_round_trip_is_exact_float32(tmp_path):
    img = _images(h=9, w=7, scale=3.0).float()
    img[0, 0] = torch.tensor([0.0, 1e-30, 6.5e4])
    img[1, 1] = torch.tensor([1e30, 1.5e38, 1.17549435e-38])  # doubled below: still finite in float32
    path = tmp_path / "render.exr"
    images.write_exr(path, img)
    back = images.read_exr(path)
    assert back.dtype == torch.float32 and back.shape == (9, 7, 3)
    assert torch.equal(back, img)
    images.write_exr(path, img.double() * 2)  # float64 is written as float32, atomically over the old file
    assert torch.equal(images.read_exr(path), (img.double() * 2).float())
    assert [p.name for p in tmp_path.iterdir()] == ["render.exr"]


@pytest.mark.parametrize("exposure", [0.0, 1.5, -2.0])
def test_png_round_trip_within_one_code_value(tmp_path, exposure):
    img = _images(h=10, w=13, scale=2.0, seed=3)
    path = tmp_path / "render.png"
    images.write_png(path, img, exposure=exposure)
    with Image.open(path) as f:
        assert f.format == "PNG" and f.mode == "RGB"
        data = np.asarray(f).astype(np.float64) / 255
    assert data.shape == (10, 13, 3)
    assert np.abs(data - images.tonemap(img, exposure).numpy()).max() <= 1 / 255
    assert [p.name for p in tmp_path.iterdir()] == ["render.png"]


@pytest.mark.parametrize("writer", [images.write_exr, images.write_png])
def test_writing_a_non_finite_image_names_the_path_and_pixel_count(tmp_path, writer):
    img = torch.ones(4, 5, 3)
    img[0, 0, 1] = float("nan")
    img[2, 3] = float("inf")
    path = tmp_path / "bad.img"
    with pytest.raises(ValueError, match=r"bad\.img.*2 pixels have NaN/Inf"):
        writer(path, img)
    with pytest.raises(ValueError, match=r"bad\.img.*1 pixels have NaN/Inf"):
        writer(path, torch.zeros(2, 2, 3, dtype=torch.float64).index_fill_(1, torch.tensor([1]), 1e39)[:1])
    with pytest.raises(ValueError, match=r"bad\.img.*shape \(H, W, 3\), got \(4, 5\)"):
        writer(path, torch.ones(4, 5))
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary left


def test_reading_a_bad_exr_raises_data_error_naming_the_file(tmp_path):
    import OpenEXR

    text = tmp_path / "notes.exr"
    text.write_text("not an image")
    with pytest.raises(DataError, match=r"notes\.exr.*not an OpenEXR file"):
        images.read_exr(text)
    png = tmp_path / "image.exr"
    images.write_png(png, torch.ones(3, 3, 3))
    with pytest.raises(DataError, match=r"image\.exr.*not an OpenEXR file"):
        images.read_exr(png)
    depth = tmp_path / "depth.exr"
    OpenEXR.File({}, {"Z": np.ones((4, 4), dtype=np.float32)}).write(str(depth))
    with pytest.raises(DataError, match=r"depth\.exr.*lacks channel\(s\) R, G, B.*'Z'"):
        images.read_exr(depth)
    good = tmp_path / "good.exr"
    images.write_exr(good, torch.ones(8, 8, 3))
    cut = tmp_path / "cut.exr"
    cut.write_bytes(good.read_bytes()[:40])
    with pytest.raises(DataError, match=r"cut\.exr"):
        images.read_exr(cut)
    with pytest.raises(DataError, match=r"missing\.exr: no such EXR file"):
        images.read_exr(tmp_path / "missing.exr")
    with pytest.raises(DataError, match="is not a file"):
        images.read_exr(tmp_path)


# --------------------------------------------------------------------------- bad metric input


@pytest.mark.parametrize("name", sorted(FUNCTIONAL))
def test_bad_metric_input_is_a_clear_value_error(name):
    fn = FUNCTIONAL[name]
    ok = _images(h=12, w=12)
    with pytest.raises(ValueError, match=r"shapes differ: \(12, 12, 3\) vs \(12, 11, 3\)"):
        fn(ok, ok[:, :11], space="ldr")
    with pytest.raises(ValueError, match=r"shape \(H, W, 3\) or \(N, H, W, 3\), got \(12, 12, 4\)"):
        fn(torch.ones(12, 12, 4), torch.ones(12, 12, 4), space="ldr")
    with pytest.raises(ValueError, match=r"got \(12, 3\)"):
        fn(torch.ones(12, 3), torch.ones(12, 3), space="hdr")
    bad = ok.clone()
    bad[0, 0, 0], bad[3, 2, 1] = float("nan"), float("-inf")
    with pytest.raises(ValueError, match="pred has 2 non-finite"):
        fn(bad, ok, space="hdr")
    with pytest.raises(ValueError, match="target has 2 non-finite"):
        fn(ok, bad, space="ldr")
    with pytest.raises(ValueError, match="float tensor.*torch.uint8"):
        fn(ok.to(torch.uint8), ok.to(torch.uint8), space="ldr")
    with pytest.raises(ValueError, match="unknown space 'linear'"):
        fn(ok, ok, space="linear")
    with pytest.raises(ValueError, match="unknown reduction 'sum'"):
        fn(ok, ok, space="ldr", reduction="sum")


def test_metric_specific_bad_input():
    ok, black = _images(h=12, w=12), torch.zeros(12, 12, 3)
    with pytest.raises(ValueError, match="target image 0 has no positive value.*data_range"):
        IF.psnr(ok, black, space="hdr")
    with pytest.raises(ValueError, match="target image 0 has no positive value"):
        IF.ssim(ok, black, space="hdr")
    with pytest.raises(ValueError, match="data_range must be a positive finite number, got -1"):
        IF.psnr(ok, ok, space="ldr", data_range=-1.0)
    with pytest.raises(ValueError, match=r"at least 11×11.*\(12, 10, 3\)"):
        IF.ssim(ok[:, :10], ok[:, :10], space="ldr")
    with pytest.raises(ValueError, match="non-negative radiance; pred has minimum -0.5"):
        IF.ssim(torch.full((12, 12, 3), -0.5), ok, space="hdr")
    with pytest.raises(ValueError, match="non-negative radiance; target has minimum -1"):
        IF.flip(ok, -ok.clamp_min(1.0), space="hdr")
    with pytest.raises(ValueError, match="ppd.*got 0"):
        IF.flip(ok, ok, space="ldr", ppd=0)
    with pytest.raises(ValueError, match="float32 range"):
        IF.flip(ok * 1e300, ok * 1e300, space="hdr")
    # negative radiance is fine where the metric is defined for it (tone mapping clamps it)
    assert float(IF.flip(-ok, -ok, space="ldr")) == 0.0
