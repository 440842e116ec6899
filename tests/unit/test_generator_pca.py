"""PCA-A / PCA-N generators: the decomposition against an SVD, the sampling distribution,
exact reconstruction in the full subspace, and the refusals (memory, too few materials,
bad model files, another weight layout)."""

import json
import logging
import math

import numpy as np
import pytest
import torch
from scipy import stats

from brdfbench import logrel
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import ResourceError, TrainingData, WeightSet
from brdfbench.nbrdf.network import n_weights
from brdfbench.testing.generators import training_data
from brdfbench_generators import pca
from brdfbench_generators.pca import PCABRDF, PCANBRDF, gram_pca

ALPHA = 1e-3  # significance level of every statistical test here (Bonferroni-corrected within a test)


def weight_data(n=20, hidden=(21, 21), seed=0, rank=None) -> TrainingData:
    """n random weight vectors (optionally of a given rank around a mean) as a TrainingData."""
    g = torch.Generator().manual_seed(seed)
    width = n_weights(hidden)
    if rank is None:
        v = torch.randn(n, width, generator=g)
    else:
        v = 0.3 + torch.randn(n, rank, generator=g) @ torch.randn(rank, width, generator=g)
    names = tuple(f"w{i}" for i in range(n))
    ws = WeightSet(names, v.numpy().astype(np.float32), hidden)
    return TrainingData(names=names, load=lambda name: None, weight_source=lambda _: ws, dataset="toy")


@pytest.fixture(scope="module")
def pca_a():
    return PCABRDF().fit(training_data(), seed=3)


# --------------------------------------------------------------------------- the decomposition


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_gram_basis_matches_svd(monkeypatch, dtype):
    monkeypatch.setattr(pca, "_BLOCK_BYTES", 8 * 12 * 1024)  # several column blocks
    g = torch.Generator().manual_seed(1)
    x = torch.randn(12, 5000, generator=g, dtype=torch.float64) * torch.logspace(0, -2, 5000, dtype=torch.float64)
    x -= x.mean(dim=0)
    eigvals, scores, basis, total = gram_pca(x.to(dtype), 11)
    _, s, vh = torch.linalg.svd(x, full_matrices=False)  # the slow reference
    tol = 1e-9 if dtype == torch.float64 else 2e-4
    assert torch.allclose(eigvals, s[:11] ** 2, rtol=tol * 10)
    assert total == pytest.approx(float((x**2).sum()), rel=1e-6)
    for j in range(11):
        ref = vh[j]
        got = basis[:, j].double()
        sign = torch.sign(got @ ref)
        assert torch.allclose(got * sign, ref, atol=tol * 10), f"component {j}"
    assert torch.allclose(basis.double().T @ basis.double(), torch.eye(11, dtype=torch.float64), atol=tol * 10)
    assert torch.allclose(scores, x @ basis.double(), atol=tol * 100 * float(s[0]))


def test_gram_signs_do_not_depend_on_the_eigensolver():
    x = torch.randn(6, 40, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    x -= x.mean(dim=0)
    _, scores, basis, _ = gram_pca(x, 5)
    _, scores_neg, basis_neg, _ = gram_pca(x.clone(), 5)
    assert torch.equal(basis, basis_neg) and torch.equal(scores, scores_neg)
    rows = scores.abs().argmax(dim=0)
    assert (scores[rows, torch.arange(5)] > 0).all()


def test_rank_deficient_data_keeps_only_real_components(caplog):
    data = weight_data(n=30, rank=4)
    with caplog.at_level(logging.INFO, logger="brdfbench_generators.pca"):
        model = PCANBRDF(k=20).fit(data)
    assert model.std.numel() == 4
    assert torch.isfinite(model.basis).all()
    assert any("numerically zero" in r.message for r in caplog.records)


# --------------------------------------------------------------------------- PCA-N


def test_pca_n_caps_k_and_says_so(caplog):
    with caplog.at_level(logging.INFO, logger="brdfbench_generators.pca"):
        model = PCANBRDF().fit(weight_data(n=20))
    assert model.std.numel() == 19 and model.metadata()["k"] == 19
    assert any("k=100 capped at 19" in r.message for r in caplog.records)


def test_pca_n_reconstructs_training_vectors_exactly():
    data = weight_data(n=20)
    model = PCANBRDF().fit(data)
    w = torch.from_numpy(data.weights().vectors).double()
    projected = model.mean + ((w - model.mean) @ model.basis) @ model.basis.T
    assert torch.allclose(projected, w, atol=1e-5, rtol=0)
    explained = model.metadata()["explained_variance"]
    assert sum(explained) == pytest.approx(1.0, abs=1e-9)
    assert explained == sorted(explained, reverse=True)


def _check_gaussian(coefficients: torch.Tensor, std: torch.Tensor) -> None:
    """Samples c (n, k) against N(0, diag(std²)), at level ALPHA with Bonferroni corrections:
    per-component mean (z), variance (χ² with n degrees of freedom: the mean is known) and
    pairwise correlation (Fisher z)."""
    n, k = coefficients.shape
    c = coefficients.double() / std.double()
    z_mean = c.mean(dim=0) * math.sqrt(n)
    assert (z_mean.abs() < stats.norm.ppf(1 - ALPHA / (2 * k))).all(), f"means off: {z_mean.tolist()}"
    chi2 = (c**2).sum(dim=0)
    lo, hi = stats.chi2.ppf(ALPHA / (2 * k), n), stats.chi2.ppf(1 - ALPHA / (2 * k), n)
    assert ((chi2 > lo) & (chi2 < hi)).all(), f"variance ratios off: {(chi2 / n).tolist()}"
    if k > 1:
        r = torch.corrcoef(c.T)
        pairs = k * (k - 1) // 2
        fisher = torch.atanh(r[torch.triu_indices(k, k, 1).unbind()]) * math.sqrt(n - 3)
        assert (fisher.abs() < stats.norm.ppf(1 - ALPHA / (2 * pairs))).all(), "components correlated"


def test_pca_n_samples_follow_the_model():
    model = PCANBRDF().fit(weight_data(n=20))
    samples = model.sample(4000, seed=7)
    coefficients = (samples.array.double() - model.mean) @ model.basis
    _check_gaussian(coefficients, model.std)


def test_pca_n_is_deterministic_and_leaves_the_global_rng_alone():
    data = weight_data(n=20)
    before = torch.get_rng_state()
    a, b = PCANBRDF().fit(data, seed=1), PCANBRDF().fit(data, seed=1)
    sa, sb = a.sample(5, seed=4), b.sample(5, seed=4)
    assert torch.equal(torch.get_rng_state(), before), "fit or sample used the global RNG"
    assert all(torch.equal(a.state_dict()[k], b.state_dict()[k]) for k in a.state_dict())
    assert torch.equal(sa.array, sb.array) and not torch.equal(sa.array, a.sample(5, seed=5).array)


def test_pca_n_layout_is_kept_and_other_widths_refused():
    model = PCANBRDF().fit(weight_data(n=10, hidden=(10, 10)))
    samples = model.sample(3, seed=0)
    assert samples.hidden == (10, 10) and samples.array.shape == (3, n_weights((10, 10)))
    loaded = PCANBRDF.from_state(model.params, model.state_dict(), json.loads(json.dumps(model.metadata())))
    assert loaded.sample(3, seed=0).hidden == (10, 10)
    with pytest.raises(ConfigError, match="213-value weight vectors.*675"):
        loaded.fit(weight_data(n=10))


def test_pca_n_refusals():
    assert PCANBRDF().state_dict() == {}
    with pytest.raises(ConfigError, match="pca_nbrdf: k=0 must be a positive integer"):
        PCANBRDF(k=0)
    with pytest.raises(ConfigError, match="at least 2"):
        PCANBRDF().fit(weight_data(n=1))
    same = weight_data(n=3)
    ws = same.weights()
    ws3 = WeightSet(ws.names, np.repeat(ws.vectors[:1], 3, axis=0), ws.hidden)
    with pytest.raises(ConfigError, match="identical"):
        PCANBRDF().fit(TrainingData(ws.names, lambda n: None, weight_source=lambda _: ws3))


@pytest.mark.parametrize("name, change, message", [
    ("basis", lambda t: t[:-1], "'basis' has shape"),
    ("mean", lambda t: t.float(), "'mean' has dtype torch.float32"),
    ("std", lambda t: t * float("nan"), "'std' has non-finite"),
    ("std", lambda t: t[:0], "'std' has shape"),
])
def test_pca_n_bad_model_files_name_the_tensor(name, change, message):
    model = PCANBRDF().fit(weight_data(n=10))
    tensors = dict(model.state_dict())
    tensors[name] = change(tensors[name])
    with pytest.raises(ModelFileError, match=message):
        PCANBRDF.from_state(model.params, tensors, model.metadata())


# --------------------------------------------------------------------------- PCA-A


def test_pca_a_fit_records_its_figures(pca_a):
    meta = pca_a.metadata()
    json.dumps(meta)
    n = len(training_data())
    assert meta["n_materials"] == n and meta["k"] == n - 1 == pca_a.basis.shape[1]
    explained = meta["explained_variance"]
    assert 0 < sum(explained) <= 1 + 1e-9 and explained == sorted(explained, reverse=True)
    assert meta["fit_seconds"] > 0 and meta["planned_peak_bytes"] >= PCABRDF.fit_nbytes(n, n - 1) - 1
    p = logrel.domain()[0].numel()
    assert pca_a.basis.shape == (3 * p, n - 1) and pca_a.basis.dtype == torch.float32
    assert pca_a.nbytes == sum(t.numel() * t.element_size() for t in pca_a.state_dict().values())


def test_pca_a_reconstructs_training_materials_exactly(pca_a):
    """A training material projected onto all n − 1 components comes back up to fp32, in the
    log-relative space and as BRDF values (cosine-weighted, as the mapping sees them) on its valid cells."""
    material = next(training_data().tables())
    values, valid = pca.values_on_domain(material)
    _, w = logrel.domain()
    x = torch.where(valid, logrel.to_mapped(values, pca_a.reference.double(), w), 0.0).reshape(-1)
    centred = x - pca_a.mean.double()
    coefficients = torch.zeros(pca_a.basis.shape[1], dtype=torch.float64)
    for c in pca.block_columns(pca_a.basis.shape[1], x.numel()):
        coefficients += (centred[c].float() @ pca_a.basis[c]).double()
    back = pca_a.mean.double() + pca.chunked_combine(pca_a.basis, coefficients)
    assert (back - x).abs().max() < 2e-4 * max(1.0, float(x.abs().max()))
    table = pca_a.to_table(coefficients)
    cells, _ = logrel.domain()
    got = torch.from_numpy(table.values.reshape(3, -1))[:, cells]
    # Errors δx in the mapped space are relative errors of ρ·w + ε (large for ρ near grazing, where w → 0).
    error = (got - values).abs() * w / (values * w + logrel.EPSILON)
    assert error[:, valid].max() < 1e-3


def test_pca_a_samples_follow_the_model(pca_a):
    samples = pca_a.sample(4000, seed=3)
    assert samples.array.shape == (4000, pca_a.std.numel())
    _check_gaussian(samples.array, pca_a.std)


def test_pca_a_sample_tables_are_finite_and_invalid_below_the_horizon(pca_a):
    table = pca_a.sample(1, seed=0).table(0)
    cells, _ = logrel.domain()
    valid = table.valid.reshape(-1)
    assert valid.sum() == cells.numel() and valid[cells.numpy()].all()
    assert np.isfinite(table.values).all() and (table.values.reshape(3, -1)[:, valid] >= 0).all()


def test_pca_a_max_materials_subsamples_per_seed():
    data = training_data()
    a = PCABRDF(k=2, max_materials=4).fit(data, seed=1)
    b = PCABRDF(k=2, max_materials=4).fit(data, seed=1)
    assert a.metadata()["n_materials"] == 4 and a.std.numel() == 2
    assert a.metadata()["training_materials"] == b.metadata()["training_materials"]
    assert torch.equal(a.basis, b.basis)


def test_pca_a_refuses_a_fit_larger_than_memory(monkeypatch):
    monkeypatch.setattr(pca, "available_memory", lambda: 1 << 30)

    def never(name):
        raise AssertionError("a refused fit must not read tables")

    data = TrainingData(names=tuple(f"m{i}" for i in range(400)), load=never)
    with pytest.raises(ResourceError, match=r"needs about [\d.]+ GiB.*lower max_materials"):
        PCABRDF().fit(data)


def test_pca_a_refusals():
    assert PCABRDF().state_dict() == {} and not PCABRDF().fitted
    with pytest.raises(ConfigError, match="pca_brdf: k=0 must be a positive integer"):
        PCABRDF(k=0)
    with pytest.raises(ConfigError, match="pca_brdf: max_materials=1.5 must be a positive integer or null"):
        PCABRDF(max_materials=1.5)
    one = TrainingData(names=("a",), load=lambda n: None)
    with pytest.raises(ConfigError, match="at least 2 training materials"):
        PCABRDF().fit(one)


@pytest.mark.parametrize("name, change, message", [
    ("basis", lambda t: t[:, :-1], "'basis' has shape"),
    ("reference", lambda t: t.double(), "'reference' has dtype"),
    ("mean", lambda t: t.clone().index_fill_(0, torch.tensor([5]), float("inf")), "'mean' has non-finite"),
    ("std", lambda t: t[None], "'std' has shape"),
])
def test_pca_a_bad_model_files_name_the_tensor(pca_a, name, change, message):
    tensors = dict(pca_a.state_dict())
    tensors[name] = change(tensors[name])
    with pytest.raises(ModelFileError, match=message):
        PCABRDF.from_state(pca_a.params, tensors, pca_a.metadata())
