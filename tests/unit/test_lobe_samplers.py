"""The analytic models' samplers (brdfbench/sampling/lobes.py): the conformance kit on
anisotropic and off-specular parameters and at hard ones, the papers' formulas written out
here as oracles, masses known in closed form, and the identities with the built-ins
(isotropic Ward = Beckmann, isotropic Ashikhmin-Shirley = Blinn-Phong, Lafortune's
(−1, 1) lobe = Phong, its (0, 1) lobe = power cosine). The registered defaults' own
conformance (the roughness sweep) runs in test_samplers.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.sampling.builtin import Beckmann, BlinnPhong, PowerCosine
from brdfbench.sampling.chi2 import Unresolvable, chi2_test, integrate_pdf
from brdfbench.sampling.lobes import AshikhminShirley, Lafortune, Phong, Ward
from brdfbench.testing.adversarial import adversarial_pairs
from brdfbench.testing.samplers import _hard_inputs, chi2_cells, sampler_checks

LOBES = ("ward", "ashikhmin_shirley", "phong", "lafortune")
DTYPES = (torch.float64, torch.float32)

#: Parameters the registered defaults' sweep does not reach: anisotropy (the sweep sets
#: alpha_x or nu; the other axis stays as given), off-specular and retro-reflective lobes,
#: and a horizontal axis (C_z = 0; at normal incidence it falls back to the normal).
#: Ashikhmin-Shirley's anisotropy is kept to n_v = 100 against n_u ∈ {0 … 2e6}: at n_u = 0,
#: n_v = 1000 and θi ≥ 89° the kit's half-vector chart (a lobe reaching the horizon of h
#: along x, through the pole of Mitsuba's cells) rejects, while the same cell binned in ωo
#: accepts (p = 0.85); h is drawn independently of ωi and passes at θi ≤ 80°.
VARIANTS = (
    ("ward", {"alpha_y": 0.3}),
    ("ashikhmin_shirley", {"nv": 100.0}),
    ("lafortune", {"cxy": -0.8, "cz": 0.5}),
    ("lafortune", {"cxy": 0.7, "cz": 1.0}),
    ("lafortune", {"cxy": -1.0, "cz": 0.0}),
)
#: χ² cells at the hard ends, beyond the sweep: exponents 1e6, α = 1e-3 against 0.01.
HARD_CELLS = tuple(
    (name, params, theta, dtype)
    for name, params, thetas in (
        ("phong", {"exponent": 1e6}, (0.0, 89.9)),
        ("lafortune", {"cxy": -0.8, "cz": 0.5, "exponent": 1e6}, (45.0, 89.9)),
        ("ashikhmin_shirley", {"nu": 1e6, "nv": 1e4}, (0.0, 89.9)),
        ("ward", {"alpha_x": 1e-3, "alpha_y": 0.01}, (0.0, 89.9)),
    )
    for theta in thetas
    for dtype in DTYPES
)
# The Šidák family: every χ² test of this file (quick and full sweeps of VARIANTS, and
# HARD_CELLS). Each rejects at p < 1 − (1 − 0.01)^(1/FAMILY): the file errs with
# probability ≤ 0.01.
FAMILY = sum(len(chi2_cells(registry.get("samplers", n), p, sweep, DTYPES)) for n, p in VARIANTS
             for sweep in ("quick", "full")) + len(HARD_CELLS)


def _wi(theta_deg: float, phi: float = 1.0) -> tuple[float, float, float]:
    t = math.radians(theta_deg)
    return (math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t))


def _label(params: dict) -> str:
    return ",".join(f"{k}={v:g}" for k, v in params.items())


def _variant_params():
    for name, params in VARIANTS:
        for check in sampler_checks(name, params=params, sweep="quick", dtypes=DTYPES, test_count=FAMILY, n_pairs=20_000):
            yield pytest.param(check, id=f"{check}[{_label(params)}]-quick" if check.name.startswith("chi2") else f"{check}[{_label(params)}]")
        for check in sampler_checks(name, params=params, sweep="full", dtypes=DTYPES, test_count=FAMILY):
            if check.name.startswith("chi2"):
                yield pytest.param(check, id=f"{check}[{_label(params)}]-full", marks=[pytest.mark.slow])


@pytest.mark.parametrize("check", list(_variant_params()))
def test_conformance_of_anisotropic_and_off_specular_lobes(check):
    try:
        check()
    except Unresolvable as exc:  # reported, never silent: the fixed checks compare fp32 with fp64 there
        pytest.skip(f"{check}: {exc}")


@pytest.mark.parametrize("name,params,theta,dtype", HARD_CELLS,
                         ids=[f"{n}[{_label(p)}]-theta_i={t:g}-{str(d)[6:]}" for n, p, t, d in HARD_CELLS])
def test_chi2_at_hard_parameters(name, params, theta, dtype):
    sampler = registry.get("samplers", name).create(**params)
    try:
        result = chi2_test(sampler, _wi(theta), dtype=dtype, sample_count=200_000, res=51, test_count=FAMILY, seed=7)
    except Unresolvable as exc:
        pytest.skip(f"{exc}; fp32 there is checked against fp64 instead (test_fixed_checks_at_hard_parameters)")
    assert result.passed, result.summary()


HARD_FIXED = (
    ("phong", {"exponent": 1e6}),
    ("phong", {"exponent": 1e12}),
    ("lafortune", {"cxy": -0.8, "cz": 0.5, "exponent": 1e6}),
    ("lafortune", {"cxy": 0.0, "cz": -1.0, "exponent": 10.0}),  # the axis below the horizon
    ("ward", {"alpha_x": 1e-3, "alpha_y": 1.0}),
    ("ashikhmin_shirley", {"nu": 1e6, "nv": 0.0}),
)


@pytest.mark.parametrize("name,params", HARD_FIXED, ids=[f"{n}[{_label(p)}]" for n, p in HARD_FIXED])
def test_fixed_checks_at_hard_parameters(name, params):
    """Finite, unit, fp32 = fp64, pdf > 0 at its own samples above the horizon, 0 below it."""
    for check in sampler_checks(name, params=params, sweep="none", n_pairs=20_000):
        check()


# --------------------------------------------------------------------------- registration, parameters


def test_registered_with_tags_and_twins():
    for name in LOBES:
        spec = registry.get("samplers", name)
        cls = spec.load()
        assert spec.tags <= cls.tags and isinstance(spec.create(), cls)
        assert callable(getattr(cls, "drjit_sampler", None))
    assert {n for n in LOBES if "microfacet" in registry.get("samplers", n).tags} == {"ward", "ashikhmin_shirley"}
    assert not registry.get("samplers", "phong").tags and not registry.get("samplers", "lafortune").tags


@pytest.mark.parametrize(
    "name,key,value",
    [("ward", k, v) for k in ("alpha_x", "alpha_y") for v in (0.0, -0.1, math.nan, math.inf, "rough", True)]
    + [("ashikhmin_shirley", k, v) for k in ("nu", "nv") for v in (-1.0, math.nan, math.inf, False)]
    + [("ashikhmin_shirley", "nu", None)]  # nv=None (and alpha_y=None) is the default: isotropic
    + [(n, "exponent", v) for n in ("phong", "lafortune") for v in (-1.0, math.nan, -math.inf, math.inf, None)]
    + [("lafortune", k, v) for k in ("cxy", "cz") for v in (math.nan, math.inf, -math.inf, "up", None, True)],
)
def test_bad_parameters_name_key_and_value(name, key, value):
    with pytest.raises(ConfigError, match=rf"{name}.*{key}={value!r}"):
        registry.get("samplers", name).create(**{key: value})


def test_lafortune_without_an_axis_is_a_config_error():
    with pytest.raises(ConfigError, match=r"lafortune.*cxy=0 and cz=0"):
        Lafortune(cxy=0.0, cz=0.0)
    Lafortune(cxy=0.0, cz=1.0), Lafortune(cxy=-1.0, cz=0.0)  # one of them may be 0


def test_roughness_params():
    assert Ward.roughness_params(0.2) == {"alpha_x": 0.2}
    assert Ward(**Ward.roughness_params(0.2)).params == {"alpha_x": 0.2, "alpha_y": 0.2}
    assert Ward(alpha_y=0.5, **Ward.roughness_params(0.2)).params == {"alpha_x": 0.2, "alpha_y": 0.5}
    assert AshikhminShirley.roughness_params(1e-3) == {"nu": pytest.approx(2e6 - 2)}
    assert AshikhminShirley(**AshikhminShirley.roughness_params(0.5)).params == {"nu": 6.0, "nv": 6.0}
    for cls in (Phong, Lafortune):
        # n = 1/(2α²) − ½: the reflected Beckmann lobe's width about the mirror direction
        assert cls.roughness_params(1e-3) == {"exponent": pytest.approx(5e5 - 0.5)}
        assert cls.roughness_params(0.1) == {"exponent": pytest.approx(49.5)}
        assert cls.roughness_params(1.0) == {"exponent": 0.0}


# --------------------------------------------------------------------------- identities with the built-ins


def _agree(a, b, dtype, *, sample_ulps: float, pdf_ulps: float, peak_ulps: float = 0.0, above_only: bool = False):
    """Samples within sample_ulps·ε (absolute), densities within pdf_ulps·ε·(1 + |log p|)
    relative (cosⁿ = exp(n log cos) carries the rounding of its argument), plus
    peak_ulps·ε of the peak density (1/(2π) here) and the dtype's subnormal range, at the
    hard inputs (own samples) and the adversarial pairs."""
    finfo = torch.finfo(dtype)
    wi, u = _hard_inputs(dtype, seed=1)
    if above_only:
        keep = wi[:, 2] > 0
        wi, u = wi[keep], u[keep]
    wa, wb = a.sample(wi, u), b.sample(wi, u)
    assert (wa - wb).abs().max() <= sample_ulps * finfo.eps, float((wa - wb).abs().max() / finfo.eps)
    for x, y in [(wi, wa), *adversarial_pairs(14_000, dtype, seed=2).values()]:
        pa, pb = a.pdf(x, y).double(), b.pdf(x, y).double()
        log_p = torch.log(pb.clamp(min=finfo.tiny)).abs()
        tol = pdf_ulps * finfo.eps * (1 + log_p) * pb + peak_ulps * finfo.eps / (2 * math.pi) + 64 * finfo.tiny
        bad = (pa - pb).abs() > tol
        assert not bad.any(), (x[bad][:3].tolist(), y[bad][:3].tolist(), pa[bad][:3].tolist(), pb[bad][:3].tolist())


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("alpha", [1e-3, 0.01, 0.3, 1.0])
def test_isotropic_ward_is_beckmann(alpha, dtype):
    _agree(Ward(alpha_x=alpha), Beckmann(alpha=alpha), dtype, sample_ulps=8, pdf_ulps=64)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [0.0, 5.0, 1e4, 2e6])
def test_isotropic_ashikhmin_shirley_is_blinn_phong(n, dtype):
    """p(h) = (n_u + 1)/(2π) cos^(n_u) θh is Blinn-Phong's D cos = (n + 2)/(2π) cos^(n+1) θh."""
    _agree(AshikhminShirley(nu=n + 1.0), BlinnPhong(exponent=n), dtype, sample_ulps=8, pdf_ulps=64)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [0.0, 1.5, 100.0, 1e6])
def test_lafortune_minus_one_one_is_phong(n, dtype):
    wi, u = _hard_inputs(dtype, seed=3)
    lf, ph = Lafortune(cxy=-1.0, cz=1.0, exponent=n), Phong(exponent=n)
    wo = ph.sample(wi, u)
    assert torch.equal(lf.sample(wi, u), wo)
    assert torch.equal(lf.pdf(wi, wo), ph.pdf(wi, wo))
    # only the axis' direction matters: (C_xy, C_z) scaled by 3 is Phong to rounding
    _agree(Lafortune(cxy=-3.0, cz=3.0, exponent=n), ph, dtype, sample_ulps=8, pdf_ulps=64, peak_ulps=64 * (n + 1))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("n", [0.0, 5.0, 1e4, 2e6])
def test_lafortune_zero_one_is_power_cosine(n, dtype):
    """C_xy = 0: the axis is the normal for every ωi above the horizon (samples differ at
    the rim, where the lobe keeps cos α ≥ 64 ε)."""
    _agree(Lafortune(cxy=0.0, cz=1.0, exponent=n), PowerCosine(exponent=n), dtype, sample_ulps=72, pdf_ulps=64, above_only=True)


@pytest.mark.parametrize("dtype", DTYPES)
def test_lafortune_degenerate_axis_falls_back_to_the_normal(dtype):
    """C_z = 0 at normal incidence: (C_xy ωi_x, C_xy ωi_y, 0) = 0, the lobe is the normal's;
    off the normal the axis is horizontal, C_xy (ωi_x, ωi_y) normalised."""
    sampler, about_normal = Lafortune(cxy=-1.0, cz=0.0, exponent=30.0), PowerCosine(exponent=30.0)
    g = torch.Generator().manual_seed(0)
    u = torch.rand(512, 2, generator=g, dtype=torch.float64).to(dtype)
    normal = torch.zeros(512, 3, dtype=dtype)
    normal[:, 2] = 1.0
    wo = sampler.sample(normal, u)
    assert torch.allclose(wo, about_normal.sample(normal, u), rtol=0, atol=8 * torch.finfo(dtype).eps)
    assert torch.allclose(sampler.pdf(normal, wo), about_normal.pdf(normal, wo), rtol=1e-5)
    tilted = torch.tensor([[1e-30, 0.0, 1.0]], dtype=torch.float64).to(dtype)
    assert torch.equal(sampler.axis(tilted), torch.tensor([[-1.0, 0.0, 0.0]], dtype=torch.float64))


# --------------------------------------------------------------------------- the papers' formulas


def _random_pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Pairs above the horizon, half of them near the mirror direction (where the lobes are)."""
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g, dtype=torch.float64)
    v[..., 2] = v[..., 2].abs()
    wi, wo = (x / x.norm(dim=-1, keepdim=True) for x in v)
    mirror = torch.stack((-wi[:, 0], -wi[:, 1], wi[:, 2]), -1) + 0.05 * torch.randn(n, 3, generator=g, dtype=torch.float64)
    mirror[:, 2] = mirror[:, 2].abs()
    wo[: n // 2] = (mirror / mirror.norm(dim=-1, keepdim=True))[: n // 2]
    return wi, wo


def _half_angles(wi, wo):
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True)
    theta = torch.atan2(torch.hypot(h[:, 0], h[:, 1]), h[:, 2])
    return h, theta, torch.atan2(h[:, 1], h[:, 0])


@pytest.mark.parametrize("ax,ay", [(0.05, 0.3), (0.5, 0.1), (0.2, 0.2), (1e-3, 0.02)])
def test_ward_pdf_is_walters_formula(ax, ay):
    """Walter (2005), h's density with 1/(4 h·ωo): p(ωo) = exp(−tan²θh (cos²φh/α_x² + sin²φh/α_y²))
    / (4π α_x α_y (h·ωi) cos³θh), in spherical coordinates of h."""
    wi, wo = _random_pairs(20_000, seed=1)
    h, theta, phi = _half_angles(wi, wo)
    expo = -torch.tan(theta) ** 2 * (torch.cos(phi) ** 2 / ax**2 + torch.sin(phi) ** 2 / ay**2)
    walter = torch.exp(expo) / (4 * math.pi * ax * ay * (h * wi).sum(-1) * torch.cos(theta) ** 3)
    got = Ward(alpha_x=ax, alpha_y=ay).pdf(wi, wo)
    assert torch.allclose(got, walter, rtol=1e-9, atol=1e-300)
    assert float(walter.max()) > 1.0  # the pairs reach the lobe


@pytest.mark.parametrize("nu,nv", [(10.0, 1000.0), (300.0, 3.0), (50.0, 50.0), (0.0, 20.0)])
def test_ashikhmin_shirley_pdf_is_the_papers(nu, nv):
    """Ashikhmin and Shirley (2000): p(ωo) = √((n_u + 1)(n_v + 1))/(2π)
    cos^(n_u cos²φh + n_v sin²φh) θh / (4 ωo·h)."""
    wi, wo = _random_pairs(20_000, seed=2)
    h, theta, phi = _half_angles(wi, wo)
    ph = math.sqrt((nu + 1) * (nv + 1)) / (2 * math.pi) * torch.cos(theta) ** (nu * torch.cos(phi) ** 2 + nv * torch.sin(phi) ** 2)
    got = AshikhminShirley(nu=nu, nv=nv).pdf(wi, wo)
    assert torch.allclose(got, ph / (4 * (wo * h).sum(-1)), rtol=1e-9, atol=1e-300)


@pytest.mark.parametrize("cls,params", [(Phong, {}), (Lafortune, {"cxy": -0.8, "cz": 0.5}), (Lafortune, {"cxy": 0.6, "cz": 1.0})])
def test_cosine_lobe_pdf_is_the_papers(cls, params):
    """(n + 1)/(2π) max(0, cos α)ⁿ, cos α = ωo·A/|A|, A = (C_xy ωi_x, C_xy ωi_y, C_z ωi_z)."""
    cxy, cz = params.get("cxy", -1.0), params.get("cz", 1.0)
    wi, wo = _random_pairs(20_000, seed=3)
    a = torch.stack((cxy * wi[:, 0], cxy * wi[:, 1], cz * wi[:, 2]), -1)
    cos_a = (wo * a).sum(-1) / a.norm(dim=-1)
    for n in (0.0, 1.0, 37.0, 2e4):
        want = (n + 1) / (2 * math.pi) * cos_a.clamp(min=0.0) ** n * (cos_a > 0)
        assert torch.allclose(cls(exponent=n, **params).pdf(wi, wo), want, rtol=1e-9, atol=1e-300)


# --------------------------------------------------------------------------- masses known in closed form


def _gauss_hemisphere(pdf_fn, n_theta: int = 400, n_phi: int = 512) -> float:
    """∫ pdf dω over the upper hemisphere: Gauss-Legendre in θ, the trapezoid (spectral for a
    periodic integrand) in φ."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta = torch.tensor((x + 1) * math.pi / 4, dtype=torch.float64)
    wt = torch.tensor(w * math.pi / 4, dtype=torch.float64)
    phi = torch.arange(n_phi, dtype=torch.float64) * (2 * math.pi / n_phi)
    t, p = torch.meshgrid(theta, phi, indexing="ij")
    wo = torch.stack((torch.sin(t) * torch.cos(p), torch.sin(t) * torch.sin(p), torch.cos(t)), -1).reshape(-1, 3)
    weight = (wt[:, None] * torch.sin(t) * (2 * math.pi / n_phi)).reshape(-1)
    return float((pdf_fn(wo) * weight).sum())


def _normal(n: int) -> torch.Tensor:
    wi = torch.zeros(n, 3, dtype=torch.float64)
    wi[:, 2] = 1.0
    return wi


def _fraction_above(sampler, wi, n: int = 100_000, seed: int = 0) -> tuple[float, float]:
    """Fraction of samples above the horizon, and 5σ (+ 1e-3) of it."""
    g = torch.Generator().manual_seed(seed)
    wo = sampler.sample(torch.tensor([wi], dtype=torch.float64).expand(n, 3), torch.rand(n, 2, generator=g, dtype=torch.float64))
    f = float((wo[:, 2] > 0).double().mean())
    return f, 5 * math.sqrt(max(f * (1 - f), 1e-4) / n) + 1e-3


def _marginal_phi(p_phi, tail, n: int = 4096) -> float:
    """1 − ∫ p(φ) tail(φ) dφ over [0, 2π) (trapezoid: periodic)."""
    phi = torch.arange(n, dtype=torch.float64) * (2 * math.pi / n)
    return 1.0 - float((p_phi(phi) * tail(phi)).sum()) * (2 * math.pi / n)


@pytest.mark.parametrize("ax,ay", [(0.4, 0.9), (0.3, 0.3), (0.8, 0.2)])
def test_ward_mass_at_normal_incidence(ax, ay):
    """At normal incidence ωo is above the horizon iff tan²θh < 1, of probability
    ∫ p(φ)(1 − exp(−B(φ))) dφ, B = cos²φ/α_x² + sin²φ/α_y², p(φ) = α_x α_y /
    (2π(α_y² cos²φ + α_x² sin²φ)) (the marginal of tan φ = (α_y/α_x) tan 2πu)."""
    mass = _marginal_phi(lambda p: ax * ay / (2 * math.pi * (ay**2 * torch.cos(p) ** 2 + ax**2 * torch.sin(p) ** 2)),
                         lambda p: torch.exp(-(torch.cos(p) ** 2 / ax**2 + torch.sin(p) ** 2 / ay**2)))
    if ax == ay:
        assert mass == pytest.approx(1 - math.exp(-1 / ax**2), abs=1e-12)
    sampler = Ward(alpha_x=ax, alpha_y=ay)
    assert _gauss_hemisphere(lambda wo: sampler.pdf(_normal(wo.shape[0]), wo)) == pytest.approx(mass, abs=1e-6)
    f, tol = _fraction_above(sampler, (0.0, 0.0, 1.0))
    assert abs(f - mass) <= tol


@pytest.mark.parametrize("nu,nv", [(3.0, 30.0), (1.0, 1.0), (8.0, 0.5)])
def test_ashikhmin_shirley_mass_at_normal_incidence(nu, nv):
    """At normal incidence ωo is above the horizon iff θh < 45°: P = 1 − ∫ p(φ) 2^(−(e+1)/2) dφ,
    e = n_u cos²φ + n_v sin²φ, p(φ) = √((n_u + 1)(n_v + 1)) / (2π (e + 1))."""
    e = lambda p: nu * torch.cos(p) ** 2 + nv * torch.sin(p) ** 2  # noqa: E731
    mass = _marginal_phi(lambda p: math.sqrt((nu + 1) * (nv + 1)) / (2 * math.pi * (e(p) + 1)), lambda p: 0.5 ** ((e(p) + 1) / 2))
    sampler = AshikhminShirley(nu=nu, nv=nv)
    assert _gauss_hemisphere(lambda wo: sampler.pdf(_normal(wo.shape[0]), wo)) == pytest.approx(mass, abs=1e-6)
    f, tol = _fraction_above(sampler, (0.0, 0.0, 1.0))
    assert abs(f - mass) <= tol


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 85.0])
@pytest.mark.parametrize("cls,params", [(Phong, {}), (Lafortune, {"cxy": -0.8, "cz": 0.5}), (Lafortune, {"cxy": 0.6, "cz": 1.0})])
def test_cosine_lobe_mass_above_the_horizon(cls, params, theta):
    """The part of a lobe about an axis at β from the normal above the horizon: 1 − β/π for
    n = 0 (a lune of the two hemispheres), (1 + cos β)/2 for n = 1 (∫ ω dω over the lune
    is π(a + z)/2, Arvo's irradiance tensor), 1 for any n at β = 0. Both the adaptive
    cubature of the pdf and the samples must find it."""
    cxy, cz = params.get("cxy", -1.0), params.get("cz", 1.0)
    wi = _wi(theta)
    a = (cxy * wi[0], cxy * wi[1], cz * wi[2])
    beta = math.acos(a[2] / math.sqrt(sum(x * x for x in a)))
    for n, mass in ((0.0, 1 - beta / math.pi), (1.0, (1 + math.cos(beta)) / 2), *([(300.0, 1.0)] if theta == 0 else [])):
        sampler = cls(exponent=n, **params)
        assert integrate_pdf(sampler, wi) == pytest.approx(mass, abs=2e-3), (n, mass)
        f, tol = _fraction_above(sampler, wi, seed=int(theta))
        assert abs(f - mass) <= tol, (n, f, mass)


# --------------------------------------------------------------------------- extremes


EXTREME = (
    ("ward", {"alpha_x": 1e-9, "alpha_y": 1e9}),
    ("ward", {"alpha_x": 1e-6, "alpha_y": 1e-3}),
    ("ward", {"alpha_x": 1e9}),
    ("ashikhmin_shirley", {"nu": 0.0, "nv": 1e30}),
    ("ashikhmin_shirley", {"nu": 1e12, "nv": 1e6}),
    ("ashikhmin_shirley", {"nu": 0.0}),
    ("phong", {"exponent": 0.0}),
    ("phong", {"exponent": 1e30}),
    ("lafortune", {"cxy": 1e-300, "cz": 1e300, "exponent": 1e6}),
    ("lafortune", {"cxy": -1e-30, "cz": 0.0, "exponent": 0.0}),
    ("lafortune", {"cxy": 5.0, "cz": -0.2, "exponent": 1e12}),
)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name,params", EXTREME, ids=[f"{n}[{_label(p)}]" for n, p in EXTREME])
def test_extreme_parameters_stay_finite(name, params, dtype):
    """Beyond the specified range (α down to 1e-3, exponents to 1e6), clamped in the
    arithmetic: finite samples and densities, > 0 at its own samples above the horizon."""
    sampler = registry.get("samplers", name).create(**params)
    wi, u = _hard_inputs(dtype, seed=4)
    wo = sampler.sample(wi, u)
    p = sampler.pdf(wi, wo)
    assert torch.isfinite(wo).all() and torch.isfinite(p).all() and (p >= 0).all()
    assert ((wo.double().norm(dim=-1) - 1).abs() <= 64 * torch.finfo(dtype).eps).all()
    assert not ((wi[:, 2] > 0) & (wo[:, 2] > 0) & (p == 0)).any()
