"""The Ngan-family analytic models (ngan_models.py): the papers' formulas, their physics,
fp32 stability up to the published extremes, the published fits' mapping, the conformance
kit, fitting, and the drjit kernels against torch.

The reference lobes here are written independently, in numpy from spherical angles, from
the papers' equations (and, for the published parameters, BBM's conventions as its headers
state them); they share no code with the models.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

import brdfbench_representations
from brdfbench import merl, mitsuba_env
from brdfbench.plugins import registry
from brdfbench.coords import from_half_diff, spherical_to_vector
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.testing import FAMILIES, adversarial_pairs, representation_checks
from brdfbench_representations.ngan_models import (MODELS, AshikhminShirley, AshikhminShirleyIor, BlinnPhongNgan,
                                                   Lafortune, Phong, Ward, WardDuer)
from quadrature import normal_incidence_albedo as rgb_normal_incidence_albedo

F64 = torch.float64
FITS = Path(brdfbench_representations.__file__).with_name("published_fits")  # the shipped copies
TAGS = frozenset({"isotropic", "reciprocal", "fittable", "analytic"})
CLASSES = {"ward": "Ward", "ward_duer": "WardDuer", "phong": "Phong", "blinn_phong_ngan": "BlinnPhongNgan",
           "lafortune": "Lafortune",
           "ashikhmin_shirley": "AshikhminShirley", "ashikhmin_shirley_ior": "AshikhminShirleyIor"}
#: Each model's published fits: (file, BBM name).
PUBLISHED = {
    "ward": [("ngan_ward.fit", "NganWard")],
    "ward_duer": [("ngan_wardduer.fit", "NganWardDuer")],
    "phong": [("ngan_blinnphong.fit", "NganBlinnPhong")],
    "blinn_phong_ngan": [("ngan_blinnphong.fit", "NganBlinnPhong")],
    "lafortune": [("ngan_lafortune.fit", "NganLafortune")],
    "ashikhmin_shirley": [("ngan_ashikhminshirley.fit", "NganAshikhminShirley")],
    "ashikhmin_shirley_ior": [("low_ashikhminshirley_E1.fit", "LowAshikhminShirley"),
                              ("low_ashikhminshirley_E2.fit", "LowAshikhminShirley")],
}
MODERATE = {
    "ward": [dict(alpha=0.05), dict(alpha=0.3)],
    "ward_duer": [dict(alpha=0.05), dict(alpha=0.3)],
    "phong": [dict(exponent=1.5), dict(exponent=40.0), dict(exponent=2000.0)],
    "blinn_phong_ngan": [dict(exponent=1.5), dict(exponent=40.0), dict(exponent=2000.0)],
    "lafortune": [dict(cxy=-0.6, cz=0.6, exponent=30.0), dict(cxy=-0.8, cz=0.5, exponent=12.0),
                  dict(cxy=-0.4, cz=0.9, exponent=200.0), dict(cxy=0.7, cz=0.7, exponent=8.0),
                  dict(cxy=0.5, cz=-0.3, exponent=3.0)],
    "ashikhmin_shirley": [dict(exponent=20.0, f0=0.05), dict(exponent=800.0, f0=0.9)],
    "ashikhmin_shirley_ior": [dict(exponent=20.0, ior=1.45), dict(exponent=800.0, ior=4.0)],
}
#: The extremes of COEFFS and the most extreme published values (with ks at its upper bound).
EXTREME = {
    "ward": [dict(alpha=1e-3), dict(alpha=1.0), dict(alpha=0.00509)],
    "ward_duer": [dict(alpha=1e-3), dict(alpha=1.0)],
    "phong": [dict(exponent=1e6), dict(exponent=1e-2), dict(exponent=121000.0)],
    "blinn_phong_ngan": [dict(exponent=1e6), dict(exponent=1e-2), dict(exponent=121000.0)],
    "lafortune": [dict(cxy=-2.0, cz=2.0, exponent=1e6), dict(cxy=2.0, cz=-2.0, exponent=1e-2),
                  dict(cxy=-0.707, cz=1.23e-10, exponent=2.29), dict(cxy=-0.578, cz=0.577, exponent=16600.0),
                  dict(cxy=2.0, cz=2.0, exponent=1e6), dict(cxy=-1e-3, cz=2.0, exponent=1e6)],
    "ashikhmin_shirley": [dict(exponent=1e6, f0=1.0), dict(exponent=1e-3, f0=0.0), dict(exponent=78200.0, f0=0.999)],
    "ashikhmin_shirley_ior": [dict(exponent=1e6, ior=50.0), dict(exponent=1e-3, ior=1.01),
                              dict(exponent=621578.388244, ior=10.08556), dict(exponent=0.001997, ior=1.07894)],
}


def model(name: str, **coeffs):
    return MODELS[name]().set_coefficients(**coeffs)


# --------------------------------------------------------------------------- independent references


def angles(n: int, seed: int, max_deg: float = 85.0):
    rng = np.random.default_rng(seed)
    c = math.cos(math.radians(max_deg))
    ti, to = (np.arccos(1 - rng.random(n) * (1 - c)) for _ in range(2))
    pi, po = (2 * math.pi * rng.random(n) for _ in range(2))
    return ti, pi, to, po


def reference_lobe(name: str, c: dict, ti, pi, to, po) -> np.ndarray:
    """The papers' lobes (k_s = 1) in numpy fp64, from spherical angles."""
    wi = np.stack((np.sin(ti) * np.cos(pi), np.sin(ti) * np.sin(pi), np.cos(ti)), 1)
    wo = np.stack((np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)), 1)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    ci, co, ch = np.cos(ti), np.cos(to), h[:, 2]
    cd = (wi * h).sum(1)
    if name in ("ward", "ward_duer"):  # Ward 1992 (isotropic); Dür 2006: cos cos for √(cos cos)
        a = c["alpha"]
        tan2 = (h[:, 0] ** 2 + h[:, 1] ** 2) / ch**2
        norm = np.sqrt(ci * co) if name == "ward" else ci * co
        return np.exp(-tan2 / a**2) / (4 * math.pi * a**2 * norm)
    if name == "phong":  # Lafortune & Willems 1994: (n+2)/(2π) cos^n α, α from the mirror direction
        n = c["exponent"]
        mirror = np.stack((-wi[:, 0], -wi[:, 1], wi[:, 2]), 1)
        cos_a = np.maximum((mirror * wo).sum(1), 0.0)
        return (n + 2) / (2 * math.pi) * cos_a**n
    if name == "blinn_phong_ngan":  # Blinn 1977's half-vector lobe with Ngan et al.'s (n+2)/(2π)
        return (c["exponent"] + 2) / (2 * math.pi) * ch ** c["exponent"]
    if name == "lafortune":  # Lafortune et al. 1997, Cx = Cy, times Ngan's (n+2)/(2π max(C²)^(n/2))
        n, cxy, cz = c["exponent"], c["cxy"], c["cz"]
        u = cxy * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) + cz * wi[:, 2] * wo[:, 2]
        with np.errstate(divide="ignore"):  # in logs: u^n alone underflows for the published n
            log_lobe = n * np.log(np.maximum(u, 0.0)) - n / 2 * np.log(max(cxy**2, cz**2))
        return (n + 2) / (2 * math.pi) * np.exp(log_lobe)
    # Ashikhmin & Shirley 2000 (isotropic), times the Fresnel term
    n = c["exponent"]
    if name == "ashikhmin_shirley":
        fresnel = c["f0"] + (1 - c["f0"]) * (1 - cd) ** 5
    else:  # the unpolarised Fresnel reflectance from Snell's law (s and p amplitudes)
        eta = c["ior"]
        ct = np.sqrt(1 - (1 - cd**2) / eta**2)
        rs = (cd - eta * ct) / (cd + eta * ct)
        rp = (ct - eta * cd) / (ct + eta * cd)
        fresnel = 0.5 * (rs**2 + rp**2)
    return (n + 1) / (8 * math.pi) * ch**n / (cd * np.maximum(ci, co)) * fresnel


def tensors(ti, pi, to, po):
    return (spherical_to_vector(torch.from_numpy(ti), torch.from_numpy(pi)),
            spherical_to_vector(torch.from_numpy(to), torch.from_numpy(po)))


@pytest.mark.parametrize("name,coeffs", [(n, c) for n, cs in MODERATE.items() for c in cs])
def test_lobe_matches_the_paper(name, coeffs):
    a = angles(20_000, seed=1)
    got = model(name, kd=0.0, ks=1.0, **coeffs).eval(*tensors(*a))[:, 0].numpy()
    want = reference_lobe(name, coeffs, *a)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-300)
    assert (want > 0).mean() > 0.2  # not a test of zeros


def test_kd_is_the_lambertian_albedo_and_ks_scales_the_lobe():
    wi, wo = tensors(*angles(1000, seed=2))
    for name, cs in MODERATE.items():
        out = model(name, kd=[0.2, 0.5, 1.0], ks=0.0, **cs[0]).eval(wi, wo)
        torch.testing.assert_close(out, torch.tensor([[0.2, 0.5, 1.0]], dtype=F64).expand(1000, 3) / math.pi, rtol=1e-14, atol=0)
        one = model(name, kd=0.0, ks=1.0, **cs[0]).eval(wi, wo)[:, 0]
        rgb = model(name, kd=0.0, ks=[0.5, 2.0, 3.0], **cs[0]).eval(wi, wo)
        torch.testing.assert_close(rgb, one[:, None] * torch.tensor([0.5, 2.0, 3.0], dtype=F64), rtol=1e-14, atol=0)


def test_lafortune_with_cxy_minus_cz_is_phong_bitwise():
    for dtype in (torch.float32, F64):
        for family, (wi, wo) in adversarial_pairs(14_000, dtype, seed=3).items():
            for scale in (0.577, 1.0, 1.9):
                lf = model("lafortune", kd=0.1, ks=0.7, cxy=-scale, cz=scale, exponent=4060.0).eval(wi, wo)
                ph = model("phong", kd=0.1, ks=0.7, exponent=4060.0).eval(wi, wo)
                assert torch.equal(lf, ph), (family, scale)


def test_lafortune_depends_only_on_the_direction_of_c():
    wi, wo = tensors(*angles(5000, seed=4))
    a = model("lafortune", kd=0.0, ks=1.0, cxy=-0.8, cz=0.5, exponent=50.0).eval(wi, wo)
    b = model("lafortune", kd=0.0, ks=1.0, cxy=-1.6, cz=1.0, exponent=50.0).eval(wi, wo)
    torch.testing.assert_close(a, b, rtol=1e-12, atol=0)


# --------------------------------------------------------------------------- physics


def normal_incidence_albedo(m, n: int = 400_000) -> float:
    """Channel 0 of the shared quadrature (tests/quadrature.py)."""
    return float(rgb_normal_incidence_albedo(m, n)[0])


def directional_albedo(m, theta_i: float, n: int = 400) -> float:
    """∫ f cosθo dωo at incidence θi by a midpoint rule in (cosθo, φo), n × 2n nodes, channel 0."""
    mu = (torch.arange(n, dtype=F64) + 0.5) / n
    phi = (torch.arange(2 * n, dtype=F64) + 0.5) * (math.pi / n)
    mu, phi = (t.reshape(-1) for t in torch.meshgrid(mu, phi, indexing="ij"))
    wo = spherical_to_vector(torch.acos(mu), phi)
    wi = spherical_to_vector(torch.full_like(mu, theta_i), torch.zeros_like(mu))
    return float((m.eval(wi, wo)[:, 0] * mu).sum() * (1.0 / n) * (math.pi / n))


@pytest.mark.parametrize("n", [0.5, 1.0, 10.0, 1e3, 1e5, 1e6])
def test_phong_albedo_at_normal_incidence_is_one(n):
    """Lafortune & Willems: (n+2)/(2π) makes ∫ cos^n α cosθo dωo = 1 at normal incidence."""
    assert normal_incidence_albedo(model("phong", kd=0.0, ks=1.0, exponent=n)) == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("cxy,cz,n", [(-0.3, 0.8, 50.0), (0.5, 0.9, 5.0), (-0.707, 0.707, 1e4)])
def test_lafortune_albedo_at_normal_incidence_is_one(cxy, cz, n):
    """With C_z ≥ |C_xy| the normalised lobe at ωi = normal is (n+2)/(2π) cos^n θo: albedo 1."""
    assert normal_incidence_albedo(model("lafortune", kd=0.0, ks=1.0, cxy=cxy, cz=cz, exponent=n)) == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("name,coeffs", [("phong", dict(exponent=10.0)), ("phong", dict(exponent=300.0)),
                                         ("ashikhmin_shirley", dict(exponent=10.0, f0=1.0)),
                                         ("ashikhmin_shirley", dict(exponent=300.0, f0=1.0))])
@pytest.mark.parametrize("theta_deg", [30.0, 60.0, 80.0])
def test_energy_conservation_at_oblique_incidence(name, coeffs, theta_deg):
    """Phong (Lafortune & Willems) and A-S with F = 1 (Ashikhmin & Shirley §3) reflect at most
    their k_s at any incidence (the quadrature at n = 400 is within 1e-5 of n = 2000 at these widths)."""
    a = directional_albedo(model(name, kd=0.0, ks=1.0, **coeffs), math.radians(theta_deg))
    assert 0.05 < a <= 1.0 + 1e-3


@pytest.mark.parametrize("n", [0.5, 10.0, 100.0, 1e3, 1e5])
def test_ashikhmin_shirley_albedo_at_normal_incidence(n):
    """F = 1, ωi = normal: θo = 2θh, cosθd = cosθh, so the albedo is
    (n+1) ∫_0^{π/4} cos^n t (2cos²t − 1) sin t dt = 2(n+1)(1 − c^(n+3))/(n+3) − (1 − c^(n+1)),
    c = cos π/4: below 1, → 1 − 4/(n+3) as n grows (the lobe is near energy conserving)."""
    a = normal_incidence_albedo(model("ashikhmin_shirley", kd=0.0, ks=1.0, exponent=n, f0=1.0))
    c = math.cos(math.pi / 4)
    exact = 2 * (n + 1) * (1 - c ** (n + 3)) / (n + 3) - (1 - c ** (n + 1))
    assert a == pytest.approx(exact, rel=1e-6)
    assert a < 1.0
    if n >= 100:
        assert 1 - a == pytest.approx(4 / (n + 3), rel=2e-2)


@pytest.mark.parametrize("alpha", [1e-3, 0.01, 0.05, 0.1, 0.2])
def test_ward_normalisation_tends_to_one(alpha):
    """Ward's 1/(4πα²) normalises the lobe for small α: the albedo at normal incidence is
    1 − O(α²) (measured: 1 − 3α² for Ward, 1 − 2α² for Dür) and below 1; Dür's 1/(cosθi cosθo)
    reflects more than Ward's 1/√(cosθi cosθo)."""
    ward = normal_incidence_albedo(model("ward", kd=0.0, ks=1.0, alpha=alpha))
    duer = normal_incidence_albedo(model("ward_duer", kd=0.0, ks=1.0, alpha=alpha))
    assert ward < duer < 1.0
    assert 1 - ward < 3.1 * alpha**2 and 1 - duer < 2.1 * alpha**2


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_reciprocity_is_exact(name, dtype):
    for family, (wi, wo) in adversarial_pairs(35_000, dtype, seed=5).items():
        for coeffs in MODERATE[name]:
            m = model(name, kd=0.1, ks=0.9, **coeffs)
            assert torch.equal(m.eval(wi, wo), m.eval(wo, wi)), (family, coeffs)


# --------------------------------------------------------------------------- numerical stability

EXTREME_CASES = [(n, c) for n, cs in EXTREME.items() for c in cs]


def _id(case) -> str:
    name, c = case
    return f"{name}-" + "-".join(f"{k}={v:g}" for k, v in c.items())


@pytest.mark.parametrize("name,coeffs", EXTREME_CASES, ids=[_id(c) for c in EXTREME_CASES])
def test_extremes_stay_finite_and_fp32_agrees_with_fp64(name, coeffs):
    m = model(name, kd=0.5, ks=1e3, **coeffs)
    floor = 0.5 / math.pi * (1 - 1e-6)
    for dtype in (torch.float32, F64):
        pairs = adversarial_pairs(35_000, dtype, seed=6)
        assert set(pairs) == set(FAMILIES)
        for family, (wi, wo) in pairs.items():
            out = m.eval(wi, wo)
            assert out.dtype == dtype
            assert bool(torch.isfinite(out).all()), f"non-finite values ({family}, {dtype})"
            assert float(out.max()) < 1e-6 * torch.finfo(dtype).max, f"saturated at the output clamp ({family})"
            if family == "below_horizon":
                assert bool((out == 0).all())
                continue
            assert bool((out >= floor).all()), f"lost the diffuse term ({family}, {dtype})"
            # the same fp32 inputs in fp64 (retro-reflective Lafortune lobes, C_xy > 0, included)
            if dtype == torch.float32:
                want = m.eval(wi.double(), wo.double())
                rel = float(((out.double() - want).abs() / want).max())
                assert rel < 1e-3, f"fp32 differs from fp64 by {rel:.3g} relative ({family})"


def near_peak_pairs(n: int, width: float, seed: int = 7):
    """Pairs with θh uniform in [0, width] (θd ≤ 80°), built in fp64 and rounded to fp32."""
    g = torch.Generator().manual_seed(seed)
    u = lambda: torch.rand(n, generator=g, dtype=F64)  # noqa: E731
    wi, wo = from_half_diff(width * u(), 2 * math.pi * u(), math.radians(80) * u(), 2 * math.pi * u())
    return wi.float(), wo.float()


@pytest.mark.parametrize("name,coeffs,width", [
    ("ward", dict(alpha=1e-3), 5e-3),
    ("ward_duer", dict(alpha=0.00509), 2e-2),
    ("phong", dict(exponent=1e6), 1e-3),
    ("phong", dict(exponent=121000.0), 3e-3),
    ("blinn_phong_ngan", dict(exponent=1e6), 1e-3),
    ("lafortune", dict(cxy=-0.707, cz=0.707, exponent=1e6), 1e-3),
    ("ashikhmin_shirley", dict(exponent=1e6, f0=0.05), 3e-3),
    ("ashikhmin_shirley_ior", dict(exponent=621578.388244, ior=9.79957), 4e-3),
])
def test_narrow_lobes_are_accurate_in_fp32(name, coeffs, width):
    """The whole peak of the narrowest lobes evaluates in fp32 to ~1e-5 relative of fp64 on
    the same inputs; the textbook cos^n α = (cosθi cosθo − dot_xy)^n does not (checked for
    the Phong lobes, so that the tolerance means something)."""
    wi, wo = near_peak_pairs(100_000, width)
    m = model(name, kd=0.0, ks=1.0, **coeffs)
    a, b = m.eval(wi, wo).double(), m.eval(wi.double(), wo.double())
    keep = b[:, 0] > 1e-30 * float(b.max())
    assert float(keep.float().mean()) > 0.2
    assert float(((a - b).abs() / b)[keep].max()) < 1e-4
    if name in ("phong", "lafortune"):
        def naive(x, y):
            cos_a = (x[:, 2] * y[:, 2] - (x[:, 0] * y[:, 0] + x[:, 1] * y[:, 1])).clamp(min=0)
            return cos_a ** coeffs["exponent"]
        na, nb = naive(wi, wo).double(), naive(wi.double(), wo.double())
        assert float(((na - nb).abs() / nb)[keep].max()) > 1e-2


def test_a_narrow_retro_reflective_lafortune_lobe_is_accurate_in_fp32():
    """C_xy = C_z > 0 peaks at ωo = ωi; its 1 − ωi·ωo = 2 sin²θd keeps fp32 within ~1e-5 of
    fp64 on the same inputs, where 2(1 − cos²θd) would not (checked below, so the tolerance
    means something)."""
    g = torch.Generator().manual_seed(11)
    u = lambda: torch.rand(100_000, generator=g, dtype=F64)  # noqa: E731
    wi, wo = from_half_diff(math.radians(80) * u(), 2 * math.pi * u(), 3e-3 * u(), 2 * math.pi * u())
    wi, wo = wi.float(), wo.float()
    keep = (wi[:, 2] > 0.05) & (wo[:, 2] > 0.05)
    wi, wo = wi[keep], wo[keep]
    m = model("lafortune", kd=0.0, ks=1.0, cxy=0.6, cz=0.6, exponent=1e5)
    a, b = m.eval(wi, wo).double(), m.eval(wi.double(), wo.double())
    alive = b[:, 0] > 1e-30 * float(b.max())
    assert float(alive.float().mean()) > 0.2
    assert float(((a - b).abs() / b)[alive].max()) < 1e-4
    cos_d = 0.5 * torch.linalg.vector_norm(wi + wo, dim=-1)
    naive = 2.0 * (1.0 - cos_d * cos_d)
    exact = 0.5 * ((wi.double() - wo.double()) ** 2).sum(-1)
    assert float(((naive.double() - exact).abs() / exact)[alive].max()) > 1e-2


# --------------------------------------------------------------------------- published fits

_LINE = re.compile(r"^([\w-]+) = Aggregate\(Lambertian\(albedo = \[([^\]]*)\]\), (\w+)\((.*)\)\)\s*$")
_PARAM = re.compile(r"(\w+) = (\[[^\]]*\]|[-+0-9.eE]+)")


def published_lines(filename: str) -> list[tuple[str, list[float], str, dict]]:
    """(material, diffuse, BBM model, params) per line of a .fit file (test-only parser)."""
    out = []
    for line in (FITS / filename).read_text().splitlines():
        m = _LINE.match(line)
        if not m:
            continue
        params = {}
        for key, value in _PARAM.findall(m.group(4)):
            params[key] = [float(v) for v in value.strip("[]").split(",")] if value.startswith("[") else float(value)
        out.append((m.group(1), [float(v) for v in m.group(2).split(",")], m.group(3), params))
    return out


needs_fits = pytest.mark.skipif(not FITS.is_dir(), reason="published fits not in /work/shared/reference")


@needs_fits
@pytest.mark.parametrize("name", MODELS)
def test_every_published_fit_maps_inside_the_coefficients(name):
    cls = MODELS[name]
    count = 0
    for filename, bbm in PUBLISHED[name]:
        lines = published_lines(filename)
        assert len(lines) >= 80, filename
        for material, diffuse, model_name, params in lines:
            assert model_name == bbm and bbm in cls.PUBLISHED_AS
            kwargs = cls.from_published(bbm, diffuse, params)
            m = cls().set_coefficients(**kwargs)
            bounds = {c.name: (c.lower, c.upper) for c in cls.COEFFS}
            for key, value in kwargs.items():
                if key not in ("kd", "ks"):
                    assert bounds[key][0] <= value <= bounds[key][1], (material, key, value)
            assert m.kd.tolist() == diffuse and m.ks.tolist() == params["albedo"]
            count += 1
    assert count >= 80


#: BBM's parameter name → the reference's coefficient name, per model.
_REF_KEYS = {"roughness": "alpha", "sharpness": "exponent", "Cxy": "cxy", "Cz": "cz"}


@needs_fits
@pytest.mark.parametrize("name", MODELS)
def test_published_fit_evaluates_as_published(name):
    """alum-bronze (and two more materials) as published: kd/π + albedo · the paper's lobe."""
    cls = MODELS[name]
    filename, bbm = PUBLISHED[name][0]
    lines = {ln[0]: ln for ln in published_lines(filename)}
    a = angles(5000, seed=8)
    wi, wo = tensors(*a)
    for material in ("alum-bronze", "black-obsidian", "white-acrylic"):
        if material not in lines:
            continue
        _, diffuse, _, params = lines[material]
        m = cls().set_coefficients(**cls.from_published(bbm, diffuse, params))
        ref = {_REF_KEYS.get(k, k): v for k, v in params.items()}
        if name == "ashikhmin_shirley":
            ref["f0"] = ref.pop("fresnelReflectance")
        if name == "ashikhmin_shirley_ior":
            ref["ior"] = ref.pop("fresnelReflectance")
        want = np.array(diffuse) / math.pi + reference_lobe(name, ref, *a)[:, None] * np.array(ref["albedo"])
        np.testing.assert_allclose(m.eval(wi, wo).numpy(), want, rtol=1e-8, atol=1e-300)


@needs_fits
def test_from_published_on_real_lines():
    _, diffuse, bbm, params = next(ln for ln in published_lines("ngan_ward.fit") if ln[0] == "alum-bronze")
    assert Ward.from_published(bbm, diffuse, params) == {
        "kd": [0.0851, 0.0586, 0.0294], "ks": [0.0484, 0.0274, 0.0135], "alpha": 0.0357}
    _, diffuse, bbm, params = next(ln for ln in published_lines("ngan_lafortune.fit") if ln[0] == "alum-bronze")
    assert Lafortune.from_published(bbm, diffuse, params) == {
        "kd": [0.0923, 0.0625, 0.0311], "ks": [0.322, 0.193, 0.105], "cxy": -0.579, "cz": 0.574, "exponent": 630.0}
    _, diffuse, bbm, params = next(ln for ln in published_lines("ngan_ashikhminshirley.fit") if ln[0] == "alum-bronze")
    assert AshikhminShirley.from_published(bbm, diffuse, params) == {
        "kd": [0.0877, 0.0598, 0.0297], "ks": [0.108, 0.0637, 0.0337], "f0": 0.249, "exponent": 1350.0}
    _, diffuse, bbm, params = next(ln for ln in published_lines("low_ashikhminshirley_E1.fit") if ln[0] == "alum-bronze")
    assert AshikhminShirleyIor.from_published(bbm, diffuse, params) == {
        "kd": [0.1062, 0.0815, 0.0556], "ks": [0.2481, 0.18428, 0.22073], "ior": 1.45359, "exponent": 6679.521974}


GOOD = {
    Ward: ("NganWard", {"albedo": [0.05, 0.03, 0.01], "roughness": 0.03}),
    WardDuer: ("NganWardDuer", {"albedo": [0.05, 0.03, 0.01], "roughness": 0.03}),
    Phong: ("NganBlinnPhong", {"albedo": [0.05, 0.03, 0.01], "sharpness": 1290.0}),
    BlinnPhongNgan: ("NganBlinnPhong", {"albedo": [0.05, 0.03, 0.01], "sharpness": 1290.0}),
    Lafortune: ("NganLafortune", {"albedo": [0.3, 0.2, 0.1], "Cxy": -0.579, "Cz": 0.574, "sharpness": 630.0}),
    AshikhminShirley: ("NganAshikhminShirley", {"albedo": [0.1, 0.06, 0.03], "fresnelReflectance": 0.249, "sharpness": 1350.0}),
    AshikhminShirleyIor: ("LowAshikhminShirley", {"albedo": [0.2, 0.2, 0.2], "fresnelReflectance": 1.45, "sharpness": 6679.5}),
}
DIFFUSE = [0.1, 0.05, 0.02]


@pytest.mark.parametrize("cls", GOOD, ids=lambda c: c.NAME)
def test_from_published_refuses_bad_parameters(cls):
    bbm, good = GOOD[cls]
    cls().set_coefficients(**cls.from_published(bbm, DIFFUSE, good))
    shape_key = next(k for k in good if k != "albedo")
    cases = [
        ("NotAModel", good, "NotAModel"),
        (bbm, {k: v for k, v in good.items() if k != shape_key}, f"missing parameter.*'{shape_key}'"),
        (bbm, {**good, "anisotropy": 0.5}, "unknown.*'anisotropy'"),
        (bbm, {**good, "albedo": [0.1, 0.2]}, "'albedo'.*3 values"),
        (bbm, {**good, "albedo": [0.1, -0.2, 0.1]}, "'albedo'.*non-negative"),
        (bbm, {**good, "albedo": [0.1, float("nan"), 0.1]}, "'albedo'.*finite"),
        (bbm, {**good, "sharpness" if "sharpness" in good else "roughness": -1.0}, "outside the model's domain"),
        (bbm, {**good, shape_key: [1.0, 2.0]}, f"'{shape_key}'.*one number"),
        (bbm, {**good, shape_key: "0.5"}, f"'{shape_key}'.*finite number"),
    ]
    if "sharpness" in good:
        cases.append((bbm, {**good, "sharpness": 1e9}, r"'sharpness' = 1000000000.0 is outside"))
    for name, params, match in cases:
        with pytest.raises(ValueError, match=match):
            cls.from_published(name, DIFFUSE, params)
    with pytest.raises(ValueError, match="diffuse.*non-negative"):
        cls.from_published(bbm, [0.1, -0.1, 0.1], good)


def test_from_published_refuses_an_undefined_lafortune_lobe():
    with pytest.raises(ValueError, match="'Cxy' and 'Cz' are both 0"):
        Lafortune.from_published("NganLafortune", DIFFUSE, {"albedo": 0.1, "Cxy": 0.0, "Cz": 0.0, "sharpness": 10.0})
    with pytest.raises(ValueError, match="'Cz' = 3.0 is outside"):
        Lafortune.from_published("NganLafortune", DIFFUSE, {"albedo": 0.1, "Cxy": -0.5, "Cz": 3.0, "sharpness": 10.0})


def test_ior_is_not_a_reflectance():
    """LowAshikhminShirley's fresnelReflectance is an IoR (> 1); NganAshikhminShirley's an F0 in [0, 1]."""
    with pytest.raises(ValueError, match="'fresnelReflectance' = 0.5 is outside"):
        AshikhminShirleyIor.from_published("LowAshikhminShirley", DIFFUSE, {**GOOD[AshikhminShirleyIor][1], "fresnelReflectance": 0.5})
    with pytest.raises(ValueError, match="'fresnelReflectance' = 1.45 is outside"):
        AshikhminShirley.from_published("NganAshikhminShirley", DIFFUSE, {**GOOD[AshikhminShirley][1], "fresnelReflectance": 1.45})


# --------------------------------------------------------------------------- the kit and fitting

QUICK = {"n_samples": 4096, "restarts": 1}


#: Every literature model: tests/unit/test_conformance.py runs the whole kit (fp32 and fp64,
#: a quick fit) on each registered representation; this checks that the registrations make
#: it run the physics checks too.
LITERATURE = ("ward", "ward_duer", "phong", "blinn_phong_ngan", "lafortune", "lafortune2", "lafortune3",
              "ashikhmin_shirley", "ashikhmin_shirley_ior", "cook_torrance_beckmann", "cook_torrance_1982",
              "low_smooth", "low_microfacet", "sgd", "he")


@pytest.mark.parametrize("name", LITERATURE)
def test_the_kit_runs_every_check_on_each_registered_model(name):
    spec = registry.get("representations", name)
    quick = dict(spec.kit_params)  # a short fit: one start, at most QUICK's samples
    assert quick.keys() == QUICK.keys() and quick["restarts"] == 1 and quick["n_samples"] <= QUICK["n_samples"]
    assert spec.tags >= TAGS and not spec.xfail_checks
    checks = {c.name for c in representation_checks(name)}
    assert checks >= {"protocol", "eval_shapes_and_dtypes", "adversarial_finite_nonnegative", "zero_below_horizon",
                      "reciprocity", "isotropy", "fit_deterministic", "save_load_roundtrip",
                      "load_refuses_broken_state", "devices_declared", "fit_in_a_helper", "cost_declared"}, checks


def test_classes_declare_what_the_registry_needs():
    for name, cls in MODELS.items():
        assert cls.NAME == name and cls.tags == TAGS
        assert [c.name for c in cls.COEFFS[:2]] == ["kd", "ks"]
        assert isinstance(cls.FLOPS, int) and 20 < cls.FLOPS < 100
        assert cls.PUBLISHED_AS and set(cls.PUBLISHED_PARAMS.values()) == {c.name for c in cls.COEFFS[1:]}
        m = cls()
        assert m.params == {"n_samples": 32768, "restarts": 4} and m.flops_per_eval == cls.FLOPS
        shape = cls.init_shape(0.2)
        assert set(shape) == {c.name for c in cls.COEFFS[2:]}


TRUTH = {
    "ward": dict(kd=[0.3, 0.1, 0.05], ks=[0.08, 0.06, 0.04], alpha=0.06),
    "ward_duer": dict(kd=[0.3, 0.1, 0.05], ks=[0.08, 0.06, 0.04], alpha=0.15),
    "phong": dict(kd=[0.2, 0.1, 0.05], ks=[0.5, 0.6, 0.7], exponent=150.0),
    "blinn_phong_ngan": dict(kd=[0.2, 0.1, 0.05], ks=[0.5, 0.6, 0.7], exponent=400.0),
    "lafortune": dict(kd=[0.2, 0.1, 0.05], ks=[0.5, 0.6, 0.7], cxy=-0.8, cz=0.78, exponent=80.0),
    "ashikhmin_shirley": dict(kd=[0.2, 0.1, 0.05], ks=[0.6, 0.5, 0.4], exponent=400.0, f0=0.3),
    "ashikhmin_shirley_ior": dict(kd=[0.2, 0.1, 0.05], ks=[0.6, 0.5, 0.4], exponent=400.0, ior=2.0),
}


@pytest.fixture(scope="module")
def grid():
    wi, wo = merl.grid_directions()
    return wi, wo, ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)


@pytest.mark.parametrize("name", MODELS)
def test_fit_recovers_known_coefficients(name, grid):
    wi, wo, valid = grid
    truth = TRUTH[name]
    values = model(name, **truth).eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    target = Material(f"self-{name}", MerlTable.from_values(values, valid), "synthetic-self")
    fitted = MODELS[name](**QUICK).fit(target, seed=0)
    assert fitted.fit_loss < 2e-3, fitted.fit_loss
    for key, want in truth.items():
        if key in ("cxy", "cz"):
            continue
        got = fitted.coeffs[key]
        torch.testing.assert_close(got, torch.tensor(want, dtype=F64).reshape(-1).expand_as(got), rtol=3e-2, atol=3e-3)
    if name == "lafortune":  # only the direction of (C_xy, C_z) matters
        assert float(fitted.cxy / fitted.cz) == pytest.approx(truth["cxy"] / truth["cz"], rel=3e-2)


# --------------------------------------------------------------------------- drjit kernels


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")
def test_drjit_kernels_agree_with_torch():
    cases = [(n, c) for n, cs in MODERATE.items() for c in cs[:2]] + [(n, c) for n, cs in EXTREME.items() for c in cs[:1]]
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        def vec(t):
            return mi.Vector3f(*(mi.Float(t[:, c].numpy().copy()) for c in range(3)))

        for name, coeffs in cases:
            m = model(name, kd=[0.1, 0.2, 0.3], ks=[0.5, 0.6, 0.7], **coeffs)
            kernel = m.drjit_kernel()
            assert kernel is not None and kernel.name == name
            for family, (wi, wo) in adversarial_pairs(14_000, torch.float32, seed=9).items():
                if family == "below_horizon":  # the adapter masks these before the kernel
                    continue
                got = np.stack([np.asarray(c) for c in kernel.eval(vec(wi), vec(wo))], axis=1)
                cos = wo[:, 2:3].numpy()
                np.testing.assert_allclose(got * cos, m.eval(wi, wo).numpy() * cos, rtol=2e-5, atol=1e-6,
                                           err_msg=f"{name} {coeffs} {family}")


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")
def test_kernel_hook_is_for_the_exact_class_only():
    class Tweaked(Phong):
        pass

    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        assert Tweaked().drjit_kernel() is None
        assert Phong().drjit_kernel() is not None
