"""Hu 2026 Table 4.5's ablation, hyperdiffusion trained without augmentation:
`harness.augmented=false` trains on the training split's unpermuted, unmixed base materials
and scores on the same test split; configurations stored before the key keep their hash; the
report puts the paper's ablation column beside such a configuration."""

from __future__ import annotations

import pytest

from brdfbench.data import augmerl as A
from brdfbench.data.synthetic import synthetic_dataset
from brdfbench.errors import ConfigError
from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row
from brdfbench_generators.harness import GenerationConfig, GenerationHarness
from brdfbench_leaderboard import view


def test_the_default_leaves_the_hash_as_it_was():
    assert "augmented" not in GenerationConfig().hashed()
    assert GenerationConfig(augmented=False).hashed()["augmented"] is False


def test_without_augmentation_the_training_split_keeps_its_base_materials_only(tmp_path):
    ds = A.augmerl_dataset(base="synthetic", base_params={"size": "small"}, size=60, seed=1, cache_dir=tmp_path)
    train, test = GenerationHarness.split(GenerationConfig(), ds, 0)
    few, same_test = GenerationHarness.split(GenerationConfig(augmented=False), ds, 0)
    assert same_test == test and set(few) < set(train)
    recipes = {r.name: r for r in A.permuted_list(A.load_base("synthetic", {"size": "small"}, tmp_path))}
    assert few and all(recipes[n].permutation == "rgb" for n in few)
    assert set(few) == {n for n in train if n.endswith("~rgb")}


def test_without_augmentation_needs_augmerl_or_neumerl():
    with pytest.raises(ConfigError, match=r"harness.augmented=false trains on AugMERL's unaugmented base materials; "
                                          r"dataset 'synthetic' is not AugMERL or NeuMERL"):
        GenerationHarness.split(GenerationConfig(augmented=False), synthetic_dataset(size="small"), 0)


def test_the_report_puts_the_papers_ablation_column_beside_it(tmp_path):
    store = ResultsStore(tmp_path / "brdfbench.sqlite")
    for h, augmented in (("h_aug", True), ("h_plain", False)):
        harness = {"kind": "generation"} if augmented else {"kind": "generation", "augmented": False}
        store.write_config(ConfigRecord(h, "hyperdiffusion", "hyperdiffusion", "0.1.0", "generation",
                                        {"generator": "hyperdiffusion", "harness": harness}))
        store.write_cell([Row(run_id="r", config_hash=h, dataset="neumerl", dataset_fingerprint="fp",
                              material="draw-0", category="set", metric="mmd", value=0.004, unit="1/sr",
                              higher_is_better=False, status="ok", message="", seed=0, package_version="0.1.0",
                              git_sha="abc", timestamp=1.0, scope="set", distance="l1")])
    (section,) = view.build(store.frame(), "test").sections
    labels = {c.config_hash: c.label for c in section.columns}
    assert labels["h_plain"].endswith("(without augmentation)") and "without" not in labels["h_aug"]
    mmd = next(r for r in section.rows if r.metric == "mmd")
    assert mmd.published == {"h_aug": 4.02, "h_plain": 4.3}  # Hu 2026, Table 4.5: NeuMaDiff, and without augmentation


def test_a_run_without_augmentation_trains_on_the_base_materials_and_is_labelled(tmp_path, cli):
    res = tmp_path / "res"
    out = cli("harness=generation", "generator=pca_brdf", "dataset=augmerl", "dataset.params.base_params.size=small",
              "dataset.params.size=30", "dataset.params.test_fraction=0.2", f"dataset.params.cache_dir={tmp_path}",
              "harness.augmented=false", "harness.distances=[l1]", "harness.metrics=[mmd,cov]", "harness.draws=1",
              "harness.categories=false", "progress=lines", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    ds = A.augmerl_dataset(base="synthetic", base_params={"size": "small"}, size=30, test_fraction=0.2,
                           cache_dir=tmp_path)
    few, _ = GenerationHarness.split(GenerationConfig(augmented=False), ds, 0)
    assert f"training pca_brdf on {len(few)} materials" in out.stdout + out.stderr  # progress lines: stderr
    assert "`pca_brdf (without augmentation)`" in (res / "leaderboard.md").read_text()
