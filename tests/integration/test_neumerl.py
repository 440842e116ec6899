"""NeuMERL: aligned weight vectors, the per-material cache (resume, damage), progress, fingerprints."""

from __future__ import annotations

import json
import logging
from itertools import combinations

import numpy as np
import pytest

from brdfbench.plugins import registry
from brdfbench.data import neumerl as N
from brdfbench.data.augmerl import augmerl_dataset
from brdfbench.errors import ConfigError
from brdfbench.protocols.generator import WeightSet
from brdfbench.nbrdf.layouts import flatten

#: A short recipe: the tests check bookkeeping and alignment, not fit quality.
RECIPE = dict(epochs=2, n_samples=10_000, batch_size=1024, lr=1e-2, batch_materials=2)


@pytest.fixture(scope="module")
def base_params(synthetic_cache):
    return {"size": "small", "cache_dir": str(synthetic_cache)}


def make(base_params, cache, **changes):
    params = dict(base_params=base_params, size=8, test_fraction=0.25, seed=0, cache_dir=str(cache), **RECIPE)
    return N.neumerl_dataset(**{**params, **changes})


@pytest.fixture(scope="module")
def one_shot(base_params, tmp_path_factory):
    """Every material's vector, fitted in one call into a fresh cache."""
    cache = tmp_path_factory.mktemp("neumerl-one-shot")
    ds = make(base_params, cache)
    return ds, ds.weights(ds.materials), cache


def test_tables_and_splits_are_augmerls(base_params, tmp_path, one_shot):
    ds, _, _ = one_shot
    aug = augmerl_dataset(base_params=base_params, size=8, test_fraction=0.25, seed=0, cache_dir=str(tmp_path))
    assert ds.materials == aug.materials and dict(ds.splits) == dict(aug.splits)
    assert ds.categories == aug.categories and ds.fingerprint != aug.fingerprint


def test_weights_shape_and_alignment(base_params, one_shot):
    ds, ws, _ = one_shot
    assert isinstance(ws, WeightSet) and ws.names == ds.materials
    assert ws.vectors.shape == (8, 675) and ws.vectors.dtype == np.float32 and ws.hidden == (21, 21)
    # The anchor is fitted from its own random initialisation: the plain nbrdf fit with init=random.
    anchor = ds.splits["train"][0]
    fitter = registry.get("representations", "nbrdf").create(**RECIPE, patience=None, init="random")
    some = [anchor, *[m for m in ds.materials if m != anchor][:3]]
    independent = fitter.fit_many([ds.load(m) for m in some], seed=0)
    free = np.stack([flatten(m.weights) for m in independent])
    aligned = np.stack([ws.vectors[ws.names.index(m)] for m in some])
    np.testing.assert_array_equal(aligned[0], free[0])

    def spread(v):
        return np.mean([np.linalg.norm(v[i] - v[j]) for i, j in combinations(range(len(v)), 2)])

    assert spread(aligned) < 0.5 * spread(free)


def test_weights_of_a_subset_and_repeats(one_shot):
    ds, ws, _ = one_shot
    names = (ds.splits["test"][0], ds.splits["train"][1], ds.splits["test"][0])
    sub = ds.weights(names)
    assert sub.names == names
    for i, n in enumerate(names):
        np.testing.assert_array_equal(sub.vectors[i], ws.vectors[ws.names.index(n)])


def test_resume_equals_one_shot(base_params, tmp_path, one_shot, monkeypatch):
    _, expected, _ = one_shot
    ds = make(base_params, tmp_path)
    written = []
    real_write = N.NeumerlWeights.write

    def interrupted(self, name, *args, **kwargs):
        if len(written) == 2:  # the anchor and one material: stop in the middle of a batch
            raise KeyboardInterrupt
        written.append(name)
        return real_write(self, name, *args, **kwargs)

    monkeypatch.setattr(N.NeumerlWeights, "write", interrupted)
    with pytest.raises(KeyboardInterrupt):
        ds.weights(ds.materials)
    monkeypatch.setattr(N.NeumerlWeights, "write", real_write)
    refits = []
    monkeypatch.setattr(N.NeumerlWeights, "_fit", lambda self, names, init: _record(refits, self, names, init))
    resumed = make(base_params, tmp_path).weights(ds.materials)
    assert set(refits) == set(ds.materials) - set(written)
    # the resumed batch is smaller: the fitter's shared first-layer product over the stack rounds
    # differently with its size (to fp32 rounding, as tests/integration/test_nbrdf.py's batching checks)
    np.testing.assert_allclose(resumed.vectors, expected.vectors, rtol=1e-4, atol=1e-5)


_REAL_FIT = N.NeumerlWeights._fit


def _record(log, self, names, init):
    log.extend(names)
    return _REAL_FIT(self, names, init)


def test_damaged_cache_files_are_refitted(base_params, tmp_path, one_shot, caplog):
    ds, expected, cache = one_shot
    weights = ds.weights
    names = [m for m in ds.materials if m != ds.splits["train"][0]]
    npy0, _ = weights.paths(names[0])
    npy0.write_bytes(b"not a numpy file")  # corrupt
    npy1, record1 = weights.paths(names[1])
    other, _ = weights.paths(names[2])
    npy1.write_bytes(other.read_bytes())  # another material's vector in its place
    _, record3 = weights.paths(names[3])
    doc = json.loads(record3.read_text())
    doc["anchor_sha256"] = "0" * 64  # fitted from another anchor
    record3.write_text(json.dumps(doc))
    with caplog.at_level(logging.WARNING):
        again = make(base_params, cache).weights(ds.materials)
    for name in names[:2] + [names[3]]:
        assert f"neumerl: {name}: unusable cached weights" in caplog.text
    np.testing.assert_array_equal(again.vectors, expected.vectors)


def test_progress_lines(base_params, tmp_path, capsys):
    ds = make(base_params, tmp_path)
    ds.weights(ds.splits["train"][:3])
    err = capsys.readouterr().err
    assert "neumerl: fitting the anchor" in err
    total = 3
    assert f"neumerl: {total}/{total} materials fitted (" in err and "per minute)" in err


def test_fit_info_records_losses(one_shot):
    ds, _, _ = one_shot
    info = N.neumerl_fit_info(ds)
    assert set(info) == set(ds.materials)
    anchor = ds.splits["train"][0]
    assert info[anchor]["anchor_sha256"] == N.RANDOM_INIT
    assert all(0 < doc["fit_loss"] < 10 for doc in info.values())


def test_fingerprint_and_cache_key_include_the_recipe(base_params, tmp_path, one_shot):
    ds, _, _ = one_shot
    changes = [dict(epochs=3), dict(n_samples=30_000), dict(batch_size=512), dict(lr=2e-2), dict(hidden=[16, 16]),
               dict(fit_seed=1), dict(seed=1), dict(size=9)]
    seen = {ds.fingerprint}
    keys = {ds.weights.key}
    for change in changes:
        other = make(base_params, tmp_path, **change)
        seen.add(other.fingerprint)
        keys.add(other.weights.key)
    assert len(seen) == len(changes) + 1 and len(keys) == len(changes) + 1
    # results do not depend on batch-mates: batch_materials is not part of the content
    assert make(base_params, tmp_path, batch_materials=5).fingerprint == ds.fingerprint


@pytest.mark.parametrize("change, key", [
    (dict(epochs=0), "dataset.params.epochs"),
    (dict(n_samples=-5), "dataset.params.n_samples"),
    (dict(batch_size=1.5), "dataset.params.batch_size"),
    (dict(lr=0), "dataset.params.lr"),
    (dict(hidden=[]), "dataset.params.hidden"),
    (dict(hidden="21,21"), "dataset.params.hidden"),
    (dict(batch_materials=0), "dataset.params.batch_materials"),
    (dict(fit_seed=-1), "dataset.params.fit_seed"),
    (dict(size=1), "dataset.params.size"),
])
def test_bad_params_are_named(base_params, tmp_path, change, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        make(base_params, tmp_path, **change)


def test_unknown_material(one_shot):
    ds, _, _ = one_shot
    with pytest.raises(Exception, match="no-such"):
        ds.weights(("no-such",))
