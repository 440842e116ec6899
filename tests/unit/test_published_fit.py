"""`published_fit`: every published fit of every shipped file evaluates (or fails by name),
bad sources and lines are one line, models save and load, and each source's parameters
describe their own material (checked against the published NBRDF networks where present)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from brdfbench import merl, modelio
from brdfbench.errors import ConfigError
from brdfbench.protocols.representation import Material
from brdfbench.testing import adversarial_pairs
from brdfbench.testing.kit import reference_material
from brdfbench_representations.published import (NOT_IMPLEMENTED, NoPublishedFit, PublishedFit, load_source, published_forms,
                                                 shipped_sources, source_model)

NBRDF_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "neural-brdf" / "merl"


def named(name: str) -> Material:
    """The kit's synthetic table under a MERL material's name (the lookup reads only the name)."""
    ref = reference_material()
    return Material(name, ref.table, ref.category)


def _pairs(n: int, seed: int, dtype=torch.float64):
    """The kit's adversarial pairs (every family and hard case) in one batch."""
    fam = adversarial_pairs(n, dtype=dtype, seed=seed).values()
    return torch.cat([w for w, _ in fam]), torch.cat([w for _, w in fam])


def test_every_published_fit_evaluates_or_fails_by_name():
    wi, wo = _pairs(1024, seed=5)
    for source in shipped_sources():
        fits = load_source(source)
        for material in fits.materials:
            model = PublishedFit(source=source)
            entry = fits.fits[material]
            model.fit(named(material))
            assert model.fit_info["published_model"] == entry.model and model.fit_info["line"] == entry.line
            for dtype in (torch.float32, torch.float64):
                out = model.eval(wi.to(dtype), wo.to(dtype))
                assert out.dtype == dtype and bool(torch.isfinite(out).all()) and bool((out >= 0).all()), (source, material)


def test_every_shipped_source_names_its_model():
    models = {s: source_model(s) for s in shipped_sources()}
    assert not NOT_IMPLEMENTED and models.pop("ngan_he") == "he"  # He et al. 1991 (he_model.py)
    registered = {c.NAME for c in published_forms().values()}
    assert set(models.values()) <= registered and len(set(models.values())) == 11


def test_sources_and_materials_that_do_not_exist_are_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"unknown source 'ngan_wrd'; did you mean 'ngan_ward'\?"):
        PublishedFit(source="ngan_wrd")
    with pytest.raises(ConfigError, match=r"source '.*nope\.fit': no such \.fit file"):
        PublishedFit(source=str(tmp_path / "nope.fit"))
    with pytest.raises(NoPublishedFit, match=r"no published fit of 'synth-plastic-green-00' in bagher_sgd \(100 materials\)"):
        PublishedFit().fit(named("synth-plastic-green-00"))
    with pytest.raises(NoPublishedFit, match=r"no published fit of 'alum-bronz' in ngan_ward \(86 materials\); did you mean 'alum-bronze'\?"):
        PublishedFit(source="NGAN_WARD").fit(named("alum-bronz"))
    with pytest.raises(ConfigError, match="material must be a MERL material name or null"):
        PublishedFit(material=3)


def test_a_users_file_with_bad_lines_fails_only_those_materials(tmp_path):
    path = tmp_path / "mine.fit"
    path.write_text(
        "# my fits\n"
        "alum-bronze = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), NganWard(albedo = [0.05, 0.05, 0.05], roughness = 0.1))\n"
        "chrome = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), NganWard(albedo = [0.05, 0.05, 0.05], roughness = -0.1))\n"
        "nickel = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), Mystery(albedo = [0.05, 0.05, 0.05]))\n"
        "teflon = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), NganWard(albedo = [0.05, 0.05, 0.05], roughness = 0.1)\n",
        encoding="utf-8",
    )
    assert PublishedFit(source=str(path)).fit(named("alum-bronze")).model.NAME == "ward"
    with pytest.raises(NoPublishedFit, match=r"mine\.fit:3: chrome: .*roughness"):
        PublishedFit(source=str(path)).fit(named("chrome"))
    with pytest.raises(NoPublishedFit, match=r"mine\.fit:4: nickel: no brdfbench model evaluates 'Mystery' fits"):
        PublishedFit(source=str(path)).fit(named("nickel"))
    with pytest.raises(NoPublishedFit, match=r"mine\.fit:5: teflon: line ends"):
        PublishedFit(source=str(path)).fit(named("teflon"))


def test_material_param_fixes_the_fit_for_every_target():
    model = PublishedFit(source="low_lowsmooth_e2", material="chrome").fit(named("something-else"))
    assert model.fit_info["published_material"] == "chrome"


def test_save_and_load_give_the_same_values(tmp_path):
    model = PublishedFit(source="bagher_sgd").fit(named("gold-paint"))
    path = tmp_path / "m.safetensors"
    modelio.save(model, "published_fit", path)
    name, back = modelio.load(path)
    assert name == "published_fit"
    wi, wo = _pairs(2048, seed=2)
    assert torch.equal(back.eval(wi, wo), model.eval(wi, wo))
    assert back.fit_info == model.fit_info


def _l1_log_cos(model, table, cells, wi, wo) -> float:
    ref = torch.from_numpy(table.values.reshape(3, -1)).T[cells]
    f = model.eval(wi[cells], wo[cells])
    c = wi[cells, 2:3]
    return float((torch.log1p(f * c) - torch.log1p(ref * c)).abs().mean())


@pytest.mark.skipif(not NBRDF_DIR.is_dir(), reason="the published NBRDF networks (../shared/data/neural-brdf) are absent")
def test_each_source_describes_its_own_material_best():
    """The published parameters of a material describe its own table better than the others',
    for every source: parameters read in the wrong convention (a π misplaced, a roughness
    squared) would not single out their own materials."""
    from brdfbench.data.nbrdf_release import nbrdf_release_dataset

    ds = nbrdf_release_dataset(path=str(NBRDF_DIR.parent))
    names = ["alum-bronze", "blue-acrylic", "gold-metallic-paint", "red-plastic", "white-diffuse-bball"]
    tables = {n: ds.load(n).table for n in names}
    wi, wo = merl.grid_directions(torch.float64)
    valid = tables[names[0]].valid.reshape(-1) & (wi[:, 2] > 0).numpy() & (wo[:, 2] > 0).numpy()
    cells = torch.from_numpy(np.random.default_rng(0).choice(np.flatnonzero(valid), 2**13, replace=False))
    for source in shipped_sources():
        if source_model(source) is None:
            continue
        own, others, best = [], [], 0
        for a in names:
            model = PublishedFit(source=source).fit(named(a))
            own.append(_l1_log_cos(model, tables[a], cells, wi, wo))
            rest = [_l1_log_cos(model, tables[b], cells, wi, wo) for b in names if b != a]
            others += rest
            best += own[-1] < min(rest)
        # a network is not the measurement a fit was made against: one material of five may
        # sit closer to another's network (Bagher's white-diffuse-bball is nearer red-plastic's)
        # Every one of Ngan et al.'s fits misses alum-bronze and blue-acrylic here (l1_log_cos
        # 0.2-0.3 against the networks: their fits weighted the measurement differently, and
        # a half-vector reading of their "Blinn-Phong" scores the same): 2 or 3 of 5 singled out,
        # own error under 0.8 of the others'; Löw et al.'s and Bagher et al.'s: 4 of 5, under half
        ngan = source.startswith("ngan_")
        assert best >= (2 if ngan else len(names) - 1), (source, own)
        assert np.mean(own) < (0.8 if ngan else 0.5) * np.mean(others), (source, np.mean(own), np.mean(others))
