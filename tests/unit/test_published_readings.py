"""Two readings of a disputed published fit: Ngan et al.'s "Blinn-Phong" fits evaluated as
BBM reads them (the mirror-direction lobe, `phong`, the default) or with the half vector
(`published_fit` with model=blinn_phong_ngan); choosing the reading, refusing a wrong one,
saving it, and the report pairing it with refits of its own model."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfbench import modelio
from brdfbench.errors import ConfigError
from brdfbench.merl import MerlTable
from brdfbench.protocols.representation import Material
from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row
from brdfbench_leaderboard.published_fits_view import build
from brdfbench_representations.ngan_models import BlinnPhongNgan, Phong
from brdfbench_representations.published import (PublishedFit, load_source, published_forms, published_readings,
                                                 reading_names)

ALUM = load_source("ngan_blinnphong").lookup("alum-bronze")  # albedo ≈ 0.05, sharpness 1290


def _target(name="alum-bronze") -> Material:
    values = np.zeros((3, 90, 90, 180))
    return Material(name, MerlTable.from_values(values, np.ones((90, 90, 180), dtype=bool)), "test")


def _pairs(n=3000, seed=0):
    g = torch.Generator().manual_seed(seed)
    t = torch.rand(n, 4, generator=g, dtype=torch.float64)
    ti, to = torch.acos(1 - 0.95 * t[:, 0]), torch.acos(1 - 0.95 * t[:, 1])
    pi, po = 2 * math.pi * t[:, 2], 2 * math.pi * t[:, 3]
    wi = torch.stack((torch.sin(ti) * torch.cos(pi), torch.sin(ti) * torch.sin(pi), torch.cos(ti)), 1)
    wo = torch.stack((torch.sin(to) * torch.cos(po), torch.sin(to) * torch.sin(po), torch.cos(to)), 1)
    return wi, wo


def test_the_blinn_phong_fits_have_two_readings_bbms_first():
    assert published_readings()["NganBlinnPhong"] == (Phong, BlinnPhongNgan)
    assert published_forms()["NganBlinnPhong"] is Phong
    assert all(len(v) == 1 for k, v in published_readings().items() if k != "NganBlinnPhong")
    assert reading_names()["blinn_phong_ngan"] is BlinnPhongNgan


def test_each_reading_evaluates_the_printed_parameters():
    wi, wo = _pairs()
    kd, ks = np.array(ALUM.diffuse), np.array(ALUM.params["albedo"])
    n = float(ALUM.params["sharpness"])
    h = (wi + wo) / torch.linalg.vector_norm(wi + wo, dim=1, keepdim=True)
    half = kd / math.pi + ((n + 2) / (2 * math.pi) * h[:, 2].numpy() ** n)[:, None] * ks
    mirror_dir = torch.stack((-wi[:, 0], -wi[:, 1], wi[:, 2]), 1)
    cos_a = (mirror_dir * wo).sum(1).clamp(min=0).numpy()
    mirror = kd / math.pi + ((n + 2) / (2 * math.pi) * cos_a ** n)[:, None] * ks
    default = PublishedFit(source="ngan_blinnphong").fit(_target())
    other = PublishedFit(source="ngan_blinnphong", model="blinn_phong_ngan").fit(_target())
    np.testing.assert_allclose(default.eval(wi, wo).numpy(), mirror, rtol=1e-8, atol=1e-300)
    np.testing.assert_allclose(other.eval(wi, wo).numpy(), half, rtol=1e-8, atol=1e-300)
    assert default.metadata()["model"] == "phong" and other.metadata()["model"] == "blinn_phong_ngan"


def test_the_default_reading_leaves_the_configuration_as_it_was(tmp_path):
    assert PublishedFit(source="ngan_blinnphong").params == {"source": "ngan_blinnphong", "material": None}
    chosen = PublishedFit(source="ngan_blinnphong", model="blinn_phong_ngan")
    assert chosen.params == {"source": "ngan_blinnphong", "material": None, "model": "blinn_phong_ngan"}
    fitted = chosen.fit(_target())
    path = tmp_path / "m.brdfbench"
    modelio.save(fitted, "published_fit", path)
    name, back = modelio.load(path)
    assert name == "published_fit"
    wi, wo = _pairs(200)
    assert torch.equal(back.eval(wi, wo), fitted.eval(wi, wo)) and back.params == chosen.params


def test_a_wrong_reading_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"model='blinn_phong_nga' evaluates no published fits; did you mean 'blinn_phong_ngan'\?"):
        PublishedFit(source="ngan_blinnphong", model="blinn_phong_nga")
    with pytest.raises(ConfigError, match=r"model='ward' does not evaluate ngan_blinnphong's NganBlinnPhong fits "
                                          r"\(those: blinn_phong_ngan, phong\)"):
        PublishedFit(source="ngan_blinnphong", model="ward").preflight()
    PublishedFit(source="ngan_blinnphong", model="phong").preflight()


def test_the_report_pairs_a_reading_with_refits_of_its_own_model(tmp_path):
    store = ResultsStore(tmp_path / "brdfbench.sqlite")
    configs = {
        "pub_mirror": ("published_fit", {"source": "ngan_blinnphong", "material": None}),
        "pub_half": ("published_fit", {"source": "ngan_blinnphong", "material": None, "model": "blinn_phong_ngan"}),
        "phong": ("phong", {"n_samples": 32768, "restarts": 4}),
        "half": ("blinn_phong_ngan", {"n_samples": 32768, "restarts": 4}),
    }
    for i, (h, (plugin, params)) in enumerate(configs.items()):
        store.write_config(ConfigRecord(h, plugin, plugin, "0.1.0", "accuracy",
                                        {"representation": plugin, "params": params, "seed": 0}))
        for m in ("a", "b"):
            store.write_cell([Row(metric="l1_log_cos", value=0.1 + 0.01 * i, unit="log(1+1/sr)", higher_is_better=False,
                                  status="ok", message="", config_hash=h, dataset="nbrdf_release",
                                  dataset_fingerprint="fp", material=m, category="plastic", scene="brdf_space",
                                  run_id="r", seed=0, package_version="0.1.0", git_sha="abc", timestamp=1.0)])
    (section,) = build(store.frame()).sections
    by_config = {f.config_hash: f for f in section.sources}
    assert by_config["pub_mirror"].model == "phong" and by_config["pub_half"].model == "blinn_phong_ngan"
    assert [o.config_hash for o in by_config["pub_mirror"].ours] == ["phong"]
    assert [o.config_hash for o in by_config["pub_half"].ours] == ["half"]
