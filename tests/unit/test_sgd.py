"""Bagher et al.'s SGD model (`sgd`): the paper's formula, its normalisation, fp32 stability,
the published MERL fits (BBM's bagher_sgd.fit), the conformance kit, a fit, the drjit kernel."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.special import gamma, gammaincc

import brdfbench_representations
from brdfbench import merl, mitsuba_env
from brdfbench.coords import from_half_diff, spherical_to_vector
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.testing import adversarial_pairs
from brdfbench_representations import fitting
from brdfbench_representations.sgd import COEFFS_SHAPE, SGD

F64 = torch.float64
TAGS = frozenset({"isotropic", "reciprocal", "fittable", "analytic"})
_FIT_FILES = (Path(brdfbench_representations.__file__).with_name("published_fits") / "bagher_sgd.fit",
              *(p / "shared" / "reference" / "published_fits" / "bagher_sgd.fit" for p in Path(__file__).resolve().parents))
FIT_FILE = next((p for p in _FIT_FILES if p.is_file()), None)
needs_fits = pytest.mark.skipif(FIT_FILE is None, reason="bagher_sgd.fit is not here")
PUBLISHED_EXTREMES = ("specular-orange-phenolic", "pink-fabric", "green-acrylic", "chrome-steel", "white-acrylic",
                      "green-metallic-paint2", "silicon-nitrade", "beige-fabric", "white-paint", "light-red-paint",
                      "blue-rubber", "black-fabric")


# --------------------------------------------------------------------------- independent references


def upper_gamma(a: float, x: float) -> float:
    """Γ(a, x) for any real a ≠ 0, −1, …: scipy's regularised form for a > 0, else
    Γ(a, x) = (Γ(a + 1, x) − x^a e^−x)/a."""
    if a > 0:
        return float(gammaincc(a, x) * gamma(a))
    return (upper_gamma(a + 1, x) - x**a * math.exp(-x)) / a


def normalisation(alpha: float, p: float) -> float:
    """K_ap = 1/(α Γ(1 − p, α)): ∫ D cosθh dωh = 1 (π ∫ P22(x) dx over x = tan²θh)."""
    return 1.0 / (alpha * upper_gamma(1.0 - p, alpha))


def reference(c: dict, ti, pi_, to, po) -> np.ndarray:
    """The paper's model in numpy from spherical angles, (N, 3): the textbook forms (tan, pow,
    1 − exp), fp64, fine away from the hard cases."""
    def d(t, p):
        return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)

    wi, wo = d(ti, pi_), d(to, po)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    theta_h = np.arccos(np.clip(h[:, 2], -1, 1))[:, None]
    cos_d = np.sum(wi * h, axis=1)[:, None]
    rgb = {k: np.broadcast_to(np.asarray(v, dtype=np.float64), (3,)) for k, v in c.items()}
    a, p = rgb["alpha"], rgb["p"]
    x = np.tan(theta_h) ** 2
    ndf = rgb["K_ap"] * np.exp(-(a + x / a)) / (a + x / a) ** p / (np.pi * np.cos(theta_h) ** 4)

    def g1(theta):
        t = theta[:, None] - rgb["sh_theta0"]
        with np.errstate(over="ignore"):
            g = 1 + rgb["sh_lambda"] * (1 - np.exp(rgb["sh_c"] * np.maximum(t, 0.0) ** rgb["sh_k"]))
        return np.where(t > 0, np.maximum(g, 0.0), 1.0)

    fresnel = rgb["f0"] - rgb["f1"] * cos_d + (1 - rgb["f0"]) * (1 - cos_d) ** 5
    spec = ndf * g1(ti) * g1(to) * fresnel / (np.pi * np.cos(ti)[:, None] * np.cos(to)[:, None])
    return rgb["kd"] / np.pi + rgb["ks"] * spec


def published_lines() -> dict[str, tuple[list, dict]]:
    """name -> (Lambertian albedo, Bagher parameters) of every line, read with a regex."""
    out = {}
    for line in FIT_FILE.read_text().splitlines():
        m = re.match(r"(\S+) = Aggregate\(Lambertian\(albedo = (\[[^\]]*\])\), Bagher\((.*)\)\)\s*$", line)
        if m:
            params = {k: json.loads(v) for k, v in re.findall(r"(\w+) = (\[\[.*?\]\]|\[[^\]]*\])", m.group(3))}
            out[m.group(1)] = (json.loads(m.group(2)), params)
    return out


@pytest.fixture(scope="module")
def published():
    if FIT_FILE is None:
        pytest.skip("bagher_sgd.fit is not here")
    lines = published_lines()
    assert len(lines) == 100
    return lines


def shadowing_c(lam, theta0, k):
    """c with G1(π/2) = 0: log(1 + 1/Λ)/(π/2 − θ0)^k."""
    return math.exp(math.log(math.log1p(1 / lam)) - k * math.log(math.pi / 2 - theta0))


def coeffs(alpha=0.05, p=0.45, f0=0.05, f1=-0.95, lam=3.0, theta0=0.3, k=20.0, kd=(0.05, 0.04, 0.03),
           ks=(0.3, 0.25, 0.2), K=None, c=None) -> dict:
    """A full, consistent coefficient set (K_ap the normalisation, c zeroing G1 at the horizon)."""
    return dict(kd=list(np.broadcast_to(kd, (3,))), ks=list(np.broadcast_to(ks, (3,))), alpha=alpha, p=p, K_ap=normalisation(alpha, p) if K is None else K,
                f0=f0, f1=f1, sh_lambda=lam, sh_c=shadowing_c(lam, theta0, k) if c is None else c, sh_k=k,
                sh_theta0=theta0)


MODERATE = [
    coeffs(),
    coeffs(alpha=0.3, p=1.2, f0=0.9, f1=0.1, lam=0.5, theta0=-0.4, k=8.0, kd=(0.2, 0.1, 0.3), ks=(2.0, 1.0, 0.5)),
    # RGB shapes differ per channel
    dict(coeffs(), alpha=[0.01, 0.1, 0.5], p=[0.2, 0.8, 1.6], K_ap=[normalisation(0.01, 0.2), normalisation(0.1, 0.8),
                                                                normalisation(0.5, 1.6)], sh_k=[10.0, 30.0, 300.0],
         sh_c=[shadowing_c(3.0, 0.3, k) for k in (10.0, 30.0, 300.0)]),
]


def model(**c) -> SGD:
    return SGD().set_coefficients(**c)


def angles(n: int, seed: int, max_deg: float = 85.0):
    g = np.random.default_rng(seed)
    t = lambda: np.arccos(1 - g.random(n) * (1 - math.cos(math.radians(max_deg))))  # noqa: E731
    return t(), 2 * math.pi * g.random(n), t(), 2 * math.pi * g.random(n)


def evaluate(m: SGD, ti, pi_, to, po, dtype=F64) -> np.ndarray:
    wi = spherical_to_vector(torch.from_numpy(ti), torch.from_numpy(pi_)).to(dtype)
    wo = spherical_to_vector(torch.from_numpy(to), torch.from_numpy(po)).to(dtype)
    return m.eval(wi, wo).double().numpy()


# --------------------------------------------------------------------------- (a) the formula


def _published_sets():
    if FIT_FILE is None:
        return []
    lines = published_lines()
    return [pytest.param(name, id=name) for name in ("alum-bronze", "chrome", "beige-fabric", "chrome-steel",
                                                      "green-acrylic", "specular-orange-phenolic")
            if name in lines]


@pytest.mark.parametrize("i", range(len(MODERATE)))
def test_matches_the_paper_formula(i):
    a = angles(20_000, seed=i)
    got = evaluate(model(**MODERATE[i]), *a)
    np.testing.assert_allclose(got, reference(MODERATE[i], *a), rtol=1e-9, atol=0)


@needs_fits
@pytest.mark.parametrize("name", _published_sets())
def test_published_fit_matches_the_paper_formula(name, published):
    diffuse, params = published[name]
    c = SGD.from_published("Bagher", diffuse, params)
    a = angles(20_000, seed=3)
    want = reference(c, *a)
    got = evaluate(model(**c), *a)
    # The reference's G1 = 1 − Λ(e^E − 1) cancels near its zero (Λ up to 1.5e7): compare to
    # 1e-9 of each channel's largest value there.
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-9 * float(want.max()))


def test_rgb_channels_are_independent_models():
    """Channel j of an RGB-shaped model is the model with channel j's scalars."""
    c = MODERATE[2]
    a = angles(2000, seed=4)
    got = evaluate(model(**c), *a)
    for j in range(3):
        cj = {k: (v[j] if isinstance(v, list) else v) for k, v in c.items()}
        np.testing.assert_array_equal(got[:, j], evaluate(model(**cj), *a)[:, j])


# --------------------------------------------------------------------------- (b) physics


def _no_shadow_no_fresnel(alpha, p, K=None):
    """kd = 0, ks = 1, G1 ≡ 1 (θ0 = π/2), F ≡ 1 (F0 = 1, F1 = 0): the lobe is D/(π cosθi cosθo)."""
    return coeffs(alpha=alpha, p=p, K=K, f0=1.0, f1=0.0, theta0=math.pi / 2, c=1.0, kd=0.0, ks=1.0)


@pytest.mark.parametrize("alpha,p", [(1.62017e-5, 0.5), (1e-3, 1.776), (0.03, 0.45), (0.3, 0.0), (0.854, 1.2),
                                     (0.05, 2.5)])
def test_ndf_is_normalised(alpha, p):
    """∫ D cosθh dωh = 1 with K_ap = 1/(α Γ(1 − p, α)) (the paper's normalisation), by
    quadrature over u = tan²θh (∫ = π ∫ D cos⁴θh du), D read off the model at ωi = ωo = h."""
    m = model(**_no_shadow_no_fresnel(alpha, p))
    log_u = torch.linspace(math.log(1e-16), math.log(2e3), 40_001, dtype=F64)
    u = torch.exp(log_u)
    theta = torch.atan(torch.sqrt(u))
    w = spherical_to_vector(theta, torch.full_like(theta, 0.3))
    ndf = math.pi * torch.cos(theta) ** 2 * m.eval(w, w)[:, 0]  # lobe(ω, ω) = D/(π cos²θ)
    integrand = math.pi * ndf * torch.cos(theta) ** 4 * u
    total = float(torch.trapezoid(integrand, log_u))
    assert total == pytest.approx(1.0, rel=2e-4)


@pytest.mark.parametrize("alpha", [1e-4, 1e-3])
def test_near_mirror_normal_incidence_albedo_is_four_over_pi(alpha):
    """ρ_s D G F/(π cosθi cosθo): a smooth, unshadowed lobe with F ≡ 1 reflects 4/π of the
    light at normal incidence (dωo = 4 cosθh dωh), the Cook normalisation of BBM's Bagher."""
    m = model(**_no_shadow_no_fresnel(alpha, 0.5))
    log_t = torch.linspace(math.log(1e-9), math.log(math.pi / 2 - 1e-6), 200_001, dtype=F64)
    t = torch.exp(log_t)
    wo = spherical_to_vector(t, torch.zeros_like(t))
    wi = torch.zeros_like(wo)
    wi[:, 2] = 1.0
    integrand = m.eval(wi, wo)[:, 0] * torch.cos(t) * 2 * math.pi * torch.sin(t) * t
    assert float(torch.trapezoid(integrand, log_t)) == pytest.approx(4 / math.pi, rel=1e-3)


@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_reciprocity_is_exact(dtype):
    for c in MODERATE:
        m = model(**c)
        for family, (wi, wo) in adversarial_pairs(14_000, dtype, seed=11).items():
            assert torch.equal(m.eval(wi, wo), m.eval(wo, wi)), family


def test_g1_is_one_below_theta0_and_zero_at_the_horizon():
    """The shadowing of the paper: 1 up to θ0, falling to 0 at π/2 when c = log(1 + 1/Λ)/(π/2 − θ0)^k."""
    c = _no_shadow_no_fresnel(0.3, 0.5)
    c.update(sh_lambda=3.0, sh_theta0=0.4, sh_k=15.0, sh_c=shadowing_c(3.0, 0.4, 15.0))
    unshadowed = model(**_no_shadow_no_fresnel(0.3, 0.5))
    shadowed = model(**c)
    t = torch.tensor([0.0, 0.2, 0.39, 0.8, 1.2, 1.5, math.pi / 2 - 1e-4], dtype=F64)
    w = spherical_to_vector(t, torch.zeros_like(t))
    n = torch.zeros_like(w)
    n[:, 2] = 1.0
    g1 = (shadowed.eval(n, w) / unshadowed.eval(n, w))[:, 0]  # G1(0) G1(θ) = G1(θ)
    x = (t - 0.4).clamp(min=0)
    want = 1 + 3.0 * (1 - torch.exp(c["sh_c"] * x**15.0))
    torch.testing.assert_close(g1, want, rtol=1e-9, atol=1e-12)
    assert float(g1[0]) == 1.0 and float(g1[2]) == 1.0 and 0 < float(g1[-1]) < 2e-3


# --------------------------------------------------------------------------- (c) fp32


def _bound_sets():
    lo = {c.name: c.lower for c in COEFFS_SHAPE}
    hi = {c.name: c.upper for c in COEFFS_SHAPE}
    return [
        coeffs(alpha=lo["alpha"], p=hi["p"], lam=hi["sh_lambda"], k=hi["sh_k"], theta0=lo["sh_theta0"],
               c=lo["sh_c"], f0=hi["f0"], f1=lo["f1"], ks=1e3),
        coeffs(alpha=lo["alpha"], p=hi["p"], lam=68.8, k=856.0, theta0=0.6, f0=hi["f0"], f1=lo["f1"], ks=1e3),
        coeffs(alpha=lo["alpha"], p=lo["p"], lam=lo["sh_lambda"], k=lo["sh_k"], theta0=1.5, f0=lo["f0"], f1=hi["f1"]),
        coeffs(alpha=hi["alpha"], p=hi["p"], lam=1.0, k=50.0, theta0=hi["sh_theta0"], c=hi["sh_c"], ks=1e3),
        coeffs(alpha=hi["alpha"], p=lo["p"], lam=hi["sh_lambda"], k=hi["sh_k"], theta0=0.0, c=lo["sh_c"]),
        coeffs(alpha=1e-3, p=1.0, K=hi["K_ap"], lam=lo["sh_lambda"], k=12.0, theta0=0.5),
    ]


def _extreme_sets():
    sets = [(f"bounds-{i}", c) for i, c in enumerate(_bound_sets())]
    if FIT_FILE is not None:
        lines = published_lines()
        sets += [(n, SGD.from_published("Bagher", *lines[n])) for n in PUBLISHED_EXTREMES]
    return sets


@pytest.mark.parametrize("name,c", _extreme_sets(), ids=[n for n, _ in _extreme_sets()])
def test_extremes_are_finite_and_fp32_agrees_with_fp64(name, c):
    m = model(**c)
    kd_pi = min(np.broadcast_to(c["kd"], (3,))) / math.pi
    cos = np.linspace(0, 1, 1001)[:, None]
    f0, f1 = np.broadcast_to(c["f0"], (3,)), np.broadcast_to(c["f1"], (3,))
    fresnel_nonnegative = bool((f0 - f1 * cos + (1 - f0) * (1 - cos) ** 5 >= 0).all())  # else the lobe is negative
    for family, (wi, wo) in adversarial_pairs(28_000, torch.float32, seed=12).items():
        a, b = m.eval(wi, wo), m.eval(wi.double(), wo.double())  # the same fp32 inputs
        for out in (a, b):
            assert bool(torch.isfinite(out).all()) and bool((out >= 0).all()), family
            assert float(out.max()) < 1e-6 * torch.finfo(out.dtype).max, f"saturated ({family})"
        if family == "below_horizon":
            assert bool((a == 0).all()) and bool((b == 0).all())
            continue
        if fresnel_nonnegative:
            assert bool((b >= kd_pi * (1 - 1e-12)).all()), f"lost the diffuse term ({family})"
        # f·cosθi, the metric's quantity: 1e-4 relative, or 1e-6 of the family's largest value.
        # A shadowing exponent k makes G1 that steep in θ (condition number ~k): an ulp of θ
        # then moves it by k·1e-7 (1e-3 at the bound k = 1e4), in any fp32 evaluation.
        rtol = max(1e-4, 1e-7 * float(np.max(c["sh_k"])))
        fa, fb = a.double() * wi[:, 2:3].double(), b * wi[:, 2:3].double()
        err = (fa - fb).abs() - rtol * fb.abs() - 1e-6 * float(fb.max())
        assert float(err.max()) <= 0, (family, float((fa - fb).abs().max()), float(fb.max()))


@pytest.mark.parametrize("alpha,p,width", [(1.62017e-5, 0.5, 2e-4), (1e-6, 2.5, 1e-5), (1e-3, 1.776, 5e-3)])
def test_narrow_lobes_are_accurate_in_fp32(alpha, p, width):
    """The whole peak of the narrowest lobes (the published α = 1.6e-5 and the bound 1e-6) in
    fp32 to 2e-5 relative against fp64 at the same inputs."""
    g = torch.Generator().manual_seed(13)
    u = lambda: torch.rand(50_000, generator=g, dtype=F64)  # noqa: E731
    wi, wo = from_half_diff(width * u(), 2 * math.pi * u(), math.radians(80) * u(), 2 * math.pi * u())
    wi, wo = wi.float(), wo.float()
    m = model(**dict(coeffs(alpha=alpha, p=p), kd=0.0))
    a, b = m.eval(wi, wo).double(), m.eval(wi.double(), wo.double())
    assert float(((a - b).abs() / b).max()) < 2e-5


# --------------------------------------------------------------------------- (d) published fits


@needs_fits
def test_from_published_maps_a_real_line(published):
    diffuse, params = published["alum-bronze"]
    c = SGD.from_published("Bagher", diffuse, params)
    assert c["kd"] == [0.0478786, 0.0313514, 0.0200638]
    assert c["ks"] == [0.0364976, 0.664975, 0.268836]
    assert c["f0"] == [6.05524, 0.235756, 0.580647] and c["f1"] == [5.05524, 0.182842, 0.476088]
    assert c["K_ap"] == [46.3841, 24.5961, 14.8261] and c["sh_theta0"] == [0.205635, 0.066289, -0.0661091]
    assert c["sh_lambda"] == params["Lambda"] and c["sh_c"] == params["c"] and c["sh_k"] == params["k"]
    m = model(**c)
    for key, value in c.items():
        assert m.coeffs[key].tolist() == value


@needs_fits
def test_every_published_line_maps_within_the_bounds(published):
    """Every published shape value lies inside its fit bound; k_s (the specular albedo) lies
    below _KS's 1e-8 for seven materials (they evaluate as published: bounds only steer fits)."""
    bounds = {c.name: (c.lower, c.upper) for c in SGD.COEFFS}
    below_ks = set()
    for name, (diffuse, params) in published.items():
        c = SGD.from_published("Bagher", diffuse, params)
        for key, values in c.items():
            lo, hi = bounds[key]
            if key == "ks" and min(values) < lo:
                below_ks.add(name)
                continue
            assert all(lo <= v <= hi for v in values), (name, key, values)
    assert below_ks == {"black-fabric", "light-brown-fabric", "pink-fabric", "pink-plastic", "polyurethane-foam",
                        "red-fabric2", "white-fabric"}


@needs_fits
def test_published_conventions(published):
    """What the numbers mean, read off the fits: K is the NDF's normalisation 1/(α Γ(1 − p, α))
    and c is set so that G1(π/2) = 0, i.e. c = log(1 + 1/Λ)/(π/2 − θ0)^k (to the 6 printed digits)."""
    for name, (_, p) in published.items():
        for j in range(3):
            k_norm = normalisation(p["alpha"][j], p["p"][j])
            assert p["K"][j] == pytest.approx(k_norm, rel=1e-5), name
            assert math.log(p["c"][j]) == pytest.approx(
                math.log(shadowing_c(p["Lambda"][j], p["theta0"][j], p["k"][j])), abs=3e-3), name


def test_from_published_refuses_bad_input():
    good = {"albedo": [0.1, 0.2, 0.3], "alpha": [0.01, 0.02, 0.03], "p": [0.4, 0.5, 0.6],
            "eta": [[0.5, 0.6, 0.7], [-0.5, -0.4, -0.3]], "K": [80.0, 40.0, 25.0], "Lambda": [3.0, 3.0, 3.0],
            "c": [1e-3, 1e-3, 1e-3], "k": [12.0, 12.0, 12.0], "theta0": [0.2, 0.2, 0.2]}
    diffuse = [0.01, 0.02, 0.03]
    c = SGD.from_published("Bagher", diffuse, good)
    assert c["kd"] == diffuse and c["f0"] == [0.5, 0.6, 0.7] and c["f1"] == [-0.5, -0.4, -0.3]
    assert SGD.from_published("Bagher", 0.1, {**good, "alpha": 0.05})["alpha"] == [0.05] * 3  # scalars broadcast
    with pytest.raises(ValueError, match="NganWard"):
        SGD.from_published("NganWard", diffuse, good)
    with pytest.raises(ValueError, match="missing parameter.*'Lambda'"):
        SGD.from_published("Bagher", diffuse, {k: v for k, v in good.items() if k != "Lambda"})
    with pytest.raises(ValueError, match="unknown parameter.*'n'"):
        SGD.from_published("Bagher", diffuse, {**good, "n": 1.5})
    with pytest.raises(ValueError, match="diffuse albedo"):
        SGD.from_published("Bagher", [0.1, 0.2], good)
    cases = [
        ({"alpha": [0.01, 0.02]}, "'alpha' needs 1 or 3 values"),
        ({"eta": [[0.5, 0.6, 0.7]]}, "'eta' must be two rows"),
        ({"eta": [[0.5, 0.6, 0.7], [1, 2, 3], [4, 5, 6]]}, "'eta' must be two rows"),
        ({"eta": [[0.5, 0.6, 0.7], [1.0, 2.0]]}, r"'eta\[1\] \(F1\)' needs 1 or 3 values"),
        ({"alpha": [0.01, -0.02, 0.03]}, r"'alpha' = \[0.01, -0.02, 0.03\] is outside the model's domain"),
        ({"alpha": [1e-9, 0.02, 0.03]}, "'alpha' .* outside the model's domain"),
        ({"p": [-0.1, 0.5, 0.6]}, "'p' .* outside"),
        ({"K": [0.0, 40.0, 25.0]}, "'K' .* outside"),
        ({"Lambda": [3.0, -1.0, 3.0]}, "'Lambda' .* outside"),
        ({"c": [-1e-3, 1e-3, 1e-3]}, "'c' .* outside"),
        ({"k": [0.0, 12.0, 12.0]}, "'k' .* outside"),
        ({"albedo": [-0.1, 0.2, 0.3]}, "'albedo' .* outside"),
        ({"theta0": [0.2, float("nan"), 0.2]}, "'theta0' must hold finite numbers"),
        ({"c": [1e-3, "x", 1e-3]}, "'c' must hold finite numbers"),
        ({"alpha": [1e-5, 0.02, 0.03], "p": [9.0, 0.5, 0.6]}, "overflows float32"),
    ]
    for change, what in cases:
        with pytest.raises(ValueError, match=what):
            SGD.from_published("Bagher", diffuse, {**good, **change})


@needs_fits
def test_published_fit_evaluates_through_published_fit(published):
    """The lead's `published_fit` finds this class for "Bagher" lines (where it is present)."""
    pub = pytest.importorskip("brdfbench_representations.published")
    assert pub.published_forms().get("Bagher") is SGD


# --------------------------------------------------------------------------- (e) the kit, (f) a fit


def test_class_declarations():
    assert SGD.NAME == "sgd" and SGD.PUBLISHED_AS == ("Bagher",) and SGD.tags == TAGS
    assert [c.name for c in SGD.COEFFS] == ["kd", "ks", "alpha", "p", "K_ap", "f0", "f1", "sh_lambda", "sh_c",
                                            "sh_k", "sh_theta0"]
    assert all(c.size == 3 for c in SGD.COEFFS)
    assert SGD().flops_per_eval == SGD.FLOPS == 132
    assert type("Sub", (SGD,), {})().drjit_kernel() is None  # a subclass may change the lobe


@pytest.mark.parametrize("alpha", [1e-3, 0.02, 0.1, 0.3, 0.7])
def test_init_shape_matches_the_ggx_half_width(alpha):
    """init_shape's slope distribution P22 (D cos⁴θh) falls to half its peak where GGX's of
    roughness α does (tanθ½ = √(√2 − 1) α, as fitting.py estimates α), and D is normalised."""
    shape = SGD.init_shape(alpha)
    assert shape["K_ap"] == pytest.approx(normalisation(shape["alpha"], shape["p"]), rel=1e-12)
    assert shape["sh_c"] == pytest.approx(shadowing_c(shape["sh_lambda"], shape["sh_theta0"], shape["sh_k"]))
    m = model(**_no_shadow_no_fresnel(shape["alpha"], shape["p"]))
    th = torch.tensor([0.0, math.atan(math.sqrt(math.sqrt(2) - 1) * alpha)], dtype=F64)
    w = spherical_to_vector(th, torch.zeros_like(th))
    p22 = (m.eval(w, w)[:, 0] * torch.cos(th) ** 6).tolist()  # lobe(ω, ω) = D/(π cos²θ)
    assert p22[1] / p22[0] == pytest.approx(0.5, rel=1e-9)


def test_fit_recovers_a_rendered_table(monkeypatch):
    # The shipped refinement budget stops short of the truth, at a point that moves with
    # scipy's L-BFGS-B (1.17 stops elsewhere than earlier releases): recovery is asked of a
    # refinement long enough to converge.
    monkeypatch.setattr(fitting, "MAX_ITER", 1000)
    truth = coeffs(alpha=0.03, p=0.5, f0=0.3, f1=-0.7, lam=2.5, theta0=0.25, k=15.0)
    wi, wo = merl.grid_directions()
    values = model(**truth).eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    valid = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)
    target = Material("self-sgd", MerlTable.from_values(values, valid), "synthetic-self")
    fitted = SGD(n_samples=4096, restarts=1).fit(target, seed=0)
    # 39 coefficients, three of them degenerate with k_s (K_ap, and F's scale); a Lambertian
    # fit scores 0.50 here.
    assert fitted.fit_loss < 1e-2, (fitted.fit_loss, fitted.coeffs)
    torch.testing.assert_close(fitted.kd, torch.tensor(truth["kd"], dtype=F64), rtol=0.05, atol=2e-3)
    assert fitted.metadata()["n_fit_cells"] == 4096


# --------------------------------------------------------------------------- (g) the drjit kernel


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
def test_drjit_kernel_matches_torch():
    sets = MODERATE + _bound_sets()
    if FIT_FILE is not None:
        lines = published_lines()
        sets += [SGD.from_published("Bagher", *lines[n]) for n in ("alum-bronze", *PUBLISHED_EXTREMES)]
    pairs = adversarial_pairs(14_000, torch.float32, seed=21)
    g = torch.Generator().manual_seed(22)
    pairs["peak"] = tuple(v.float() for v in from_half_diff(
        *(torch.rand(4000, generator=g, dtype=F64) * s for s in (0.02, 2 * math.pi, math.radians(85), 2 * math.pi))))
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        def vec(t):
            return mi.Vector3f(*(mi.Float(np.ascontiguousarray(t[:, k].numpy())) for k in range(3)))

        for i, c in enumerate(sets):
            m = model(**c)
            rtol = max(2e-5, 2e-7 * float(np.max(c["sh_k"])))  # G1's steepness, see the fp32 test
            kernel = m.drjit_kernel()
            assert kernel is not None and kernel.name == "sgd"
            for family, (wi, wo) in pairs.items():
                if family == "below_horizon":
                    continue  # the adapter masks those before the kernel
                got = np.stack([np.asarray(v) for v in kernel.eval(vec(wi), vec(wo))], axis=1)
                want = m.eval(wi, wo).numpy()
                cos = wo[:, 2:3].numpy()
                np.testing.assert_allclose(got * cos, want * cos, rtol=rtol, atol=1e-6, err_msg=f"{family} set {i}")
