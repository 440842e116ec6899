"""AugMERL: names, splits, permutations, the pooled reference, the kernel-form PCA, the cache."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import torch

from brdfbench import logrel
from brdfbench.protocols import generator as generator_protocol
from brdfbench.data import augmerl as A
from brdfbench.data import _augmerl_pca as K
from brdfbench.errors import ConfigError
from brdfbench.merl import CHANNEL_SCALES, INVALID_RAW, SHAPE, MerlTable


@pytest.fixture(scope="module")
def base_params(synthetic_cache):
    return {"size": "small", "cache_dir": str(synthetic_cache)}


@pytest.fixture(scope="module")
def aug_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("augmerl-cache")


@pytest.fixture(scope="module")
def aug(base_params, aug_cache):
    """6 base materials → 36 permuted + 4 mixes; the PCA is built once for the module."""
    return A.augmerl_dataset(base_params=base_params, size=40, test_fraction=0.1, seed=3, cache_dir=str(aug_cache))


def make(base_params, tmp_path, **params):
    return A.augmerl_dataset(base_params=base_params, cache_dir=str(tmp_path), **params)


# --------------------------------------------------------------------------- names, sizes, splits


def test_names_sizes_and_split(aug):
    assert len(aug) == 40 and len(set(aug.materials)) == 40
    permuted = [m for m in aug.materials if "~" in m]
    mixes = [m for m in aug.materials if m.startswith("mix-")]
    assert len(permuted) == 36 and mixes == ["mix-0000", "mix-0001", "mix-0002", "mix-0003"]
    assert {m.rsplit("~", 1)[1] for m in permuted} == set(A.PERMUTATION_NAMES)
    train, test = aug.splits["train"], aug.splits["test"]
    assert set(train) | set(test) == set(aug.materials) and not set(train) & set(test)
    assert len(test) == 4
    assert all(aug.category(m) == "mixture" for m in mixes)
    assert aug.category("synth-metal-chrome-01~gbr") == "metal"


def test_small_size_is_a_seeded_subset_without_mixes(base_params, tmp_path):
    d = make(base_params, tmp_path, size=10, seed=1)
    assert len(d) == 10 and all("~" in m for m in d.materials)
    full = [p.name for p in A.permuted_list(A.load_base("synthetic", base_params))]
    assert [m for m in full if m in d.materials] == list(d.materials)  # listing order kept


def test_deterministic_from_the_seed(base_params, tmp_path, aug):
    again = make(base_params, tmp_path, size=40, test_fraction=0.1, seed=3)
    assert again.materials == aug.materials and dict(again.splits) == dict(aug.splits)
    assert again.fingerprint == aug.fingerprint
    assert [A.augmerl_recipe(again, m) for m in again.materials] == [A.augmerl_recipe(aug, m) for m in aug.materials]
    other = make(base_params, tmp_path, size=40, test_fraction=0.1, seed=4)
    assert other.splits["test"] != aug.splits["test"]
    assert A.augmerl_recipe(other, "mix-0000") != A.augmerl_recipe(aug, "mix-0000")
    a, b = make(base_params, tmp_path, size=12, seed=5), make(base_params, tmp_path, size=12, seed=5)
    assert a.materials == b.materials


def test_a_larger_size_keeps_the_smaller_ones_mixes(base_params, tmp_path, aug):
    bigger = make(base_params, tmp_path, size=45, test_fraction=0.1, seed=3)
    for m in aug.materials:
        assert A.augmerl_recipe(bigger, m) == A.augmerl_recipe(aug, m)


def test_mix_recipes(aug):
    for j in range(4):
        r = A.augmerl_recipe(aug, f"mix-{j:04d}")
        assert isinstance(r, A.Mix) and r.a != r.b and 0 <= r.t < 1
        assert all(p in aug.materials for p in r.parents)
    r = A.augmerl_recipe(aug, "synth-metal-chrome-01~brg")
    assert (r.base, r.permutation) == ("synth-metal-chrome-01", "brg")


# --------------------------------------------------------------------------- permutations


def test_permuted_values_scales_and_validity(aug, small_dataset):
    base = small_dataset.load("synth-metallic-paint-blue-02").table
    assert aug.load("synth-metallic-paint-blue-02~rgb").table is not None
    assert np.array_equal(aug.load("synth-metallic-paint-blue-02~rgb").table.raw, base.raw)
    for name, perm in zip(A.PERMUTATION_NAMES, A.PERMUTATIONS):
        t = aug.load(f"synth-metallic-paint-blue-02~{name}").table
        assert np.array_equal(t.valid, base.valid)
        v = base.valid
        for c in range(3):
            np.testing.assert_allclose(t.values[c][v], base.values[perm[c]][v], rtol=1e-14)
            # stored with the destination channel's scale: raw = value / scale[c]
            np.testing.assert_allclose(t.raw[c][v], base.values[perm[c]][v] / CHANNEL_SCALES[c], rtol=1e-14)
            assert (t.raw[c][~v] == INVALID_RAW).all()


def test_permute_table_partial_invalid_cell():
    values = np.full((3, *SHAPE), 0.5)
    values[0, 1, 2, 3] = -1.0  # invalid in red only: the cell is invalid
    table = MerlTable(values / np.asarray(CHANNEL_SCALES).reshape(3, 1, 1, 1))
    out = A.permute_table(table, "gbr")
    assert not out.valid[1, 2, 3] and out.valid.sum() == table.valid.sum()
    assert (out.raw[:, 1, 2, 3] == INVALID_RAW).all()
    assert A.permute_table(table, "rgb") is table
    with pytest.raises(ValueError, match="rgx"):
        A.permute_table(table, "rgx")


# --------------------------------------------------------------------------- the pooled reference


def _random_base(n: int, p: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    values = torch.exp(torch.randn(3 * n, p, generator=g) * 2).float()
    valid = torch.rand(n, p, generator=g) > 0.2
    valid[:, 0] = False  # a cell nobody measured
    return values, valid


@pytest.mark.parametrize("n", [3, 4])
def test_pooled_median_is_the_per_channel_median_of_the_permuted_set(n):
    values, valid = _random_base(n, 500, seed=n)
    rows = K.source_rows(n)  # (6n, 3)
    explicit = values[rows.reshape(-1)].reshape(6 * n, 3, -1).clone()  # every permuted material, channel-major
    obs_valid = valid.repeat_interleave(6, dim=0)  # a permuted material is valid where its base is
    explicit[~obs_valid[:, None, :].expand_as(explicit)] = float("nan")
    per_channel = torch.nan_to_num(torch.nanmedian(explicit, dim=0).values, nan=0.0).clamp_min(0.0)
    pooled = K.pooled_reference(values, valid)
    for c in range(3):
        assert torch.equal(per_channel[c], pooled)
    assert pooled[0] == 0


def test_pooled_mean_is_the_mean_of_the_permuted_observations():
    n, p = 3, 200
    values, _ = _random_base(n, p)
    rows = K.source_rows(n)
    explicit = values[rows.reshape(-1)].reshape(6 * n, 3 * p).double()
    mean = K.pooled_mean(values)
    torch.testing.assert_close(explicit.mean(dim=0).float(), mean.repeat(3), rtol=1e-6, atol=1e-6)


# --------------------------------------------------------------------------- kernel form vs explicit PCA


def _explicit_pca(centred_base: torch.Tensor, mean: torch.Tensor, k: int):
    """A plain PCA over the explicit 6n × 3P observations: (mean, basis (3P, k))."""
    n = centred_base.shape[0] // 3
    rows = K.source_rows(n)
    obs = (centred_base + mean)[rows.reshape(-1)].reshape(6 * n, -1).double()
    mu = obs.mean(dim=0)
    _, _, vh = torch.linalg.svd(obs - mu, full_matrices=False)
    return obs, mu, vh[:k].T


@pytest.mark.parametrize("k", [5, 6, 9, 100])
def test_kernel_form_interpolation_equals_explicit_basis_pca(k):
    n, p = 4, 300
    values, valid = _random_base(n, p, seed=7)
    w = torch.rand(p, dtype=torch.float64) * 0.9 + 0.1
    reference = K.pooled_reference(values, valid)
    channels = K.map_channels_(values.clone(), valid, reference, w)
    mean = K.pooled_mean(channels)
    K.centre_(channels, mean)
    gram = K.permuted_gram(K.base_gram(channels))
    comp = K.components(gram, k)
    assert comp.rank == 5 * n - 1  # 1 + 4 per base material (S3's orbit), less the mean
    assert comp.k <= min(k, comp.rank)
    eig = logrel.top_eigen(gram, gram.shape[0])[0]
    assert eig[comp.k - 1] - eig[comp.k] > K.DEGENERATE_TOL * eig[0]  # no degenerate pair split
    obs, mu, basis = _explicit_pca(channels, mean, comp.k)
    torch.testing.assert_close(mu.float(), mean.repeat(3), rtol=1e-5, atol=1e-5)
    coeffs = (obs - mu) @ basis  # (6n, k)
    for a, b, t in [(0, 5, 0.3), (7, 2, 0.9), (11, 23, 0.5)]:
        explicit = mu + ((1 - t) * coeffs[a] + t * coeffs[b]) @ basis.T
        beta = K.channel_weights(K.mix_weights(comp, a, b, t))
        kernel = K.reconstruct(beta, channels, mean).reshape(-1)
        torch.testing.assert_close(kernel, explicit, rtol=1e-6, atol=1e-5)
        # the same through explicit coefficients in kernel form
        mixed = (1 - t) * K.coefficients(comp)[a] + t * K.coefficients(comp)[b]
        torch.testing.assert_close(K.point_weights(comp, mixed), K.mix_weights(comp, a, b, t))


def test_a_requested_k_that_splits_a_pair_is_lowered():
    n, p = 4, 300
    values, valid = _random_base(n, p, seed=7)
    ones = torch.ones(p, dtype=torch.float64)
    channels = K.map_channels_(values.clone(), valid, K.pooled_reference(values, valid), ones)
    K.centre_(channels, K.pooled_mean(channels))
    gram = K.permuted_gram(K.base_gram(channels))
    eig = logrel.top_eigen(gram, gram.shape[0])[0]
    pairs = [i for i in range(1, 19) if eig[i - 1] - eig[i] <= K.DEGENERATE_TOL * eig[0]]
    assert pairs, "S3 symmetry makes degenerate pairs"
    split = pairs[0]  # keeping `split` components would keep one of a pair
    assert K.components(gram, split).k == split - 1


@pytest.mark.parametrize("t", [0.0, 1.0])
def test_t_0_and_1_reproduce_the_parents_pca_reconstructions(t):
    n, p = 4, 300
    values, valid = _random_base(n, p, seed=11)
    ones = torch.ones(p, dtype=torch.float64)
    channels = K.map_channels_(values.clone(), valid, K.pooled_reference(values, valid), ones)
    mean = K.pooled_mean(channels)
    K.centre_(channels, mean)
    comp = K.components(K.permuted_gram(K.base_gram(channels)), 7)
    obs, mu, basis = _explicit_pca(channels, mean, comp.k)
    a, b = 3, 17
    parent = b if t == 1.0 else a
    reconstruction = mu + ((obs[parent] - mu) @ basis) @ basis.T
    mixed = K.reconstruct(K.channel_weights(K.mix_weights(comp, a, b, t)), channels, mean).reshape(-1)
    torch.testing.assert_close(mixed, reconstruction, rtol=1e-6, atol=1e-5)


def test_mix_at_t0_is_its_parent_when_k_is_the_rank(aug):
    """At k = rank every permuted material is its own reconstruction: a mix with t = 0 is
    parent a's table, on the cells both parents' base materials measured."""
    loader = aug.loader
    state = A.augmerl_pca(aug)
    assert state.comp.k == state.comp.rank == 5 * 6 - 1
    recipe = A.augmerl_recipe(aug, "mix-0001")
    for t, parent in ((0.0, recipe.a), (1.0, recipe.b)):
        table = loader.mix_table(A.Mix("probe", recipe.a, recipe.b, t))
        target = aug.load(parent.name).table
        both = table.valid
        assert both.sum() > 0.99 * logrel.domain()[0].numel()
        np.testing.assert_allclose(table.values[:, both], target.values[:, both], rtol=2e-4, atol=1e-6)


# --------------------------------------------------------------------------- mixes


def test_mix_tables_validity_and_determinism(aug):
    recipe = A.augmerl_recipe(aug, "mix-0002")
    mix = aug.load("mix-0002")
    assert mix.category == "mixture" and recipe.a.name in mix.source
    va = aug.load(recipe.a.name).table.valid
    vb = aug.load(recipe.b.name).table.valid
    above = torch.zeros(np.prod(SHAPE), dtype=torch.bool)
    above[logrel.domain()[0]] = True
    assert np.array_equal(mix.table.valid, va & vb & above.numpy().reshape(SHAPE))
    assert (mix.table.values[:, mix.table.valid] >= 0).all()
    assert np.array_equal(aug.load("mix-0002").table.raw, mix.table.raw)


def test_pca_cache_is_read_back_and_a_damaged_one_rebuilt(aug, caplog):
    state = A.augmerl_pca(aug)
    path = aug.loader.pca_path
    assert path.is_file() and path.suffix == ".safetensors"
    A._STATES.clear()
    again = A.augmerl_pca(aug)
    assert torch.equal(again.channels, state.channels) and torch.equal(again.comp.eigvecs, state.comp.eigvecs)
    assert torch.equal(again.valid, state.valid)
    path.write_bytes(path.read_bytes()[:1000])
    A._STATES.clear()
    with caplog.at_level(logging.WARNING):
        rebuilt = A.augmerl_pca(aug)
    assert "unusable AugMERL PCA cache" in caplog.text
    assert torch.equal(rebuilt.channels, state.channels)
    assert path.stat().st_size > 1000


# --------------------------------------------------------------------------- fingerprints and errors


def test_fingerprint_changes_with_every_param(base_params, tmp_path):
    ref = dict(size=40, test_fraction=0.1, seed=0, k=300)
    fp = make(base_params, tmp_path, **ref).fingerprint
    changes = [dict(size=41), dict(test_fraction=0.2), dict(seed=1), dict(k=10)]
    prints = {make(base_params, tmp_path, **{**ref, **c}).fingerprint for c in changes}
    prints.add(A.augmerl_dataset(base_params={**base_params, "size": 5}, cache_dir=str(tmp_path), **ref).fingerprint)
    prints.add(A.augmerl_dataset(base_params={**base_params, "seed": 1}, cache_dir=str(tmp_path), **ref).fingerprint)
    assert fp not in prints and len(prints) == len(changes) + 2
    # where the cache lives is not content
    assert make(base_params, tmp_path / "elsewhere", **ref).fingerprint == fp


@pytest.mark.parametrize("params, key", [
    (dict(size=0), "dataset.params.size"),
    (dict(size="240"), "dataset.params.size"),
    (dict(size=True), "dataset.params.size"),
    (dict(test_fraction=0.0), "dataset.params.test_fraction"),
    (dict(test_fraction=1.5), "dataset.params.test_fraction"),
    (dict(seed=-1), "dataset.params.seed"),
    (dict(k=0), "dataset.params.k"),
    (dict(base="no-such-dataset"), "dataset.params.base"),
    (dict(base="augmerl"), "dataset.params.base"),
    (dict(base=3), "dataset.params.base"),
    (dict(base_params={"colour": 1}), "dataset.params.base_params.colour"),
    (dict(base_params={"size": "huge"}), "dataset.params.base_params"),
    (dict(base_params=[1, 2]), "dataset.params.base_params"),
])
def test_bad_params_are_named(params, key, tmp_path):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        A.augmerl_dataset(**{"cache_dir": str(tmp_path), **params})


def test_memory_refusal(base_params, tmp_path, monkeypatch):
    monkeypatch.setattr(A, "available_memory", lambda: 100 * 2**20)  # the name augmerl reads
    with pytest.raises(generator_protocol.ResourceError, match=r"dataset\.params\.base.*GiB"):
        make(base_params, tmp_path, size=40)
    assert len(make(base_params, tmp_path, size=36)) == 36  # no interpolation, no PCA: allowed
    assert A.pca_nbytes(151) > 1.9 * 2**30
