"""The naive MLP on a sharp lobe (issue 16): trained on the L1 loss alone it stays on the
diffuse-only (median) solution, l1_log_cos equal to lambert's; the default recipe's squared-
error warm-up (`l2_warmup`) lets it find the lobe. The material is the synthetic set's
phenolic-red-11, the sharpest of its 24 by lobe half-width (0.0135 rad)."""

from __future__ import annotations

import pytest

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


def _score(model, material) -> float:
    return bb.evaluate(model, material, metrics=["l1_log_cos"], n_random=N_RANDOM, cost=False)["l1_log_cos"]


@pytest.mark.parametrize("hidden", [[21, 21], [16, 16]], ids=["default", "equal_flops"])
def test_the_l1_loss_alone_collapses_to_lambert(sharp, hidden):
    material, lambert = sharp
    model = NaiveMLP(hidden=hidden, l2_warmup=0.0).fit(material, seed=0)
    assert _score(model, material) == pytest.approx(lambert, rel=0.02)


@pytest.mark.parametrize("hidden", [[21, 21], [16, 16]], ids=["default", "equal_flops"])
def test_the_default_recipe_finds_the_lobe(sharp, hidden):
    material, lambert = sharp
    model = NaiveMLP(hidden=hidden).fit(material, seed=0)
    assert model.params["l2_warmup"] == 0.3
    # measured 0.10-0.13 of lambert's at one and two threads (seeds 0-3 on a 6-material batch: below 0.15)
    assert _score(model, material) < 0.3 * lambert


def test_nbrdf_keeps_the_published_loss():
    assert NBRDF().params["l2_warmup"] == 0.0 and NaiveMLP(l2_warmup=0.1).params["l2_warmup"] == 0.1


@pytest.mark.parametrize("bad", [-0.1, 1.5, "half", True, float("nan")])
def test_a_bad_warmup_names_the_key(bad):
    with pytest.raises(ConfigError, match="l2_warmup"):
        NaiveMLP(l2_warmup=bad)
