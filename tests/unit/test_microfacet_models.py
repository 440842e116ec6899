"""Beckmann Cook-Torrance variants and Löw et al.'s models (representations/microfacet_models.py):
the papers' formulas (written here independently, in numpy from spherical angles), the
normalisations they state, fp32 stability at the coefficient bounds and at the most extreme
published fits, the mapping of published fits, the conformance kit, a fit, and the drjit twins.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from brdfbench import merl, mitsuba_env
from brdfbench.coords import from_half_diff, spherical_to_vector
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.testing import adversarial_pairs
from brdfbench_representations import microfacet_models as mm
from brdfbench_representations.analytic_terms import geometry
from brdfbench_representations.microfacet_models import CookTorrance1982, CookTorranceBeckmann, LowMicrofacet, LowSmooth
from quadrature import normal_incidence_albedo as rgb_normal_incidence_albedo

F64 = torch.float64
MODELS = {cls.NAME: cls for cls in (CookTorranceBeckmann, CookTorrance1982, LowSmooth, LowMicrofacet)}

# Published fits (BBM's fits/ files): the lead's copy in the package, else the shared reference.
_HERE = Path(__file__).resolve()
FIT_DIRS = [Path(mm.__file__).parent / "published_fits", _HERE.parents[3] / "shared" / "reference" / "published_fits"]
FIT_DIR = next((d for d in FIT_DIRS if (d / "low_lowsmooth_E2.fit").is_file()), None)
needs_fits = pytest.mark.skipif(FIT_DIR is None, reason="the published .fit files are not here")
FIT_FILES = {
    "cook_torrance_beckmann": ["ngan_cooktorrance.fit"],
    "cook_torrance_1982": ["low_cooktorrance_E1.fit", "low_cooktorrance_E2.fit"],
    "low_smooth": ["low_lowsmooth_E2.fit"],
    "low_microfacet": ["low_lowmicrofacet_E2.fit"],
}
_LINE = re.compile(r"^\s*(?P<name>[\w-]+)\s*=\s*Aggregate\(Lambertian\(albedo = \[(?P<kd>[^\]]*)\]\),\s*"
                   r"(?P<model>\w+)\((?P<params>.*)\)\)\s*$")
_PARAM = re.compile(r"(\w+)\s*=\s*(\[[^\]]*\]|[-+0-9.eE]+)")


def published(file: str) -> dict[str, tuple[list[float], str, dict]]:
    """{material: (diffuse, BBM model name, params)} of one .fit file (a test-only reader)."""
    out = {}
    for line in (FIT_DIR / file).read_text().splitlines():
        m = _LINE.match(line)
        if m is None:
            continue
        params = {}
        for key, value in _PARAM.findall(m["params"]):
            nums = [float(v) for v in value.strip("[]").split(",")]
            params[key] = nums if value.startswith("[") else nums[0]
        out[m["name"]] = ([float(v) for v in m["kd"].split(",")], m["model"], params)
    return out


def model(name: str, **coeffs):
    return MODELS[name]().set_coefficients(**coeffs)


# Moderate coefficient sets; the published ones are added by the tests that read the files.
MODERATE = {
    "cook_torrance_beckmann": [dict(kd=[0.3, 0.2, 0.1], ks=[0.9, 0.8, 0.7], roughness=0.2, eta=0.05),
                               dict(kd=0.1, ks=0.5, roughness=0.6, eta=0.9)],
    "cook_torrance_1982": [dict(kd=[0.3, 0.2, 0.1], ks=[0.9, 0.8, 0.7], roughness=0.15, eta=1.6),
                           dict(kd=0.1, ks=0.2, roughness=1.2, eta=9.0)],
    "low_smooth": [dict(kd=[0.3, 0.2, 0.1], ks=[90.0, 80.0, 70.0], B=3000.0, C=0.7, eta=1.5),
                   dict(kd=0.1, ks=2.0, B=20.0, C=2.2, eta=4.0)],
    "low_microfacet": [dict(kd=[0.3, 0.2, 0.1], ks=[60.0, 50.0, 40.0], B=8000.0, C=0.8, eta=2.2),
                       dict(kd=0.1, ks=2.0, B=30.0, C=2.5, eta=60.0)],
}


# --------------------------------------------------------------------------- the papers' formulas


def _vec(theta, phi):
    return np.stack((np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)), axis=-1)


def fresnel_ref(eta, c):
    """Cook and Torrance 1982's unpolarised dielectric Fresnel at cos c."""
    g = np.sqrt(eta * eta + c * c - 1.0)
    return 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1.0 + (c * (g + c) - 1.0) ** 2 / (c * (g - c) + 1.0) ** 2)


def reference(name: str, c: dict, ti, pi, to, po) -> np.ndarray:
    """The model from the papers' equations, fp64 numpy, from spherical angles (N, 3)."""
    wi, wo = _vec(ti, pi), _vec(to, po)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ch, cd, ci, co = h[:, 2], (wi * h).sum(1), np.cos(ti), np.cos(to)
    tan2 = (1 - ch**2) / ch**2
    g = np.minimum(1.0, np.minimum(2 * ch * ci / cd, 2 * ch * co / cd))
    if name == "cook_torrance_beckmann":  # Ngan et al. 2005
        m = c["roughness"]
        d = np.exp(-tan2 / m**2) / (math.pi * m**2 * ch**4)
        f = c["eta"] + (1 - c["eta"]) * (1 - cd) ** 5
        lobe = d * g * f / (math.pi * ci * co)
    elif name == "cook_torrance_1982":  # Cook and Torrance 1982
        m = c["roughness"]
        d = np.exp(-tan2 / m**2) / (m**2 * ch**4)
        lobe = fresnel_ref(c["eta"], cd) * d * g / (math.pi * ci * co)
    elif name == "low_smooth":  # Löw et al. 2012, smooth surface model, G = 1
        ip, op = wi[:, :2], wo[:, :2]
        dp2 = ((ip + op) ** 2).sum(1)
        cos_proj = np.sqrt(1 - 0.25 * ((ip - op) ** 2).sum(1))
        lobe = (1 + c["B"] * dp2) ** (-c["C"]) * fresnel_ref(c["eta"], cos_proj)
    else:  # Löw et al. 2012, microfacet model with the supplemental fits' 1/π
        s = (1 + c["B"] * (1 - ch)) ** (-c["C"])
        lobe = s * g * fresnel_ref(c["eta"], cd) / (math.pi * ci * co)
    kd = np.broadcast_to(np.asarray(c["kd"], dtype=np.float64), (3,))
    ks = np.broadcast_to(np.asarray(c["ks"], dtype=np.float64), (3,))
    return kd / math.pi + lobe[:, None] * ks


def random_angles(n: int, seed: int, max_deg: float = 85.0):
    rng = np.random.default_rng(seed)
    t = lambda: np.arccos(1 - rng.random(n) * (1 - math.cos(math.radians(max_deg))))  # noqa: E731
    return t(), 2 * math.pi * rng.random(n), t(), 2 * math.pi * rng.random(n)


def near_specular_angles(n: int, seed: int):
    """Angles of pairs near the mirror direction (where the lobes live), θ ≤ 85°."""
    rng = np.random.default_rng(seed)
    ti = np.arccos(1 - rng.random(n) * (1 - math.cos(math.radians(85))))
    pi = 2 * math.pi * rng.random(n)
    to = np.clip(ti + rng.normal(0, 0.05, n), 0.0, math.radians(85))
    po = pi + math.pi + rng.normal(0, 0.05, n)
    return ti, pi, to, po


def evaluate(name: str, c: dict, angles, dtype=F64) -> np.ndarray:
    ti, pi, to, po = (torch.from_numpy(a) for a in angles)
    wi, wo = spherical_to_vector(ti, pi).to(dtype), spherical_to_vector(to, po).to(dtype)
    return model(name, **c).eval(wi, wo).double().numpy()


def _published_sets(name: str, materials: tuple[str, ...] = ("alum-bronze", "chrome-steel", "blue-acrylic")):
    cls = MODELS[name]
    out = []
    for file in FIT_FILES[name]:
        fits = published(file)
        for mat in materials:
            if mat in fits:
                diffuse, bbm, params = fits[mat]
                out.append(cls.from_published(bbm, diffuse, params))
    return out


@pytest.mark.parametrize("name", MODELS)
def test_matches_the_papers_formula(name):
    sets = MODERATE[name] + (_published_sets(name) if FIT_DIR is not None else [])
    for c in sets:
        for angles in (random_angles(20_000, seed=1), near_specular_angles(20_000, seed=2)):
            got, want = evaluate(name, c, angles), reference(name, c, *angles)
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=0, err_msg=str(c))


def test_specs_flops_and_published_names():
    for name, cls in MODELS.items():
        assert cls.NAME == name and [c.name for c in cls.COEFFS[:2]] == ["kd", "ks"]
        assert isinstance(cls.FLOPS, int) and 40 < cls.FLOPS < 80
        assert cls.PUBLISHED_AS and all(isinstance(n, str) for n in cls.PUBLISHED_AS)
    assert CookTorranceBeckmann.PUBLISHED_AS == ("NganCookTorrance",)
    assert CookTorrance1982.PUBLISHED_AS == ("LowCookTorrance",)
    assert LowSmooth.PUBLISHED_AS == ("LowSmooth",)
    assert LowMicrofacet.PUBLISHED_AS == ("LowMicrofacetFit",)


# --------------------------------------------------------------------------- physics


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_reciprocity_is_exact(name, dtype):
    m = model(name, **MODERATE[name][0])
    for family, (wi, wo) in adversarial_pairs(14_000, dtype, seed=11).items():
        assert torch.equal(m.eval(wi, wo), m.eval(wo, wi)), family


def _hemisphere_rule(n: int = 200_000):
    """Midpoint rule in θ over the hemisphere, for integrands symmetric about the normal:
    directions (n, 3) fp64 at φ = 0 and their solid-angle weights 2π sinθ dθ."""
    t = (torch.arange(n, dtype=F64) + 0.5) * (math.pi / 2 / n)
    w = 2 * math.pi * torch.sin(t) * (math.pi / 2 / n)
    return spherical_to_vector(t, torch.zeros_like(t)), w


def _normal_albedo_1d(m, n: int = 200_000) -> float:
    """Channel 0 of the shared quadrature (tests/quadrature.py)."""
    return float(rgb_normal_incidence_albedo(m, n)[0])


@pytest.mark.parametrize("m", [0.05, 0.3, 1.0])
def test_beckmann_normalisation(m):
    """Cook and Torrance's D integrates (·cosθh over the hemisphere of h) to π, Ngan's to 1."""
    h, w = _hemisphere_rule()
    d = mm.beckmann_unnormalised(torch.tensor(1.0 / m**2, dtype=F64), geometry(h, h))
    assert float((d * h[:, 2] * w).sum()) == pytest.approx(math.pi, rel=1e-6)


@pytest.mark.parametrize("b,c", [(30.0, 0.7), (1e4, 1.5), (50.0, 1.0)])
def test_low_ndf_normalisation(b, c):
    """Löw et al.'s sampling normalisation: ∫ (1 + B(1 − cosθh))^(−C) dωh = 2π((1+B)^(1−C) − 1)/(B(1−C))
    (C = 1: 2π log(1+B)/B)."""
    h, w = _hemisphere_rule()
    s = mm.abc_power(torch.tensor(b, dtype=F64), torch.tensor(c, dtype=F64), mm.one_minus_cos_h(geometry(h, h)))
    exact = 2 * math.pi * (math.log1p(b) / b if c == 1.0 else ((1 + b) ** (1 - c) - 1) / (b * (1 - c)))
    assert float((s * w).sum()) == pytest.approx(exact, rel=1e-5)


@pytest.mark.parametrize("b,c", [(30.0, 0.7), (3000.0, 1.2), (50.0, 1.0)])
def test_low_smooth_normal_incidence_integral(b, c):
    """At ωi = n, D_p = sinθo: ∫ S cosθo dωo = π((1+B)^(1−C) − 1)/(B(1−C)) (the lobe divided by
    its Fresnel factor, computed independently at the projected cos √(1 − sin²θo/4))."""
    n = 400_000
    t = (torch.arange(n, dtype=F64) + 0.5) * (math.pi / 2 / n)
    wo = torch.stack((torch.sin(t), torch.zeros_like(t), torch.cos(t)), dim=1)
    wi = torch.zeros_like(wo)
    wi[:, 2] = 1.0
    lobe = model("low_smooth", kd=0.0, ks=1.0, B=b, C=c, eta=1.5).eval(wi, wo)[:, 0].numpy()
    q = fresnel_ref(1.5, np.sqrt(1 - 0.25 * np.sin(t.numpy()) ** 2))
    w = 2 * math.pi * np.cos(t.numpy()) * np.sin(t.numpy()) * (math.pi / 2 / n)
    exact = math.pi * (math.log1p(b) / b if c == 1.0 else ((1 + b) ** (1 - c) - 1) / (b * (1 - c)))
    assert float((lobe / q * w).sum()) == pytest.approx(exact, rel=1e-6)


@pytest.mark.parametrize("f0", [0.04, 0.5])
def test_ngan_smooth_albedo_is_4f0_over_pi(f0):
    """Cook's normalisation 1/(π cos cos) with a normalised D: a smooth lobe reflects 4F0/π at
    normal incidence (G ≈ 1, F ≈ F0 across the narrow lobe)."""
    a = _normal_albedo_1d(model("cook_torrance_beckmann", kd=0.0, ks=1.0, roughness=0.02, eta=f0))
    assert a == pytest.approx(4 * f0 / math.pi, rel=2e-3)


@pytest.mark.parametrize("eta", [1.5, 2.5])
def test_cook_torrance_1982_smooth_albedo_is_4f(eta):
    """Without Beckmann's 1/π (Cook and Torrance 1982): 4 F(η) at normal incidence."""
    a = _normal_albedo_1d(model("cook_torrance_1982", kd=0.0, ks=1.0, roughness=0.02, eta=eta))
    assert a == pytest.approx(4 * ((eta - 1) / (eta + 1)) ** 2, rel=2e-3)


def test_low_microfacet_normal_incidence_albedo():
    """At ωi = n: ∫ f_s cosθo dωo = (4/π) ∫ S G F cosθh dωh (dωo = 4 cosθh dωh); for a narrow
    lobe G ≈ 1, F ≈ F(η, 1), and ∫ S cosθh dωh = 2π ∫₀¹ (1 + B u)^(−C) (1 − u) du."""
    b, c, eta = 1e5, 4.0, 1.8
    a = _normal_albedo_1d(model("low_microfacet", kd=0.0, ks=1.0, B=b, C=c, eta=eta), n=400_000)
    i1 = ((1 + b) ** (1 - c) - 1) / (b * (1 - c))  # ∫ (1+Bu)^-C du
    i2 = (((1 + b) ** (2 - c) - 1) / (b * (2 - c)) - i1) / b  # ∫ u (1+Bu)^-C du
    exact = 4 / math.pi * ((eta - 1) / (eta + 1)) ** 2 * 2 * math.pi * (i1 - i2)
    assert a == pytest.approx(exact, rel=3e-3)


# --------------------------------------------------------------------------- numerical stability


def _bounds(name: str):
    """Corner sets of the shape coefficients' fit bounds, ks at its upper bound."""
    shape = [c for c in MODELS[name].COEFFS[2:]]
    for corner in range(2 ** len(shape)):
        yield {"kd": 0.5, "ks": 1e3, **{c.name: (c.upper if corner >> i & 1 else c.lower) for i, c in enumerate(shape)}}


def _published_extremes(name: str):
    """The published fits holding each parameter's smallest and largest value."""
    cls = MODELS[name]
    fits = [f for file in FIT_FILES[name] for f in published(file).values()]
    out = {}
    for key in fits[0][2]:
        def score(f):
            v = f[2][key]
            return max(v) if isinstance(v, list) else v
        for f in (min(fits, key=score), max(fits, key=score)):
            out[id(f)] = cls.from_published(f[1], f[0], f[2])
    return list(out.values())


def _extreme_sets():
    for name in MODELS:
        for c in _bounds(name):
            shape = "-".join(f"{k}={v:g}" for k, v in c.items() if k not in ("kd", "ks"))
            yield pytest.param(name, c, id=f"{name}-bounds-{shape}")
        yield pytest.param(name, "published", id=f"{name}-published-extremes", marks=needs_fits)


@pytest.mark.parametrize("name,coeffs", list(_extreme_sets()))
def test_extremes_stay_finite_in_fp32(name, coeffs):
    sets = _published_extremes(name) if coeffs == "published" else [coeffs]
    for c in sets:
        m = model(name, **c)
        for dtype in (torch.float32, F64):
            for family, (wi, wo) in adversarial_pairs(7_000, dtype, seed=12).items():
                out = m.eval(wi, wo)
                assert bool(torch.isfinite(out).all()), f"non-finite ({family}, {dtype}, {c})"
                assert bool((out >= 0).all()), f"negative ({family}, {dtype}, {c})"
                assert float(out.max()) < 1e-6 * torch.finfo(dtype).max, f"saturated ({family}, {dtype}, {c})"
                if family == "below_horizon":
                    assert bool((out == 0).all())
                else:
                    kd = torch.as_tensor(c["kd"], dtype=F64).reshape(-1).min()
                    assert bool((out.double() >= kd / math.pi * (1 - 1e-6)).all()), f"lost the diffuse term ({family})"
        # fp32 against fp64 on the very same (fp32) inputs, lobe alone, where it matters: the
        # well-conditioned families and the specular peak (the peak's width in θh ~ 0.5°).
        lobe = model(name, **{**c, "kd": 0.0})
        pairs = adversarial_pairs(7_000, torch.float32, seed=13)
        g = torch.Generator().manual_seed(14)
        u = lambda k: torch.rand(k, generator=g, dtype=F64)  # noqa: E731
        pairs["peak"] = tuple(v.float() for v in from_half_diff(0.01 * u(4000), 2 * math.pi * u(4000),
                                                                 math.radians(85) * u(4000), 2 * math.pi * u(4000)))
        for family in ("mirror", "identical", "normal", "uniform", "grazing", "peak"):
            wi, wo = pairs[family]
            a, b = lobe.eval(wi, wo).double(), lobe.eval(wi.double(), wo.double())
            big = b > 1e-30 * float(b.max()) + 1e-30
            rel = ((a - b).abs() / b)[big]
            worst = float(rel.max()) if rel.numel() else 0.0
            assert worst < 2e-4, f"fp32 off by {worst:.3g} ({family}, {c})"
            assert bool((a[~big] <= 1e-29 * float(b.max()) + 1e-29).all())


def test_beckmann_has_no_overflow_at_grazing_half_vectors():
    """h_z → 0 (both directions grazing, nearly opposite): the textbook exp(−tan²/m²)/cos⁴θh is
    0/0 or ∞·0 in fp32; the lobe must go to 0, and be exactly 0 at h_z = 0."""
    for hz in (1e-3, 1e-10, 1e-20, 1e-30, 0.0):
        h = torch.tensor([[math.sqrt(1 - hz * hz), 0.0, hz]], dtype=torch.float32)
        g = geometry(h, h)
        for m in (1e-3, 0.3, 4.0):
            for dtype in (torch.float32, F64):
                gd = type(g)(*(t.to(dtype) for t in g))
                d = mm.beckmann_unnormalised(torch.tensor(1.0 / m**2, dtype=dtype), gd)
                assert bool(torch.isfinite(d).all()) and float(d) < 1.0, (hz, m, dtype, d)


# --------------------------------------------------------------------------- published fits


@needs_fits
@pytest.mark.parametrize("name", MODELS)
def test_from_published_reads_every_line(name):
    """Every published line maps onto the coefficients exactly; values lie in the fit bounds
    (k_s: see ks_outside below)."""
    cls = MODELS[name]
    bounds = {c.name: c for c in cls.COEFFS}
    ks_outside = 0
    for file in FIT_FILES[name]:
        fits = published(file)
        assert len(fits) >= 80, file
        for mat, (diffuse, bbm, params) in fits.items():
            c = cls.from_published(bbm, diffuse, params)
            m = cls().set_coefficients(**c)
            assert m.kd.tolist() == diffuse
            scale = params["albedo" if "albedo" in params else "A"]
            assert m.ks.tolist() == scale
            for key in c:
                if key not in ("kd", "ks"):
                    assert float(m.coeffs[key]) == params[key]
                    assert bounds[key].lower <= params[key] <= bounds[key].upper, (mat, key, params[key])
            assert all(bounds["kd"].lower <= v <= bounds["kd"].upper for v in diffuse)
            ks_outside += max(scale) > bounds["ks"].upper
    # every published scale lies inside the fit bounds (Löw's A up to ~5.7e3: a wider k_s bound)
    assert ks_outside == 0


@needs_fits
def test_published_line_evaluates_as_the_paper():
    """alum-bronze of each file, evaluated from from_published, against the formula above."""
    angles = near_specular_angles(5000, seed=3)
    for name, files in FIT_FILES.items():
        for file in files:
            diffuse, bbm, params = published(file)["alum-bronze"]
            c = MODELS[name].from_published(bbm, diffuse, params)
            assert c["kd"] == diffuse
            np.testing.assert_allclose(evaluate(name, c, angles), reference(name, c, *angles), rtol=1e-9, atol=0)


GOOD = {
    "cook_torrance_beckmann": ("NganCookTorrance", {"albedo": [0.03, 0.02, 0.01], "eta": 0.117, "roughness": 0.0137}),
    "cook_torrance_1982": ("LowCookTorrance", {"albedo": [0.07, 0.05, 0.04], "roughness": 0.0676, "eta": 2.15}),
    "low_smooth": ("LowSmooth", {"A": [164.2, 120.7, 86.7], "B": 16711.8, "C": 0.66, "eta": 1.56}),
    "low_microfacet": ("LowMicrofacetFit", {"A": [51.7, 37.9, 27.4], "B": 10482.1, "C": 0.82, "eta": 2.24}),
}
BAD = {
    "cook_torrance_beckmann": [({"roughness": -0.1}, "roughness"), ({"roughness": 0.0}, "roughness"),
                               ({"eta": 1.5}, "eta"), ({"eta": -0.01}, "eta")],
    "cook_torrance_1982": [({"roughness": -0.1}, "roughness"), ({"eta": 0.0}, "eta"),
                           ({"albedo": [0.1, -0.1, 0.1]}, "albedo")],
    "low_smooth": [({"B": -1.0}, "'B'"), ({"C": -0.5}, "'C'"), ({"eta": -1.5}, "eta"), ({"A": [1.0, 2.0]}, "'A'")],
    "low_microfacet": [({"B": float("nan")}, "'B'"), ({"C": float("inf")}, "'C'"), ({"A": "big"}, "'A'"),
                       ({"eta": [1.5, 1.6]}, "eta")],
}


@pytest.mark.parametrize("name", MODELS)
def test_from_published_refuses_bad_input(name):
    cls = MODELS[name]
    bbm, good = GOOD[name]
    diffuse = [0.01, 0.02, 0.03]
    c = cls.from_published(bbm, diffuse, good)
    assert c["kd"] == diffuse
    with pytest.raises(ValueError, match="NganWard"):
        cls.from_published("NganWard", diffuse, good)
    missing = dict(good)
    key = next(iter(missing))
    del missing[key]
    with pytest.raises(ValueError, match=f"missing parameter.*{key}"):
        cls.from_published(bbm, diffuse, missing)
    with pytest.raises(ValueError, match="unknown parameter.*'sharpness'"):
        cls.from_published(bbm, diffuse, {**good, "sharpness": 3.0})
    with pytest.raises(ValueError, match="diffuse albedo"):
        cls.from_published(bbm, [0.1, 0.2], good)
    for change, what in BAD[name]:
        with pytest.raises(ValueError, match=re.escape(what) if what.startswith("'") else what):
            cls.from_published(bbm, diffuse, {**good, **change})


# --------------------------------------------------------------------------- kit, fit, kernel


RECOVERY = {
    "cook_torrance_beckmann": dict(kd=[0.3, 0.1, 0.05], ks=[0.8, 0.9, 1.0], roughness=0.15, eta=0.08),
    "cook_torrance_1982": dict(kd=[0.3, 0.1, 0.05], ks=[0.2, 0.25, 0.3], roughness=0.1, eta=1.7),
    "low_smooth": dict(kd=[0.05, 0.04, 0.03], ks=[60.0, 50.0, 40.0], B=5000.0, C=0.7, eta=1.6),
    "low_microfacet": dict(kd=[0.05, 0.04, 0.03], ks=[30.0, 25.0, 20.0], B=8000.0, C=0.9, eta=2.0),
}


@pytest.mark.parametrize("name", MODELS)
def test_fit_recovers_a_rendered_table(name):
    wi, wo = merl.grid_directions()
    truth = RECOVERY[name]
    values = model(name, **truth).eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    valid = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)
    target = Material(f"self-{name}", MerlTable.from_values(values, valid), "synthetic-self")
    fitted = MODELS[name](n_samples=4096, restarts=1).fit(target, seed=0)
    assert fitted.fit_loss < 1e-5, (fitted.fit_loss, fitted.coeffs)
    for key, want in truth.items():
        want = torch.tensor(want, dtype=F64).reshape(-1).expand_as(fitted.coeffs[key])
        torch.testing.assert_close(fitted.coeffs[key], want, rtol=1e-3, atol=1e-5)


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
@pytest.mark.parametrize("name", MODELS)
def test_drjit_kernel_matches_torch(name):
    extremes = list(_bounds(name))
    sets = MODERATE[name] + [extremes[0], extremes[-1]] + (_published_extremes(name) if FIT_DIR is not None else [])
    pairs = adversarial_pairs(14_000, torch.float32, seed=21)
    pairs["peak"] = near_peak = tuple(v.float() for v in from_half_diff(
        *(torch.rand(4000, generator=torch.Generator().manual_seed(k), dtype=F64) * s
          for k, s in enumerate((0.02, 2 * math.pi, math.radians(85), 2 * math.pi)))))
    assert near_peak[0].shape == (4000, 3)
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        def vec(t):
            return mi.Vector3f(*(mi.Float(np.ascontiguousarray(t[:, k].numpy())) for k in range(3)))

        for c in sets:
            m = model(name, **c)
            kernel = m.drjit_kernel()
            assert kernel is not None and kernel.name == name
            for family, (wi, wo) in pairs.items():
                if family == "below_horizon":
                    continue  # the adapter masks those before the kernel
                got = np.stack([np.asarray(v) for v in kernel.eval(vec(wi), vec(wo))], axis=1)
                want = m.eval(wi, wo).numpy()
                cos = wo[:, 2:3].numpy()
                # The dielectric Fresnel's g − c cancels for η → 1 (relative error ~ eps·c/(g − c)),
                # which magnifies a 1-ulp difference of cosθd (torch's and drjit's norms) at η = 1.01.
                rtol = 2e-5
                np.testing.assert_allclose(got * cos, want * cos, rtol=rtol, atol=1e-6, err_msg=f"{family} {c}")
    assert type("Sub", (MODELS[name],), {})().drjit_kernel() is None  # a subclass may change the lobe
