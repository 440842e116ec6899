"""The MERL material-type vocabulary (Zhou et al., supplementary C.2) and the descriptions of
conditional synthesis: the rule gives the paper's 48 types from the 100 MERL names; AugMERL
and NeuMERL carry types and descriptions through permutation and interpolation."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from brdfbench.data import Dataset
from brdfbench.data import augmerl as A
from brdfbench.data.material_types import (MERL_TYPES, checked_type, describe, material_type, mixture, type_index,
                                           without_colour)
from brdfbench.data.synthetic import generate_material
from brdfbench.errors import ConfigError
from brdfbench.plugins import registry
from brdfbench.plugins.specs import DatasetSpec
from brdfbench.protocols.representation import Material

SEED_003 = Path(__file__).resolve().parents[3] / "shared" / "seeds" / "003_0f9a0eeb2a8acf57.txt"


def merl_names() -> list[str]:
    """The 100 MERL material names, as BBM's published fit files spell them (shipped package data)."""
    from brdfbench_representations.published import load_source

    names = load_source("bagher_sgd").materials
    assert len(names) == 100
    return sorted(names)


@pytest.mark.skipif(not SEED_003.is_file(), reason="the source papers (../shared/seeds) are absent")
def test_the_vocabulary_is_the_papers_list():
    text = SEED_003.read_text(encoding="utf-8")
    listed = re.search(r"full list of 48 material types[^:]*:\s*(.+)", text).group(1)
    assert tuple(t.strip().rstrip(".") for t in listed.split(",")) == MERL_TYPES


def test_the_100_merl_names_give_exactly_the_48_types():
    found = {name: material_type(name) for name in merl_names()}
    assert all(t is not None for t in found.values()), [n for n, t in found.items() if t is None]
    assert set(found.values()) == set(MERL_TYPES) and len(MERL_TYPES) == 48


@pytest.mark.parametrize("name, expected", [
    ("blue-metallic-paint2", "metallic-paint"), ("gold-metallic-paint3", "metallic-paint"),
    ("specular-black-phenolic", "specular-phenolic"), ("red-specular-plastic", "specular-plastic"),
    ("dark-specular-fabric", "specular-fabric"), ("light-brown-fabric", "fabric"), ("two-layer-gold", "two-layer"),
    ("cherry-235", "wood"), ("ss440", "stainless-steel"), ("white-diffuse-bball", "diffuse-ball"),
    ("yellow-matte-plastic", "plastic"), ("pure-rubber", "rubber"), ("neoprene-rubber", "neoprene-rubber"),
    ("black-soft-plastic", "soft-plastic"), ("color-changing-paint1", "color-changing-paint"),
    ("black-oxidized-steel", "oxidized-steel"), ("Chrome-Steel", "chrome-steel"),
    # outside MERL: no type
    ("synth-plastic-green-00", None), ("acrylic_felt_green_rgb", None), ("glossyredpaper", None), ("", None),
])
def test_the_rule_on_hard_names(name, expected):
    assert material_type(name) == expected


def test_type_labels_and_a_bad_type():
    assert type_index("acrylic") == 0 and type_index("two-layer") == 47
    assert [type_index(t) for t in MERL_TYPES] == list(range(48))
    with pytest.raises(ConfigError, match=r"type='platic' is not a MERL material type; did you mean 'plastic'"):
        checked_type("platic")
    with pytest.raises(ConfigError, match=r"condition.type='zzz' is not a MERL material type \(the 48"):
        checked_type("zzz", key="condition.type")


def test_descriptions_the_papers_way():
    assert describe("blue-metallic-paint2") == "blue metallic paint"
    assert describe("ss440") == "stainless steel" and describe("white-diffuse-bball") == "white diffuse ball"
    assert without_colour("red metallic paint") == "metallic paint"  # Zhou et al.'s own example
    assert without_colour("dark blue paint") == "paint" and without_colour("nylon") == "nylon"
    assert mixture("metallic paint", "nylon") == "a mixture of metallic paint and nylon"


# --------------------------------------------------------------------------- through the datasets

MERL_NAMED = ("blue-metallic-paint", "ss440", "red-fabric2")


def merl_named(**_):
    """Three synthetic tables under MERL names (a stand-in for a MERL folder)."""
    tables = {name: generate_material(i, seed=0)[2] for i, name in enumerate(MERL_NAMED)}
    return Dataset("merl_named", MERL_NAMED, lambda n: Material(n, tables[n], "merl", f"test:{n}"), "merl-named-v1",
                   {n: "merl" for n in MERL_NAMED})


@pytest.fixture
def merl_named_base():
    registry.register("datasets", DatasetSpec(name="merl_named", description="test", target=f"{__name__}:merl_named"))
    yield
    registry.unregister("datasets", "merl_named")


def test_a_dataset_without_declared_types_reads_them_from_the_names():
    ds = merl_named()
    assert [ds.material_types(n) for n in ds.materials] == [("metallic-paint",), ("stainless-steel",), ("fabric",)]
    assert ds.description("red-fabric2") == "red fabric"
    kept = ds.subset(["ss440"])
    assert kept.material_types("ss440") == ("stainless-steel",) and kept.description("ss440") == "stainless steel"


def test_augmerl_keeps_types_through_permutation_and_gives_a_mix_both(merl_named_base, tmp_path):
    ds = A.augmerl_dataset(base="merl_named", size=22, seed=3, cache_dir=tmp_path)
    recipes = {r.name: r for r in (*A.permuted_list(A.load_base("merl_named", None, tmp_path)),)}
    for name in ds.materials:
        if name in recipes:
            base = recipes[name].base
            assert ds.material_types(name) == (material_type(base),)
            expected = describe(base) if recipes[name].permutation == "rgb" else without_colour(describe(base))
            assert ds.description(name) == expected
    mixes = [n for n in ds.materials if n.startswith("mix-")]
    assert len(mixes) == 22 - 18
    for name in mixes:
        types = ds.material_types(name)
        assert 1 <= len(types) <= 2 and set(types) <= set(MERL_TYPES)
        assert ds.description(name).startswith("a mixture of ") and " and " in ds.description(name)
    assert ds.description("blue-metallic-paint~gbr") == "metallic paint"
    assert ds.description("blue-metallic-paint~rgb") == "blue metallic paint"
    assert np.all([ds.subset([m]).material_types(m) == ds.material_types(m) for m in mixes])
