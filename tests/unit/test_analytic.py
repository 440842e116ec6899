"""Analytic baselines (cook_torrance, ggx, blinn_phong): formulas, physics, numerical
stability in fp32, and fitting (recovery, robustness, determinism).

The conformance kit runs over these plugins too (tests/unit/test_conformance.py); the tests
here are the ones specific to the models.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.plugins import registry
from brdfbench.coords import from_half_diff, spherical_to_vector
from brdfbench.errors import ConfigError, DataError
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.testing import FAMILIES, adversarial_pairs
from brdfbench_representations.analytic import BlinnPhong, CookTorrance, GGX
from brdfbench_metrics.functional import l1_log_cos as l1_log_cos_metric
from brdfbench_representations.lambert import Lambert
from quadrature import normal_incidence_albedo

F64 = torch.float64
MODELS = {"cook_torrance": CookTorrance, "ggx": GGX, "blinn_phong": BlinnPhong}
# Moderate coefficients for formula checks, and the extremes the models must survive.
MODERATE = {
    "cook_torrance": dict(kd=[0.3, 0.2, 0.1], ks=[0.9, 0.8, 0.7], roughness=0.45, ior=1.7),
    "ggx": dict(kd=[0.3, 0.2, 0.1], ks=[0.9, 0.8, 0.7], alpha=0.2, f0=0.08),
    "blinn_phong": dict(kd=[0.3, 0.2, 0.1], ks=[0.9, 0.8, 0.7], exponent=40.0),
}
EXTREME = [
    ("cook_torrance", dict(kd=0.5, ks=1e3, roughness=1e-3, ior=1.5)),
    ("cook_torrance", dict(kd=0.5, ks=1e3, roughness=1.0, ior=50.0)),
    ("ggx", dict(kd=0.5, ks=1e3, alpha=1e-3, f0=1.0)),
    ("ggx", dict(kd=0.5, ks=1e3, alpha=1.0, f0=1e-3)),
    ("blinn_phong", dict(kd=0.5, ks=1e3, exponent=1e6)),
    ("blinn_phong", dict(kd=0.5, ks=1e3, exponent=0.1)),
]


def model(name: str, **coeffs):
    return MODELS[name]().set_coefficients(**coeffs)


def uniform_pairs(n: int, seed: int, max_deg: float = 89.0):
    g = torch.Generator().manual_seed(seed)

    def d():
        u = torch.rand(n, generator=g, dtype=F64)
        theta = torch.acos(1 - u * (1 - math.cos(math.radians(max_deg))))
        return spherical_to_vector(theta, 2 * math.pi * torch.rand(n, generator=g, dtype=F64))

    return d(), d()


# --------------------------------------------------------------------------- formulas


def textbook(name: str, c: dict, wi: torch.Tensor, wo: torch.Tensor) -> torch.Tensor:
    """The models in their usual textbook form (fp64; fine away from the hard cases)."""
    h = wi + wo
    h = h / h.norm(dim=1, keepdim=True)
    ci, co, ch, cd = wi[:, 2], wo[:, 2], h[:, 2], (wi * h).sum(1)
    kd, ks = torch.tensor(c["kd"], dtype=F64), torch.tensor(c["ks"], dtype=F64)
    if name == "blinn_phong":
        lobe = (c["exponent"] + 8) / (8 * math.pi) * ch ** c["exponent"]
    else:
        a = c["roughness"] ** 2 if name == "cook_torrance" else c["alpha"]
        d = a * a / (math.pi * ((a * a - 1) * ch * ch + 1) ** 2)
        f0 = ((c["ior"] - 1) / (c["ior"] + 1)) ** 2 if name == "cook_torrance" else c["f0"]
        fresnel = f0 + (1 - f0) * (1 - cd) ** 5
        if name == "cook_torrance":  # separable Schlick-GGX with the seed's k = α²/2
            k = a * a / 2
            g = ci / (ci * (1 - k) + k) * co / (co * (1 - k) + k)
        else:  # height-correlated Smith with Λ = (√(1 + α² tan²θ) − 1)/2
            lam = lambda cos: (torch.sqrt(1 + a * a * (1 - cos * cos) / (cos * cos)) - 1) / 2  # noqa: E731
            g = 1 / (1 + lam(ci) + lam(co))
        lobe = d * g * fresnel / (4 * ci * co)
    return kd / math.pi + lobe[:, None] * ks


@pytest.mark.parametrize("name", MODELS)
def test_matches_textbook_formula(name):
    wi, wo = uniform_pairs(20_000, seed=1, max_deg=85.0)
    got = model(name, **MODERATE[name]).eval(wi, wo)
    want = textbook(name, MODERATE[name], wi, wo)
    torch.testing.assert_close(got, want, rtol=1e-9, atol=0.0)


def test_lambert_term_is_kd_over_pi_not_cosine():
    """The seed's (n·v)/π diffuse is a slip: with k_s = 0 the value is k_d/π everywhere."""
    wi, wo = uniform_pairs(1000, seed=2)
    for name, shape in (("cook_torrance", dict(roughness=0.5)), ("ggx", dict(alpha=0.5)), ("blinn_phong", dict(exponent=10.0))):
        out = model(name, kd=[0.2, 0.5, 1.0], ks=0.0, **shape).eval(wi, wo)
        torch.testing.assert_close(out, torch.tensor([[0.2, 0.5, 1.0]], dtype=F64).expand(1000, 3) / math.pi, rtol=1e-14, atol=0)


def test_specs_and_classes_agree():
    for name, cls in MODELS.items():
        spec = registry.get("representations", name)
        assert spec.load() is cls
        assert {"isotropic", "reciprocal", "fittable", "analytic"} <= spec.tags == cls.tags
        m = spec.create()
        assert m.params == {"n_samples": 32768, "restarts": 4}
        assert isinstance(m.flops_per_eval, int) and 20 < m.flops_per_eval < 200


@pytest.mark.parametrize("bad", [dict(n_samples=0), dict(n_samples=1.5), dict(restarts=0), dict(restarts=True)])
def test_bad_params_are_config_errors(bad):
    with pytest.raises(ConfigError, match="ggx"):
        GGX(**bad)


def test_unknown_or_bad_coefficient():
    with pytest.raises(ConfigError, match="unknown coefficient 'roughness'"):
        GGX().set_coefficients(roughness=0.1)
    with pytest.raises(ConfigError, match="finite"):
        GGX().set_coefficients(ks=[1.0, float("nan"), 1.0])


# --------------------------------------------------------------------------- physics


def test_diffuse_albedo_is_kd():
    for name in MODELS:
        a = normal_incidence_albedo(model(name, kd=[1.0, 0.5, 0.25], ks=0.0), n=20_000)
        torch.testing.assert_close(a, torch.tensor([1.0, 0.5, 0.25], dtype=F64), rtol=1e-6, atol=0)


@pytest.mark.parametrize("alpha", [1e-3, 0.01, 0.1, 0.3, 0.6, 1.0])
def test_ggx_normal_incidence_albedo_at_most_one(alpha):
    a = float(normal_incidence_albedo(model("ggx", kd=0.0, ks=1.0, alpha=alpha, f0=1.0))[0])
    assert a <= 1.0 + 1e-6
    if alpha <= 0.01:  # a near-mirror loses (almost) nothing to shadowing
        assert a == pytest.approx(1.0, abs=2e-4)
    if alpha == 1.0:  # D = 1/π, G2 = 2μ/(1+μ): albedo = ∫ μ/(1+μ) dμ = 1 − ln 2
        assert a == pytest.approx(1 - math.log(2), rel=1e-6)


@pytest.mark.parametrize("alpha,theta_deg", [(0.1, 45.0), (0.3, 0.0), (0.3, 60.0), (0.3, 80.0), (0.6, 75.0)])
def test_ggx_white_furnace_monte_carlo(alpha, theta_deg):
    """k_d = 0, k_s = 1, F0 = 1: directional albedo ≤ 1 within Monte Carlo error.

    ωi is drawn by sampling h from the GGX D (pdf D cosθh / (4 ωo·h), written here
    independently of the model), so a wrong normalisation of D or of 1/(4 cos cos) shows.
    """
    n = 400_000
    g = torch.Generator().manual_seed(3)
    m = model("ggx", kd=0.0, ks=1.0, alpha=alpha, f0=1.0)
    wo = spherical_to_vector(torch.full((n,), math.radians(theta_deg), dtype=F64), torch.zeros(n, dtype=F64))
    u1, u2 = torch.rand(n, generator=g, dtype=F64), torch.rand(n, generator=g, dtype=F64)
    theta_h = torch.atan(alpha * torch.sqrt(u1 / (1 - u1)))
    h = spherical_to_vector(theta_h, 2 * math.pi * u2)
    oh = (wo * h).sum(1, keepdim=True)
    wi = 2 * oh * h - wo
    ch = h[:, 2]
    d = alpha**2 / (math.pi * ((alpha**2 - 1) * ch**2 + 1) ** 2)
    pdf = d * ch / (4 * oh[:, 0].abs())
    est = torch.where(wi[:, 2] > 0, m.eval(wi, wo)[:, 0] * wi[:, 2] / pdf, torch.zeros(n, dtype=F64))
    mean, err = float(est.mean()), float(est.std() / math.sqrt(n))
    assert mean <= 1.0 + 4 * err
    if alpha == 0.1 and theta_deg == 45.0:
        assert mean > 0.97  # smooth GGX loses only a little to shadowing-masking


def test_cook_torrance_smooth_albedo_is_f0():
    """Near-smooth Cook-Torrance at normal incidence reflects F0 = ((IoR−1)/(IoR+1))²."""
    for ior in (1.5, 2.5):
        a = normal_incidence_albedo(model("cook_torrance", kd=0.0, ks=1.0, roughness=0.1, ior=ior))
        f0 = ((ior - 1) / (ior + 1)) ** 2
        torch.testing.assert_close(a, torch.full((3,), f0, dtype=F64), rtol=2e-3, atol=0)


@pytest.mark.parametrize("n", [1.0, 4.0, 10.0, 100.0, 1e3, 1e5])
def test_blinn_phong_normalisation(n):
    """∫ (n+8)/(8π) cos^n θh cosθo dωo at normal incidence (θo = 2θh, θh < π/4) equals
    (n+8)(2(1−c^(n+4))/(n+4) − (1−c^(n+2))/(n+2)), c = cos π/4: within 7.5 % of 1 for every n,
    and → 1 as n grows."""
    a = float(normal_incidence_albedo(model("blinn_phong", kd=0.0, ks=1.0, exponent=n))[0])
    c = math.cos(math.pi / 4)
    exact = (n + 8) * (2 * (1 - c ** (n + 4)) / (n + 4) - (1 - c ** (n + 2)) / (n + 2))
    assert a == pytest.approx(exact, rel=1e-6)
    assert 0.9 < a < 1.075
    if n >= 1e3:
        assert a == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_reciprocity_is_exact(name, dtype):
    for family, (wi, wo) in adversarial_pairs(70_000, dtype, seed=11).items():
        m = model(name, **MODERATE[name])
        assert torch.equal(m.eval(wi, wo), m.eval(wo, wi)), family


# --------------------------------------------------------------------------- numerical stability


@pytest.mark.parametrize("name,coeffs", EXTREME, ids=[f"{n}-{'-'.join(f'{k}={v}' for k, v in c.items() if k not in ('kd', 'ks'))}" for n, c in EXTREME])
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_extreme_coefficients_stay_finite(name, coeffs, dtype):
    m = model(name, **coeffs)
    pairs = adversarial_pairs(70_000, dtype, seed=12)
    assert set(pairs) == set(FAMILIES)
    for family, (wi, wo) in pairs.items():
        out = m.eval(wi, wo)
        assert out.dtype == dtype
        assert bool(torch.isfinite(out).all()), f"non-finite values ({family})"
        assert float(out.max()) < 1e-6 * torch.finfo(dtype).max, f"saturated at the output clamp ({family})"
        assert bool((out >= 0).all()), f"negative values ({family})"
        if family == "below_horizon":
            assert bool((out == 0).all())
        else:
            assert bool((out >= 0.5 / math.pi * (1 - 1e-6)).all()), f"lost the diffuse term ({family})"


def near_peak_pairs(n: int, width: float, seed: int = 13):
    """Pairs with θh uniform in [0, width] (θd ≤ 80°), built in fp64 and rounded to fp32."""
    g = torch.Generator().manual_seed(seed)
    u = lambda: torch.rand(n, generator=g, dtype=F64)  # noqa: E731
    wi, wo = from_half_diff(width * u(), 2 * math.pi * u(), math.radians(80) * u(), 2 * math.pi * u())
    return wi.float(), wo.float()


def _fp32_rel_error(fn, wi, wo) -> float:
    """Max relative error of fn in fp32 against fn in fp64 on the very same (fp32) inputs."""
    a, b = fn(wi, wo).double(), fn(wi.double(), wo.double())
    return float(((a - b).abs() / b.abs()).max())


@pytest.mark.parametrize(
    "name,coeffs,width",
    [
        ("ggx", dict(kd=0.0, ks=1.0, alpha=1e-3, f0=0.04), 5e-3),
        ("cook_torrance", dict(kd=0.0, ks=1.0, roughness=1e-3, ior=1.5), 5e-6),
        ("cook_torrance", dict(kd=0.0, ks=1.0, roughness=0.0316, ior=1.5), 5e-3),
        ("blinn_phong", dict(kd=0.0, ks=1.0, exponent=1e6), 3e-3),
    ],
)
def test_narrow_lobes_are_accurate_in_fp32(name, coeffs, width):
    """The whole peak of a 1e-3-wide lobe (or n = 1e6) evaluates in fp32 to ~1e-6 relative.

    The textbook forms fail this: ((α²−1)cos²θh + 1) and cos^n θh cancel in fp32 near the
    peak (errors of 10-30 %), which the second half checks so the tolerance stays meaningful.
    """
    wi, wo = near_peak_pairs(100_000, width)
    m = model(name, **coeffs)
    assert _fp32_rel_error(lambda a, b: m.eval(a, b), wi, wo) < 1e-4

    def naive(a, b):
        c = (a + b)[:, 2] / (a + b).norm(dim=1)
        if name == "blinn_phong":
            return c ** coeffs["exponent"]
        al = coeffs.get("alpha", coeffs.get("roughness", 0) ** 2)
        return al * al / (math.pi * ((al * al - 1) * c * c + 1) ** 2)

    assert _fp32_rel_error(naive, wi, wo) > 1e-2


# --------------------------------------------------------------------------- fitting

def self_target(name: str, coeffs: dict, invalid_fraction: float = 0.02, seed: int = 0) -> Material:
    """A MERL table evaluated from the model itself (cells below the horizon and a random
    fraction of the others invalid)."""
    wi, wo = merl.grid_directions()
    values = model(name, **coeffs).eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    valid = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)
    valid &= np.random.default_rng(seed).random(merl.SHAPE) >= invalid_fraction
    return Material(f"self-{name}", MerlTable.from_values(values, valid), "synthetic-self")


RECOVERY = {
    "cook_torrance": dict(kd=[0.3, 0.1, 0.05], ks=[0.8, 0.9, 1.0], roughness=0.35, ior=1.6),
    "ggx": dict(kd=[0.02, 0.02, 0.03], ks=[0.9, 0.7, 0.4], alpha=0.02, f0=0.6),
    "blinn_phong": dict(kd=[0.3, 0.1, 0.05], ks=[0.5, 0.6, 0.7], exponent=300.0),
}


@pytest.mark.parametrize("name", MODELS)
def test_fit_recovers_known_coefficients(name):
    truth = RECOVERY[name]
    fitted = MODELS[name]().fit(self_target(name, truth), seed=0)
    assert fitted.fit_loss < 1e-4
    for key, want in truth.items():
        torch.testing.assert_close(fitted.coeffs[key], torch.tensor(want, dtype=F64).reshape(-1).expand_as(fitted.coeffs[key]), rtol=1e-3, atol=1e-5)


@pytest.fixture(scope="module")
def plastic():
    from brdfbench.data.synthetic import generate_material

    name, category, table = generate_material(0, seed=0)
    return Material(name, table, category)


@pytest.fixture(scope="module")
def plastic_fits(plastic):
    return {name: cls().fit(plastic, seed=0) for name, cls in MODELS.items()}


def l1_log_cos(m, target, n: int = 2**18) -> float:
    """The benchmark's l1_log_cos (fp32 evaluation), on a fixed random 2^18 of the usable cells."""
    wi, wo = merl.grid_directions()
    usable = np.flatnonzero(target.table.valid.reshape(-1) & (wi[:, 2] > 0).numpy() & (wo[:, 2] > 0).numpy())
    cells = torch.from_numpy(np.random.default_rng(123).choice(usable, size=n, replace=False))
    ref = torch.from_numpy(target.table.values.reshape(3, -1)).T[cells]
    pred = m.eval(wi[cells].float(), wo[cells].float())
    return float(l1_log_cos_metric(pred, ref, wi[cells, 2]))


@pytest.mark.parametrize("name", MODELS)
def test_fit_on_synthetic_beats_lambert(name, plastic, plastic_fits):
    lambert = l1_log_cos(Lambert().fit(plastic), plastic)
    fitted = plastic_fits[name]
    loss = l1_log_cos(fitted, plastic)
    assert loss < 0.9 * lambert
    if name != "blinn_phong":  # microfacet models capture the Fresnel-brightened grazing lobe
        assert loss < 0.3 * lambert
    # The fit loss (on the subsample) estimates the benchmark's full-grid figure.
    assert fitted.fit_loss == pytest.approx(loss, rel=0.05)


def test_fit_metadata_and_round_trip(plastic_fits, tmp_path):
    from brdfbench import modelio

    for name, m in plastic_fits.items():
        meta = m.metadata()
        assert json.loads(json.dumps(meta)) == meta
        assert meta["fit_loss"] == m.fit_loss and meta["restarts"] == 4
        assert len(meta["restart_losses"]) == 4 and meta["n_fit_cells"] == 32768
        assert all(t.dtype == F64 for t in m.state_dict().values())
        _, loaded = modelio.load(modelio.save(m, name, tmp_path / f"{name}.safetensors"))
        assert loaded.fit_loss == m.fit_loss and loaded.metadata() == meta
        for key, t in m.state_dict().items():
            assert torch.equal(loaded.coeffs[key], t)


def test_fit_is_deterministic_and_seed_dependent(plastic, plastic_fits):
    again = GGX().fit(plastic, seed=0)
    first = plastic_fits["ggx"]
    assert again.fit_loss == first.fit_loss and again.metadata() == first.metadata()
    for key, t in first.state_dict().items():
        assert torch.equal(again.coeffs[key], t)
    other = GGX().fit(plastic, seed=1)  # another subsample: a different but equally good fit
    assert not torch.equal(other.coeffs["alpha"], first.coeffs["alpha"])
    assert other.fit_loss == pytest.approx(first.fit_loss, rel=0.05)


def test_fit_does_not_change_torch_threads(plastic):
    before = torch.get_num_threads()
    BlinnPhong(n_samples=4096, restarts=1).fit(plastic)
    assert torch.get_num_threads() == before


def test_fit_ignores_invalid_cells():
    """Invalid cells (any raw value, here huge negative ones) must not move the fit."""
    target = self_target("ggx", RECOVERY["ggx"], invalid_fraction=0.3, seed=5)
    raw = target.table.raw.copy()
    raw[:, ~target.table.valid] = -1e30
    fitted = GGX().fit(Material(target.name, MerlTable(raw)), seed=0)
    assert fitted.fit_loss < 1e-4
    assert float(fitted.coeffs["alpha"]) == pytest.approx(0.02, rel=1e-3)


@pytest.mark.parametrize("name", MODELS)
def test_all_invalid_target_is_a_data_error(name):
    table = MerlTable(np.full((3, *merl.SHAPE), -1.0))
    with pytest.raises(DataError, match=r"all-invalid-mat.*no valid MERL cell"):
        MODELS[name]().fit(Material("all-invalid-mat", table))


@pytest.mark.parametrize("name", MODELS)
def test_nan_target_is_a_data_error(name):
    raw = np.full((3, *merl.SHAPE), 100.0)
    raw[1, 3, 4, 5] = np.nan
    with pytest.raises(DataError, match=r"nan-mat.*non-finite.*channel 1, index \(3, 4, 5\)"):
        MODELS[name]().fit(Material("nan-mat", MerlTable(raw)))


def test_small_target_still_fits():
    """A target with only a handful of valid cells (fewer than n_samples) fits without error."""
    target = self_target("blinn_phong", RECOVERY["blinn_phong"], invalid_fraction=0.9999, seed=9)
    assert 10 < int(target.table.valid.sum()) < 1000
    fitted = BlinnPhong().fit(target)
    assert math.isfinite(fitted.fit_loss) and fitted.fit_loss < 0.05
    assert fitted.metadata()["n_fit_cells"] == fitted.metadata()["n_usable_cells"]


@pytest.mark.parametrize("name,coeffs", EXTREME[::2], ids=[n for n, _ in EXTREME[::2]])
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_directions_a_hair_above_the_horizon(name, coeffs, dtype):
    """cosθ down to the smallest subnormal (far past the kit's 1e-7 rad): the 1/(cosθi cosθo)
    of a nearly shadowing-free G must not overflow."""
    tiny = torch.finfo(dtype).tiny
    zs = torch.tensor([1e-7, 1e-20, 1e-30, float(tiny), float(tiny) * 2**-20], dtype=dtype)
    zs = zs[zs > 0]
    z1, z2 = torch.meshgrid(zs, zs, indexing="ij")
    z1, z2 = z1.reshape(-1), z2.reshape(-1)
    for phi in (0.0, 0.5, math.pi):  # mirror (θh = 0), oblique and retro (ωi = ωo) pairs
        wi = torch.stack((torch.sqrt(1 - z1 * z1), torch.zeros_like(z1), z1), dim=1)
        wo = torch.stack((-math.cos(phi) * torch.sqrt(1 - z2 * z2), math.sin(phi) * torch.sqrt(1 - z2 * z2), z2), dim=1)
        out = model(name, **coeffs).eval(wi, wo)
        assert bool(torch.isfinite(out).all() and (out >= 0).all()), (phi, out)
        assert float(out.max()) < 1e-6 * torch.finfo(dtype).max, "saturated: the output clamp, not the model, kept it finite"


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_lambert_albedo_is_the_same_at_any_thread_count(plastic, threads):
    """The channels' medians are sorted in parallel threads: the albedo is each channel's
    weighted median exactly as computed alone."""
    from brdfbench.threads import torch_threads
    from brdfbench_representations.lambert import weighted_median

    wi, wo = (d[:, 2].numpy() for d in merl.grid_directions())
    valid = plastic.table.valid.reshape(-1) & merl.grid_above_horizon().numpy()
    values = plastic.table.values.reshape(3, -1)[:, valid]
    alone = [math.pi * weighted_median(v, (wi * wo)[valid]) for v in values]
    with torch_threads(threads):
        assert Lambert().fit(plastic).albedo.tolist() == alone


@pytest.mark.parametrize("eta", [1.0, 1.0001, 1.01, 1.05, 1.5, 2.5, 20.0, 999.0, 0.7])
def test_dielectric_fresnel_is_the_average_of_the_two_polarisations(eta):
    """Cook and Torrance's closed form against Fresnel's equations through Snell's law, in
    fp64 and fp32 (η near 1 included, where g − c cancels unless rewritten)."""
    from brdfbench_representations.analytic_terms import fresnel_dielectric

    cos = np.concatenate([np.geomspace(1e-7, 1e-3, 50), np.linspace(1e-6, 1.0, 2001), [1.0]])

    def snell(eta, cos):
        """Fresnel's equations through Snell's law, cos²θt = 1 − sin²θd/η² = ((η² − 1) +
        cos²θd)/η², in that order so that a grazing cos²θd is not lost next to 1 (at η = 1,
        θt = θd exactly and F = 0)."""
        cos2_t = ((eta**2 - 1) + cos**2) / eta**2
        with np.errstate(invalid="ignore"):
            cos_t = np.sqrt(cos2_t)
            rs = (cos - eta * cos_t) / (cos + eta * cos_t)
            rp = (eta * cos - cos_t) / (eta * cos + cos_t)
        return np.where(cos2_t <= 0, 1.0, 0.5 * (rs**2 + rp**2))

    got = fresnel_dielectric(torch.tensor(eta, dtype=F64), torch.from_numpy(cos)).numpy()
    np.testing.assert_allclose(got, snell(eta, cos), rtol=1e-10, atol=1e-15)
    # fp32 against the same fp32 inputs (η = 1.0001 rounds to fp32 with a relative error in
    # η² − 1 of ~3e-4, which no formula can undo)
    eta32, cos32 = torch.tensor(eta), torch.from_numpy(cos).float()
    got32 = fresnel_dielectric(eta32, cos32).double().numpy()
    np.testing.assert_allclose(got32, snell(float(eta32), cos32.double().numpy()), rtol=2e-5, atol=1e-9)
