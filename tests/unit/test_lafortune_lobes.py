"""Several Lafortune lobes (lafortune_lobes.py): the paper's sum of generalised cosine lobes
written independently in numpy, one lobe reducing to `lafortune`, reciprocity, fp32 at the
extremes, the fit finding a second lobe that one lobe cannot, and the drjit kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfbench import merl, mitsuba_env
from brdfbench.plugins import registry
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.testing import adversarial_pairs
from brdfbench_representations.lafortune_lobes import MODELS, Lafortune2, Lafortune3
from brdfbench_representations.ngan_models import Lafortune

F64 = torch.float64
TWO = dict(kd=[0.1, 0.05, 0.02], ks=[0.4, 0.5, 0.6], cxy=-0.9, cz=0.88, exponent=120.0,
           weight2=[0.3, 0.2, 0.1], cxy2=-0.7, cz2=0.9, exponent2=8.0)
THREE = dict(TWO, weight3=[0.05, 0.1, 0.2], cxy3=0.6, cz3=0.6, exponent3=4.0)  # a retro-reflective third lobe


def _pairs(n=4000, seed=0):
    g = np.random.default_rng(seed)
    ti, to = np.arccos(g.uniform(0.02, 1, n)), np.arccos(g.uniform(0.02, 1, n))
    pi, po = g.uniform(0, 2 * math.pi, n), g.uniform(0, 2 * math.pi, n)
    wi = np.stack((np.sin(ti) * np.cos(pi), np.sin(ti) * np.sin(pi), np.cos(ti)), 1)
    wo = np.stack((np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)), 1)
    return wi, wo


def _paper(c, wi, wo, lobes):
    """k_d/π + Σ_j ρ_j (C_xy,j (u_x v_x + u_y v_y) + C_z,j u_z v_z)^n_j (n_j + 2)/(2π max(C²)^(n_j/2)),
    ρ₁ = k_s, ρ_j = k_s w_j (Lafortune et al. 1997, with Ngan et al.'s normalisation), in logs."""
    out = np.tile(np.asarray(c["kd"]) / math.pi, (wi.shape[0], 1))
    for j in range(1, lobes + 1):
        s = "" if j == 1 else str(j)
        n, cxy, cz = c["exponent" + s], c["cxy" + s], c["cz" + s]
        u = cxy * (wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1]) + cz * wi[:, 2] * wo[:, 2]
        with np.errstate(divide="ignore"):
            lobe = (n + 2) / (2 * math.pi) * np.exp(n * np.log(np.maximum(u, 0.0)) - n / 2 * np.log(max(cxy**2, cz**2)))
        rho = np.asarray(c["ks"]) * (1.0 if j == 1 else np.asarray(c["weight" + s]))
        out += lobe[:, None] * rho[None, :]
    return out


@pytest.mark.parametrize(("cls", "coeffs", "lobes"), [(Lafortune2, TWO, 2), (Lafortune3, THREE, 3)])
def test_matches_the_papers_sum_of_lobes(cls, coeffs, lobes):
    wi, wo = _pairs()
    got = cls().set_coefficients(**coeffs).eval(torch.from_numpy(wi), torch.from_numpy(wo)).numpy()
    np.testing.assert_allclose(got, _paper(coeffs, wi, wo, lobes), rtol=1e-9, atol=1e-13)


def test_the_first_lobe_is_lafortune_and_extra_lobes_add():
    wi, wo = (torch.from_numpy(x) for x in _pairs(seed=1))
    one = {k: TWO[k] for k in ("kd", "ks", "cxy", "cz", "exponent")}
    single = Lafortune().set_coefficients(**one).eval(wi, wo)
    second = Lafortune().set_coefficients(kd=0.0, ks=torch.tensor(TWO["ks"], dtype=F64) * torch.tensor(TWO["weight2"], dtype=F64),
                                          cxy=TWO["cxy2"], cz=TWO["cz2"], exponent=TWO["exponent2"]).eval(wi, wo)
    torch.testing.assert_close(Lafortune2().set_coefficients(**TWO).eval(wi, wo), single + second, rtol=1e-12, atol=0)


@pytest.mark.parametrize("cls", list(MODELS.values()))
def test_reciprocal_and_finite_in_fp32_at_the_bounds(cls):
    bounds = {c.name: (c.upper if i % 2 else c.lower) for i, c in enumerate(cls.COEFFS)}
    m = cls().set_coefficients(**bounds)
    for family, (wi, wo) in adversarial_pairs(6000, torch.float32, seed=3).items():
        f = m.eval(wi, wo)
        assert torch.isfinite(f).all() and (f >= 0).all(), family
    m = cls().set_coefficients(**(THREE if cls is Lafortune3 else TWO))
    wi, wo = (torch.from_numpy(x) for x in _pairs(seed=2))
    torch.testing.assert_close(m.eval(wi, wo), m.eval(wo, wi), rtol=1e-12, atol=0)


def test_registered_with_flops_and_no_published_fits():
    from brdfbench_representations.published import published_forms

    for name, cls in MODELS.items():
        assert registry.get("representations", name).load() is cls
        assert cls.FLOPS > Lafortune.FLOPS and cls().flops_per_eval == cls.FLOPS
        assert set(cls.init_shape(0.1)) == {c.name for c in cls.COEFFS[2:]}
    assert Lafortune3.FLOPS > Lafortune2.FLOPS
    assert published_forms()["NganLafortune"] is Lafortune  # the one-lobe model still evaluates Ngan's fits


@pytest.fixture(scope="module")
def two_lobe_target():
    wi, wo = merl.grid_directions()
    valid = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)
    values = Lafortune2().set_coefficients(**TWO).eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    return Material("two-lobes", MerlTable.from_values(values, valid), "synthetic-self")


def test_two_lobes_fit_what_one_lobe_cannot(two_lobe_target):
    quick = {"n_samples": 4096, "restarts": 2}
    one = Lafortune(**quick).fit(two_lobe_target, seed=0)
    two = Lafortune2(**quick).fit(two_lobe_target, seed=0)
    assert two.fit_loss < 0.5 * one.fit_loss, (two.fit_loss, one.fit_loss)
    assert two.fit_loss < 0.02, two.fit_loss


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="llvm_ad_rgb needs libLLVM >= 19")
@pytest.mark.parametrize(("cls", "coeffs"), [(Lafortune2, TWO), (Lafortune3, THREE)])
def test_drjit_kernel_agrees_with_torch(cls, coeffs):
    m = cls().set_coefficients(**coeffs)
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT) as mi:
        def vec(t):
            return mi.Vector3f(*(mi.Float(t[:, c].numpy().copy()) for c in range(3)))

        kernel = m.drjit_kernel()
        assert kernel is not None

        class Elsewhere(cls):
            pass

        Elsewhere.__module__ = __name__
        assert Elsewhere().drjit_kernel() is None  # a subclass may change the lobe
        for family, (wi, wo) in adversarial_pairs(14_000, torch.float32, seed=9).items():
            if family == "below_horizon":
                continue
            got = np.stack([np.asarray(c) for c in kernel.eval(vec(wi), vec(wo))], axis=1)
            cos = wo[:, 2:3].numpy()
            np.testing.assert_allclose(got * cos, m.eval(wi, wo).numpy() * cos, rtol=2e-5, atol=1e-6, err_msg=family)
