"""The fitting loss as a choice (`loss` of every analytic fit): the published metrics'
sampling, their values, recovery under each, and the default left exactly as it was."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import stats

from brdfbench import merl
from brdfbench.errors import ConfigError
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench_representations.analytic import GGX, BlinnPhong
from brdfbench_representations.fit_losses import FIT_LOSSES, LOSSES, sample_pairs
from brdfbench_representations.fitting import prepare

#: Significance level of the distribution tests below.
ALPHA = 1e-3
TRUTH = dict(kd=[0.3, 0.2, 0.1], ks=[0.6, 0.5, 0.4], alpha=0.3, f0=0.2)


def _target(model) -> Material:
    wi, wo = merl.grid_directions()
    values = model.eval(wi, wo).T.reshape(3, *merl.SHAPE).numpy()
    valid = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)
    return Material("self-ggx", MerlTable.from_values(values, valid), "synthetic-self")


@pytest.fixture(scope="module")
def target():
    return _target(GGX().set_coefficients(**TRUTH))


def _usable(target):
    return target.table.valid.reshape(-1) & merl.grid_above_horizon().numpy()


def test_solid_angle_pairs_are_uniform_on_both_hemispheres(target):
    wi, wo, cells = sample_pairs(LOSSES["ngan_l2"], 20000, 3, np.ones(merl.N_CELLS, bool))
    assert wi.shape == wo.shape == (20000, 3) and cells.shape == (20000,)
    for w in (wi, wo):  # uniform in solid angle: cosθ ~ U(0, 1), φ ~ U(0, 2π)
        assert stats.kstest(w[:, 2].numpy(), "uniform").pvalue > ALPHA
        phi = torch.atan2(w[:, 1], w[:, 0]).remainder(2 * math.pi).numpy() / (2 * math.pi)
        assert stats.kstest(phi, "uniform").pvalue > ALPHA


def test_incidence_plane_pairs_sample_theta_out_in_angle(target):
    wi, wo, _ = sample_pairs(LOSSES["low_e1"], 20000, 4, np.ones(merl.N_CELLS, bool))
    assert torch.all(wo[:, 1] == 0) and torch.all(wo[:, 0] >= 0)  # φo = 0
    theta_o = torch.acos(wo[:, 2].clamp(-1, 1)).numpy() / (math.pi / 2)
    assert stats.kstest(theta_o, "uniform").pvalue > ALPHA
    assert stats.kstest(wi[:, 2].numpy(), "uniform").pvalue > ALPHA


def test_pairs_on_invalid_cells_are_dropped(target):
    usable = _usable(target).copy()
    usable[np.random.default_rng(0).random(usable.size) < 0.5] = False
    _, _, cells = sample_pairs(LOSSES["ngan_l2"], 5000, 1, usable)
    assert len(cells) == 5000 and usable[cells].all()


@pytest.mark.parametrize("loss", FIT_LOSSES)
def test_the_loss_compares_what_its_authors_compared(loss, target):
    data = prepare(target, 4096, 0, "ggx", loss)
    f = torch.from_numpy(target.table.values.reshape(3, -1).T)
    cos_i = data.cos_i
    back = (torch.expm1(data.y) if LOSSES[loss].log else data.y) / cos_i
    # each row's target is the table's value at the pair's nearest cell, compared as the loss says
    torch.testing.assert_close(back, f[torch.from_numpy(data.cells)].clamp_min(0), rtol=1e-9, atol=1e-12)
    if LOSSES[loss].sampling != "cells":
        wi, wo, cells = sample_pairs(LOSSES[loss], 4096, 0, _usable(target))
        assert np.array_equal(cells, data.cells) and torch.equal(wi[:, 2:3], cos_i)
        assert np.array_equal(merl.flat_index(*merl.cell_indices(wi, wo)).numpy(), cells)


@pytest.mark.parametrize("loss", FIT_LOSSES)
def test_each_loss_recovers_a_model_from_its_own_table(loss, target):
    fitted = GGX(n_samples=8192, restarts=2, loss=loss).fit(target, seed=0)
    assert fitted.fit_info["loss"] == loss
    # nearest-cell targets at exact directions: close, not exact, away from the cells' centres
    torch.testing.assert_close(fitted.alpha, torch.tensor([TRUTH["alpha"]], dtype=torch.float64), rtol=0.05, atol=0)
    torch.testing.assert_close(fitted.kd, torch.tensor(TRUTH["kd"], dtype=torch.float64), rtol=0.05, atol=0.005)


def test_the_default_loss_leaves_params_and_fits_as_they_were(target):
    assert GGX().params == {"n_samples": 32768, "restarts": 4}  # configuration identity unchanged
    assert GGX(loss="low_e2").params == {"n_samples": 32768, "restarts": 4, "loss": "low_e2"}
    a = BlinnPhong(n_samples=2048, restarts=1).fit(target, seed=1)
    b = BlinnPhong(n_samples=2048, restarts=1, loss="l1_log_cos").fit(target, seed=1)
    assert all(torch.equal(a.coeffs[k], b.coeffs[k]) for k in a.coeffs) and a.fit_loss == b.fit_loss


def test_an_unknown_loss_is_one_line_naming_it():
    with pytest.raises(ConfigError, match=r"ggx: loss must be one of l1_log_cos, ngan_l2, low_e1, low_e2, got 'l2'"):
        GGX(loss="l2")
