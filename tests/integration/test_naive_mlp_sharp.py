"""The naive MLP on a sharp lobe (issue 16): trained on the L1 loss alone it stays on the
diffuse-only (median) solution, l1_log_cos equal to lambert's; the squared log error finds
the lobe, and the default (`loss=l1_or_l2`) keeps whichever fit ends at the lower L1 loss.
The material is the synthetic set's phenolic-red-11, the sharpest of its 24 by lobe
half-width (0.0135 rad)."""

from __future__ import annotations

import pytest
import torch

import brdfbench as bb
from brdfbench.data.synthetic import generate_material
from brdfbench.errors import ConfigError
from brdfbench.protocol import Material
from brdfbench_representations.nbrdf import NBRDF, NaiveMLP

N_RANDOM = 2**14


@pytest.fixture(scope="module")
def sharp():
    name, category, table = generate_material(11, seed=0)
    material = Material(name, table, category)
    lambert = bb.evaluate(bb.representation("lambert").fit(material), material, metrics=["l1_log_cos"],
                          n_random=N_RANDOM, cost=False)["l1_log_cos"]
    return material, lambert


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
    assert model.params["loss"] == "l1_or_l2" and model.fit_info["descended"] == "l2"
    assert _score(model, material) < 0.3 * lambert


def test_the_kept_fit_is_the_one_with_the_lower_l1_loss(sharp):
    material, _ = sharp
    small = dict(hidden=[8, 8], epochs=3, n_samples=50_000)
    fits = {loss: NaiveMLP(loss=loss, **small).fit(material, seed=0) for loss in ("l1", "l2", "l1_or_l2")}
    losses = {loss: m.fit_info["fit_loss"] for loss, m in fits.items()}
    kept = fits["l1_or_l2"].fit_info["descended"]
    assert losses["l1_or_l2"] == min(losses["l1"], losses["l2"]) == losses[kept]
    for name, w in fits["l1_or_l2"].weights.items():
        assert torch.equal(w, fits[kept].weights[name])


def test_nbrdf_keeps_the_published_loss():
    assert NBRDF().params["loss"] == "l1" and NaiveMLP(loss="l2").params["loss"] == "l2"
    assert "descended" not in NBRDF(epochs=1, n_samples=20_000).fit(_tiny_material()).fit_info


@pytest.mark.parametrize("bad", ["l3", "", 1, None.__class__.__name__])
def test_a_bad_loss_names_the_key(bad):
    with pytest.raises(ConfigError, match="loss"):
        NaiveMLP(loss=bad)
