"""The dataset conformance kit proves itself: the built-in synthetic set (small) and a small
correct dataset pass, each deliberately broken dataset is caught by the check that names its
fault, datasets whose data is not here skip cleanly, and the kit runs isolated through
`brdfbench check --kind dataset`."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pytest

from brdfbench.plugins import registry
from brdfbench.data import Dataset
from brdfbench.errors import DataError
from brdfbench.protocols.generator import WeightSet
from brdfbench.merl import SHAPE, MerlTable
from brdfbench.nbrdf.network import n_weights
from brdfbench.protocols.representation import Material
from brdfbench.plugins.specs import DatasetSpec
from brdfbench.testing import check_dataset

ALBEDOS = {"grey": (0.5, 0.5, 0.5), "red": (0.6, 0.1, 0.1), "blue": (0.1, 0.1, 0.6)}


def _material(name: str, scale: float = 1.0, rho=None) -> Material:
    rho = np.reshape(ALBEDOS[name] if rho is None else rho, (3, 1, 1, 1)) * scale
    return Material(name, MerlTable.from_values(np.broadcast_to(rho / np.pi, (3, *SHAPE))), "diffuse", source=f"test:{name}")


def diffuse(scale: float = 1.0) -> Dataset:
    """The smallest correct dataset: Lambertian tables made in memory, with a split and weights."""
    names = tuple(ALBEDOS)

    def weights(asked):
        return WeightSet(tuple(asked), np.zeros((len(asked), n_weights((21, 21))), dtype=np.float32))

    return Dataset("diffuse", names, lambda name: _material(name, scale), f"diffuse-v1-scale{scale}",
                   dict.fromkeys(names, "diffuse"), {"train": names[:2], "test": names[2:]}, weights)


# --------------------------------------------------------------------------- broken datasets


def returns_names(scale: float = 1.0):
    return list(ALBEDOS)


def repeats_a_name(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials + ds.materials[:1], ds.loader, ds.fingerprint, ds.categories)


_calls = itertools.count()


def fingerprint_per_call(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, f"diffuse-{next(_calls)}", ds.categories)


def fingerprint_ignores_scale(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, "diffuse-v1", ds.categories)


def loads_another(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, lambda name: _material("grey", scale), ds.fingerprint, ds.categories)


def nan_table(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, lambda name: _material(name, rho=(0.5, float("nan"), 0.5)), ds.fingerprint)


def wrong_category(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, dict.fromkeys(ds.materials, "metal"))


@dataclass(frozen=True)
class ForgivingDataset(Dataset):
    def load(self, material):
        return self.loader(material if material in self.materials else self.materials[0])


def accepts_unknown_names(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return ForgivingDataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories)


def categorises_a_stranger(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, {**ds.categories, "gold": "metal"})


def overlapping_splits(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories,
                   {"train": ds.materials[:2], "test": ds.materials[1:]})


def sorted_weights(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories, ds.splits,
                   lambda asked: ds.weights(tuple(sorted(asked))))


def types_a_stranger(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories, types={"gold": ("brass",)})


def unknown_type(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories, types={"grey": ("granite",)})


def empty_description(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, ds.loader, ds.fingerprint, ds.categories, descriptions={"red": " "})


def needs_a_folder(path: str) -> Dataset:
    return diffuse()


def data_elsewhere(scale: float = 1.0) -> Dataset:
    raise DataError("/nowhere/merl: no such folder; pass dataset.params.path")


def spec(fn) -> DatasetSpec:
    return DatasetSpec(name=fn.__name__, description="test dataset", target=f"{__name__}:{fn.__name__}")


def test_a_correct_dataset_passes_every_check():
    report = check_dataset(spec(diffuse), full=True)
    assert report.passed and set(report.outcomes.values()) == {"passed"}, report.summary()
    assert set(report.outcomes) == {"builds", "names_unique", "fingerprint_stable", "fingerprint_tracks_params",
                                    "loads_materials", "unknown_name_refused", "categories_consistent",
                                    "types_and_descriptions", "splits_disjoint", "weights_aligned"}
    quick = check_dataset(spec(diffuse))
    assert quick.outcomes["weights_aligned"] == "skipped" and "full=True" in quick.details["weights_aligned"]


@pytest.mark.parametrize("fn, check, words, full", [
    (returns_names, "builds", "returned a list", False),
    (repeats_a_name, "names_unique", "names repeat: ['grey']", False),
    (fingerprint_per_call, "fingerprint_stable", "two calls with the same parameters", False),
    (fingerprint_ignores_scale, "fingerprint_tracks_params", "scale=0.5 changes material 'grey'", False),
    (loads_another, "loads_materials", "load('red') returned material 'grey'", False),
    (nan_table, "loads_materials", "non-finite", False),
    (wrong_category, "loads_materials", "declares 'metal'", False),
    (accepts_unknown_names, "unknown_name_refused", "an unknown name must be refused", False),
    (categorises_a_stranger, "categories_consistent", "['gold']", False),
    (types_a_stranger, "types_and_descriptions", "types name materials the dataset does not have: ['gold']", False),
    (unknown_type, "types_and_descriptions", "outside the MERL vocabulary: ['granite']", False),
    (empty_description, "types_and_descriptions", "material 'red' has description ' '", False),
    (overlapping_splits, "splits_disjoint", "'red' is in split 'train' and in split 'test'", False),
    (sorted_weights, "weights_aligned", "returned vectors of ['grey', 'red']", True),
])
def test_the_kit_catches_a_broken_dataset(fn, check, words, full):
    report = check_dataset(spec(fn), full=full)
    assert report.outcomes[check] == "failed", report.summary()
    detail = report.details[check]
    assert words in detail and f"dataset {fn.__name__!r}, {check}:" in detail, detail
    assert "\n" not in detail, detail
    with pytest.raises(AssertionError, match=check):
        report.raise_on_failure()


@pytest.mark.parametrize("fn, params, words", [(needs_a_folder, None, "needs dataset.params path"),
                                               (data_elsewhere, None, "is not here: /nowhere/merl")])
def test_a_dataset_whose_data_is_not_here_skips_every_check(fn, params, words):
    report = check_dataset(spec(fn), params)
    assert set(report.outcomes.values()) == {"skipped"} and report.passed, report.summary()
    assert all(words in d for d in report.details.values()), report.summary()


def test_an_unknown_parameter_fails_naming_it():
    report = check_dataset(spec(diffuse), {"sise": 2})
    assert report.outcomes["builds"] == "failed" and "dataset.params.sise" in report.details["builds"]


def test_the_builtin_synthetic_set_passes():
    report = check_dataset("synthetic", {"size": 2}).raise_on_failure()
    assert report.outcomes["loads_materials"] == "passed" and report.outcomes["fingerprint_tracks_params"] == "passed"


def test_the_builtin_datasets_pass_or_skip_cleanly_without_their_data():
    """Datasets over files (a MERL folder, the NBRDF release under ../shared) skip, saying why,
    where the files are not given or not here; where they are, they pass."""
    for name in ("merl_folder", "nbrdf_release"):
        report = check_dataset(name).raise_on_failure()
        assert set(report.outcomes.values()) <= {"passed", "skipped"}, report.summary()


LOADED: list[str] = []


def counted(scale: float = 1.0) -> Dataset:
    ds = diffuse(scale)
    return Dataset(ds.name, ds.materials, lambda name: LOADED.append(name) or ds.loader(name), ds.fingerprint,
                   ds.categories)


def test_the_checks_share_one_dataset_and_load_at_most_two_materials():
    from brdfbench.testing.datasets import MAX_LOADS

    LOADED.clear()
    report = check_dataset(spec(counted))
    assert report.passed, report.summary()
    # MAX_LOADS of the dataset, and one of the dataset built with scale=0.5 (fingerprint_tracks_params)
    assert sorted(LOADED) == ["grey", "grey", "red"] and MAX_LOADS == 2


def test_the_kit_runs_isolated_through_the_cli(capsys):
    from brdfbench.cli import main

    s = spec(overlapping_splits)
    registry.register("datasets", s)
    try:
        status = main(["check", s.name, "--kind", "dataset", "--timeout", "120"])
    finally:
        registry.unregister("datasets", s.name)
    out = capsys.readouterr().out
    assert status == 1 and "failed   splits_disjoint" in out and "passed   loads_materials" in out, out
    assert main(["check", "no_such_dataset", "--kind", "dataset"]) == 2
    assert "no_such_dataset" in capsys.readouterr().err


def test_check_param_reaches_the_kit_in_its_worker(capsys):
    """`brdfbench check --param KEY=VALUE`: the value read as YAML, given to the plugin in the
    worker; without it the dataset cannot be built and every check is skipped."""
    from brdfbench.cli import main

    s = spec(needs_a_folder)
    registry.register("datasets", s)
    try:
        assert main(["check", s.name, "--kind", "dataset", "--timeout", "120"]) == 0
        assert "skipped  builds" in capsys.readouterr().out
        assert main(["check", s.name, "--kind", "dataset", "--timeout", "120", "--param", "path=/data/merl"]) == 0
        out = capsys.readouterr().out
        assert "passed   builds" in out and "/data/merl" in out, out
        for bad, says in ((["--param", "path"], "--param 'path' must look like KEY=VALUE"),
                          (["--param", "path=[1,"], "is not a YAML value")):
            assert main(["check", s.name, "--kind", "dataset", *bad]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and says in err[0], err
    finally:
        registry.unregister("datasets", s.name)
    assert main(["check", "l1", "--kind", "metric", "--param", "x=1"]) == 2
    assert "a metric takes no parameters" in capsys.readouterr().err
