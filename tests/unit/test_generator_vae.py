"""VAE-A / VAE-N generators: training lowers the loss, fits and samples are deterministic per
seed without touching the global RNG, VAE-N learns a two-cluster toy distribution, constant
coordinates stay constant, the 45 × 45 × 90 down/upsampling round trip, and the refusals."""

import json
import math

import numpy as np
import pytest
import torch
from scipy import stats

from brdfbench import logrel, merl
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import ResourceError, TrainingData, WeightSet
from brdfbench.nbrdf.network import n_weights
from brdfbench.testing.generators import training_data
from brdfbench_generators import pca, vae
from brdfbench_generators.vae import VAEBRDF, VAENBRDF, downsample, low_domain, upsample

ALPHA = 1e-3  # significance level of the statistical test here


def weight_data(vectors: torch.Tensor, hidden=(21, 21)) -> TrainingData:
    names = tuple(f"w{i}" for i in range(vectors.shape[0]))
    ws = WeightSet(names, vectors.numpy().astype(np.float32), hidden)
    return TrainingData(names=names, load=lambda name: None, weight_source=lambda _: ws, dataset="toy")


def random_weights(n=40, seed=0, hidden=(21, 21)) -> TrainingData:
    g = torch.Generator().manual_seed(seed)
    return weight_data(torch.randn(n, n_weights(hidden), generator=g), hidden)


def two_clusters(n=200, seed=0):
    """Weight vectors at centre ± a·u (u with equal-magnitude coordinates, so every coordinate
    sees the clusters) plus small noise; the first 30 coordinates constant."""
    g = torch.Generator().manual_seed(seed)
    width = n_weights((21, 21))
    u = (torch.randint(0, 2, (width,), generator=g) * 2 - 1).double() / math.sqrt(width)
    a = 0.5 * math.sqrt(width)
    centre = 0.2 * torch.randn(width, generator=g, dtype=torch.float64)
    side = (torch.arange(n) % 2 * 2 - 1).double()
    v = centre + side[:, None] * a * u + 0.05 * torch.randn(n, width, generator=g, dtype=torch.float64)
    v[:, :30] = 0.7
    return v.float(), centre, u, a


# --------------------------------------------------------------------------- VAE-N


def test_vae_n_learns_two_clusters():
    """Samples land near one of the clusters (|t ∓ 1| < 0.25 along the cluster axis) more often
    than under the Gaussian with the data's mean and covariance, the best a Gaussian (and the
    PCA baseline) can do: one-sided binomial test at level ALPHA. A standard-normal draw in the
    standardised space (no learning past the per-coordinate moments) would score lower still."""
    v, centre, u, a = two_clusters()
    model = VAENBRDF(epochs=300, patience=None).fit(weight_data(v), seed=0)
    samples = model.sample(1000, seed=1).array.double()
    t = ((samples - centre) @ u) / a
    near = int((((t - 1).abs() < 0.25) | ((t + 1).abs() < 0.25)).sum())
    t_train = ((v.double() - centre) @ u) / a
    sd = float(t_train.std())
    mean = float(t_train.mean())
    gauss = stats.norm(mean, sd)
    p0 = sum(gauss.cdf(c + 0.25) - gauss.cdf(c - 0.25) for c in (-1.0, 1.0))
    test = stats.binomtest(near, 1000, p0, alternative="greater")
    assert test.pvalue < ALPHA, f"{near}/1000 samples near a cluster; a Gaussian gives {p0:.3f}"
    assert (samples[:, :30] == torch.tensor(0.7, dtype=torch.float32).double()).all(), "constant coordinates moved"


def test_vae_n_loss_falls_and_curves_are_recorded():
    model = VAENBRDF(epochs=30).fit(random_weights(), seed=0, progress="vae_nbrdf test")
    meta = model.metadata()
    json.dumps(meta)
    assert meta["train_loss"][-1] < meta["train_loss"][0]
    assert len(meta["val_loss"]) == meta["epochs_run"] == 30 and meta["n_held_out"] == 4
    assert meta["layout"]["width"] == 675 and meta["fit_seconds"] > 0


def test_vae_n_is_deterministic_and_leaves_the_global_rng_alone():
    data = random_weights()
    before = torch.get_rng_state()
    a = VAENBRDF(epochs=5).fit(data, seed=3)
    b = VAENBRDF(epochs=5).fit(data, seed=3)
    c = VAENBRDF(epochs=5).fit(data, seed=4)
    sa, sb = a.sample(8, seed=2), b.sample(8, seed=2)
    assert torch.equal(torch.get_rng_state(), before), "fit or sample used the global RNG"
    assert all(torch.equal(a.state_dict()[k], b.state_dict()[k]) for k in a.state_dict())
    assert not torch.equal(a.state_dict()["net.decoder.0.weight"], c.state_dict()["net.decoder.0.weight"])
    assert torch.equal(sa.array, sb.array) and not torch.equal(sa.array, a.sample(8, seed=3).array)


def test_vae_n_zero_variance_coordinates_give_no_nan():
    v = torch.randn(12, 675, generator=torch.Generator().manual_seed(0))
    v[:, 5] = 0.0
    v[:, 7] = -1.25
    model = VAENBRDF(epochs=3).fit(weight_data(v))
    assert model.std[5] == 0 and model.std[7] == 0
    assert all(torch.isfinite(t).all() for t in model.state_dict().values())
    s = model.sample(50, seed=0).array
    assert torch.isfinite(s).all() and (s[:, 5] == 0).all() and (s[:, 7] == -1.25).all()


def test_vae_n_without_enough_vectors_for_a_held_out_set_monitors_the_training_loss():
    model = VAENBRDF(epochs=4).fit(random_weights(n=4))  # round(0.1 · 4) = 0 held out
    meta = model.metadata()
    assert meta["n_held_out"] == 0 and meta["val_loss"] is None and meta["monitored"] == "train_loss"


def test_vae_n_early_stop():
    model = VAENBRDF(epochs=500, patience=2, lr=1e-6).fit(random_weights(n=20))
    meta = model.metadata()
    assert meta["stopped"] == "patience" and meta["epochs_run"] < 500


@pytest.mark.parametrize("key, value, message", [
    ("latent", 0, "vae_nbrdf: latent=0 must be a positive integer"),
    ("hidden", 2.5, "vae_nbrdf: hidden=2.5 must be a positive integer"),
    ("layers", True, "vae_nbrdf: layers=True must be a positive integer"),
    ("epochs", -1, "vae_nbrdf: epochs=-1 must be a positive integer"),
    ("batch_size", "32", "vae_nbrdf: batch_size='32' must be a positive integer"),
    ("lr", 0.0, r"vae_nbrdf: lr=0.0 must be a finite number > 0"),
    ("kl_weight", float("nan"), r"vae_nbrdf: kl_weight=nan must be a finite number ≥ 0"),
    ("patience", 0, "vae_nbrdf: patience=0 must be a positive integer or null"),
    ("val_fraction", 0.5, r"vae_nbrdf: val_fraction=0.5 must be a number in \[0, 0.5\)"),
])
def test_vae_n_params_are_validated(key, value, message):
    with pytest.raises(ConfigError, match=message):
        VAENBRDF(**{key: value})


def test_vae_n_refusals():
    assert VAENBRDF().state_dict() == {} and not VAENBRDF().fitted
    with pytest.raises(ConfigError, match="at least 2"):
        VAENBRDF().fit(random_weights(n=1))
    model = VAENBRDF(epochs=2).fit(random_weights(n=8, hidden=(10, 10)))
    with pytest.raises(ConfigError, match="213-value weight vectors.*675"):
        model.fit(random_weights(n=8))


@pytest.mark.parametrize("name, change, message", [
    ("net.decoder.6.weight", lambda t: t[:, :-1], "'net.decoder.6.weight' has shape"),
    ("net.encoder.0.bias", lambda t: t.double(), "'net.encoder.0.bias' has dtype"),
    ("std", lambda t: t * float("nan"), "'std' has non-finite"),
    ("mean", None, "lacks tensor 'mean'"),
])
def test_vae_n_bad_model_files_name_the_tensor(name, change, message):
    model = VAENBRDF(epochs=2).fit(random_weights(n=8))
    tensors = dict(model.state_dict())
    if change is None:
        del tensors[name]
    else:
        tensors[name] = change(tensors[name])
    with pytest.raises(ModelFileError, match=message):
        VAENBRDF.from_state(model.params, tensors, model.metadata())


# --------------------------------------------------------------------------- down/upsampling


def test_nearest_upsampling_reproduces_block_constant_tables():
    low = torch.rand(3, 45, 45, 90, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    full = upsample(low)
    assert full.shape == (3, 90, 90, 180)
    assert torch.equal(full[:, 1::2, ::2, 1::2], low) and torch.equal(full[:, ::2, 1::2, ::2], low)
    again, counts = downsample(full, torch.ones(merl.SHAPE, dtype=torch.bool))
    assert again.shape == (3, 45, 45, 90) and torch.equal(again, low) and (counts == 8).all()
    assert torch.equal(upsample(again), full)


def test_downsample_averages_the_valid_cells_only():
    x = torch.arange(2 * 2 * 2, dtype=torch.float64).reshape(1, 2, 2, 2)
    x = x.repeat(1, 45, 45, 90)
    valid = torch.zeros(merl.SHAPE, dtype=torch.bool)
    valid[0, 0, 0] = valid[1, 1, 1] = True  # cells holding 0 and 7 of the first block
    low, counts = downsample(x, valid)
    assert low[0, 0, 0, 0] == 3.5 and counts[0, 0, 0] == 2
    assert low[0, 1, 1, 1] == 0 and counts[1, 1, 1] == 0


def test_table_fast_paths_match_the_grid_reference():
    """table_to_low / low_to_table (index_add and gather over the domain) agree with
    downsample / upsample on the full grid."""
    material = next(training_data().tables())
    low, ok = vae.table_to_low(material)
    cells, w = logrel.domain()
    values, valid = pca.values_on_domain(material)
    x = torch.zeros(3, merl.N_CELLS, dtype=torch.float64)
    x[:, cells] = logrel.to_mapped(values.clamp_min(0), torch.zeros((), dtype=torch.float64), w)
    mask = torch.zeros(merl.N_CELLS, dtype=torch.bool)
    mask[cells] = valid
    ref, counts = downsample(x.view(3, *merl.SHAPE), mask.view(merl.SHAPE))
    blocks = low_domain()
    assert blocks.numel() == 139_254
    assert torch.allclose(low, ref.reshape(3, -1)[:, blocks], rtol=1e-12, atol=1e-12)
    assert torch.equal(ok, counts.reshape(-1)[blocks] > 0)
    table = vae.low_to_table(low)
    grid = torch.zeros(3, 45 * 45 * 90, dtype=torch.float64)
    grid[:, blocks] = low
    up = upsample(grid.view(3, 45, 45, 90)).reshape(3, -1)[:, cells]
    expected = logrel.from_mapped(up, torch.zeros((), dtype=torch.float64), w)
    assert torch.allclose(torch.from_numpy(table.values.reshape(3, -1))[:, cells], expected, rtol=1e-12)
    assert table.valid.reshape(-1).sum() == cells.numel()


# --------------------------------------------------------------------------- VAE-A


@pytest.fixture(scope="module")
def vae_a():
    return VAEBRDF(epochs=40, patience=None).fit(training_data(), seed=2)


def test_vae_a_loss_falls_and_figures_are_recorded(vae_a):
    meta = vae_a.metadata()
    json.dumps(meta)
    assert meta["train_loss"][-1] < meta["train_loss"][0]
    assert meta["values_per_table"] == 3 * 139_254 and meta["reduce_dim"] == meta["n_train"] - 1 == 6
    assert 0 < sum(meta["explained_variance"]) <= 1 + 1e-9
    assert vae_a.nbytes == sum(t.numel() * t.element_size() for t in vae_a.state_dict().values())


def test_vae_a_samples_are_finite_tables(vae_a):
    samples = vae_a.sample(3, seed=0)
    assert samples.array.shape == (3, 6)
    table = samples.table(1)
    assert np.isfinite(table.values).all() and (table.values[:, table.valid] >= 0).all()
    assert torch.equal(vae_a.sample(3, seed=0).array, samples.array)


def test_vae_a_reduce_dim_and_max_materials():
    model = VAEBRDF(epochs=2, reduce_dim=3, max_materials=5).fit(training_data(), seed=0)
    meta = model.metadata()
    assert meta["n_materials"] == 5 and meta["reduce_dim"] == 3 and model.basis.shape[1] == 3


def test_vae_a_refuses_a_fit_larger_than_memory(monkeypatch):
    monkeypatch.setattr(pca, "available_memory", lambda: 1 << 30)

    def never(name):
        raise AssertionError("a refused fit must not read tables")

    with pytest.raises(ResourceError, match="vae_brdf: the fit needs about .*lower max_materials"):
        VAEBRDF().fit(TrainingData(names=tuple(f"m{i}" for i in range(2000)), load=never))


def test_vae_a_params_are_validated():
    with pytest.raises(ConfigError, match="vae_brdf: latent=0 must be a positive integer"):
        VAEBRDF(latent=0)
    with pytest.raises(ConfigError, match="vae_brdf: reduce_dim=0 must be a positive integer or null"):
        VAEBRDF(reduce_dim=0)
    assert VAEBRDF().state_dict() == {}


@pytest.mark.parametrize("name, change, message", [
    ("basis", lambda t: t[:-3], "'basis' has shape"),
    ("scale", lambda t: -t, "'scale' has negative"),
    ("net.decoder.0.weight", lambda t: t.half(), "'net.decoder.0.weight' has dtype"),
])
def test_vae_a_bad_model_files_name_the_tensor(vae_a, name, change, message):
    tensors = dict(vae_a.state_dict())
    tensors[name] = change(tensors[name])
    with pytest.raises(ModelFileError, match=message):
        VAEBRDF.from_state(vae_a.params, tensors, vae_a.metadata())
