"""The naive MLP on a sharp lobe (issue 16): trained on the L1 loss alone it stays on the
diffuse-only (median) solution, l1_log_cos equal to lambert's; the squared log error finds
the lobe. The default (`loss=l1_then_l2`) refits with it only where the L1 fit collapsed
(its loss near the best constant BRDF's) and keeps whichever fit ends at the lower L1 loss;
`l1_or_l2` fits both everywhere. The material is the synthetic set's phenolic-red-11, the
sharpest of its 24 by lobe half-width (0.0135 rad); the smooth one its felt-brown-09."""

from __future__ import annotations

import pytest
import torch

import brdfbench as bb
from brdfbench.data.synthetic import generate_material
from brdfbench.errors import ConfigError
from brdfbench.protocols.representation import Material
from brdfbench_representations.nbrdf import NBRDF, NaiveMLP
from brdfbench_representations.nbrdf_fit import COLLAPSE_RATIO

N_RANDOM = 2**14


@pytest.fixture(scope="module")
def sharp():
    name, category, table = generate_material(11, seed=0)
    material = Material(name, table, category)
    lambert = bb.evaluate(bb.representation("lambert").fit(material), material, metrics=["l1_log_cos"],
                          n_random=N_RANDOM, cost=False)["l1_log_cos"]
    return material, lambert


@pytest.fixture(scope="module")
def smooth():
    name, category, table = generate_material(9, seed=0)
    return Material(name, table, category)


def _tiny_material() -> Material:
    name, category, table = generate_material(1, seed=0)
    return Material(name, table, category)


def _score(model, material) -> float:
    return bb.evaluate(model, material, metrics=["l1_log_cos"], n_random=N_RANDOM, cost=False)["l1_log_cos"]


@pytest.mark.parametrize("hidden", [[21, 21], [16, 16]], ids=["default", "equal_flops"])
def test_the_l1_loss_alone_collapses_to_lambert(sharp, hidden):
    material, lambert = sharp
    model = NaiveMLP(hidden=hidden, loss="l1").fit(material, seed=0)
    assert _score(model, material) == pytest.approx(lambert, rel=0.02)


@pytest.mark.parametrize("hidden", [[21, 21], [16, 16]], ids=["default", "equal_flops"])
def test_the_default_recipe_finds_the_lobe(sharp, hidden):
    material, lambert = sharp
    model = NaiveMLP(hidden=hidden).fit(material, seed=0)
    assert model.params["loss"] == "l1_then_l2" and model.fit_info["descended"] == "l2"
    assert model.fit_info["losses_fitted"] == ["l1", "l2"]  # the collapse detector fired
    assert model.fit_info["collapse_ratio"] > COLLAPSE_RATIO
    assert _score(model, material) < 0.3 * lambert


def test_a_smooth_material_is_fitted_once(smooth):
    model = NaiveMLP().fit(smooth, seed=0)
    assert model.fit_info["losses_fitted"] == ["l1"] and model.fit_info["descended"] == "l1"
    assert model.fit_info["collapse_ratio"] < COLLAPSE_RATIO


def test_the_kept_fit_is_the_one_with_the_lower_l1_loss(sharp):
    material, _ = sharp
    small = dict(hidden=[8, 8], epochs=3, n_samples=50_000)
    fits = {loss: NaiveMLP(loss=loss, **small).fit(material, seed=0) for loss in ("l1", "l2", "l1_or_l2", "l1_then_l2")}
    losses = {loss: m.fit_info["fit_loss"] for loss, m in fits.items()}
    kept = fits["l1_or_l2"].fit_info["descended"]
    assert losses["l1_or_l2"] == min(losses["l1"], losses["l2"]) == losses[kept]
    for name, w in fits["l1_or_l2"].weights.items():
        assert torch.equal(w, fits[kept].weights[name])
    then = fits["l1_then_l2"].fit_info
    fired = then["collapse_ratio"] > COLLAPSE_RATIO
    assert then["losses_fitted"] == (["l1", "l2"] if fired else ["l1"])
    assert losses["l1_then_l2"] == (losses["l1_or_l2"] if fired else losses["l1"])


def test_nbrdf_keeps_the_published_loss():
    assert NBRDF().params["loss"] == "l1" and NaiveMLP(loss="l2").params["loss"] == "l2"
    info = NBRDF(epochs=1, n_samples=20_000).fit(_tiny_material()).fit_info
    assert "descended" not in info and "collapse_ratio" not in info


@pytest.mark.parametrize("bad", ["l3", "", 1, None.__class__.__name__])
def test_a_bad_loss_names_the_key(bad):
    with pytest.raises(ConfigError, match="loss"):
        NaiveMLP(loss=bad)
