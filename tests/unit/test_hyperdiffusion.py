"""The hyperdiffusion generator: its schedule, the DDIM update and guidance formula, params,
saved-state checks, learning on a toy weight set, and the conformance kit."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from scipy.stats import binomtest

from brdfbench import modelio
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.generator import TrainingData, WeightSet
from brdfbench.nbrdf.network import n_weights
from brdfbench.testing import generator_checks
from brdfbench_generators import hyperdiffusion as hd
from brdfbench_generators.hyperdiffusion import HyperDiffusion

#: A small NBRDF layout (6-8-3: 83 weights) so toy fits take a second.
TOY_HIDDEN = (8,)
TINY = {"d_model": 16, "layers": 1, "heads": 2, "chunk_size": 32, "epochs": 3, "batch_size": 16, "ddim_steps": 5}


def _data(vectors: np.ndarray, categories: list[str] | None = None, hidden=TOY_HIDDEN, **layout) -> TrainingData:
    names = tuple(f"m{i:03d}" for i in range(len(vectors)))
    ws = WeightSet(names, vectors.astype(np.float32), tuple(hidden), **layout)
    cats = dict(zip(names, categories)) if categories else {}
    return TrainingData(names=names, load=None, categories=cats, weight_source=lambda _: ws, dataset="toy")


def _clusters(n_per: int = 32, spread: float = 0.05, seed: int = 0):
    """Two clusters of 6-8-3 weight vectors around centres a and b, labelled "a" and "b"."""
    rng = np.random.default_rng(seed)
    width = n_weights(TOY_HIDDEN)
    centres = rng.standard_normal((2, width))
    vectors = np.concatenate([c + spread * rng.standard_normal((n_per, width)) for c in centres])
    return vectors, ["a"] * n_per + ["b"] * n_per, centres


@pytest.fixture(scope="module")
def toy_fit():
    vectors, _, _ = _clusters(8)
    return HyperDiffusion(**TINY).fit(_data(vectors), seed=0)


# -- the schedule ------------------------------------------------------------------------------


def test_beta_schedule_is_linear_from_1e4_to_2e2_over_100_steps():
    betas = hd.beta_schedule()
    assert betas.shape == (100,) and betas.dtype == torch.float64
    assert float(betas[0]) == pytest.approx(1e-4) and float(betas[-1]) == pytest.approx(2e-2)
    assert torch.allclose(betas.diff(), torch.full((99,), (2e-2 - 1e-4) / 99, dtype=torch.float64))


def test_alpha_bars_are_the_running_products():
    betas = hd.beta_schedule()
    ab = hd.alpha_bars(betas)
    expected = [math.prod(1 - float(b) for b in betas[: t + 1]) for t in range(100)]
    assert torch.allclose(ab, torch.tensor(expected, dtype=torch.float64), rtol=1e-12)
    assert float(ab[0]) == pytest.approx(1 - 1e-4)
    # the terminal ᾱ of Zhou et al.'s schedule is far from 0: why the matched prior exists
    assert float(ab[-1]) == pytest.approx(0.36356, abs=1e-5)


@pytest.mark.parametrize("steps,first,count", [(100, 99, 100), (50, 99, 50), (1, 99, 1), (7, 99, 7)])
def test_ddim_timesteps_descend_from_T_to_0(steps, first, count):
    ts = hd.ddim_timesteps(steps)
    assert ts[0] == first and len(ts) == count and ts == sorted(ts, reverse=True)
    assert count == 1 or ts[-1] == 0


# -- the DDIM update ------------------------------------------------------------------------------


def _point_mass_oracle(x0: torch.Tensor, ab: torch.Tensor):
    """The exact noise predictor of a data distribution that is a point mass at x0."""
    return lambda x, t: (x - ab[t].sqrt() * x0) / (1 - ab[t]).sqrt()


def _paper_step(x, eps, ab_t, ab_prev, alpha_t):
    """The defective update of the paper's code: the posterior mean μ̃(x_t, x̂₀) where ε̂ belongs."""
    x0 = (x - math.sqrt(1 - ab_t) * eps) / math.sqrt(ab_t)
    mean = (math.sqrt(ab_prev) * (1 - alpha_t) / (1 - ab_t)) * x0 + (math.sqrt(alpha_t) * (1 - ab_prev) / (1 - ab_t)) * x
    return math.sqrt(ab_prev) * x0 + math.sqrt(1 - ab_prev) * mean


@pytest.mark.parametrize("steps", [100, 20, 1])
def test_ddim_recovers_a_point_mass_along_its_exact_trajectory(steps):
    """For data = δ(x0) the exact ε̂ is known; deterministic DDIM must stay on
    x_s = √ᾱ_s x0 + √(1 − ᾱ_s) ε with ε fixed by x_T, and end exactly at x0."""
    g = torch.Generator().manual_seed(0)
    ab = hd.alpha_bars(hd.beta_schedule())
    x0 = torch.randn(64, generator=g, dtype=torch.float64) * 3
    x_T = torch.randn(64, generator=g, dtype=torch.float64)
    eps = (x_T - ab[-1].sqrt() * x0) / (1 - ab[-1]).sqrt()
    oracle = _point_mass_oracle(x0, ab)
    ts = hd.ddim_timesteps(steps)
    x = x_T
    for i, t in enumerate(ts):
        prev = float(ab[ts[i + 1]]) if i + 1 < len(ts) else 1.0
        x = hd.ddim_step(x, oracle(x, t), float(ab[t]), prev)
        assert torch.allclose(x, math.sqrt(prev) * x0 + math.sqrt(1 - prev) * eps, atol=1e-10)
    assert torch.allclose(hd.ddim_sample(oracle, x_T, ab, steps), x0, atol=1e-10)


def _paper_sample(predict, x, ab, steps):
    alphas = 1 - hd.beta_schedule()
    ts = hd.ddim_timesteps(steps)
    states = []
    for i, t in enumerate(ts):
        prev = float(ab[ts[i + 1]]) if i + 1 < len(ts) else 1.0
        x = _paper_step(x, predict(x, t), float(ab[t]), prev, float(alphas[t]))
        states.append((prev, x))
    return states


def test_the_papers_ddim_step_leaves_the_point_mass_trajectory():
    """The pinned trajectory check discriminates: the defective update strays from
    √ᾱ_s x0 + √(1 − ᾱ_s) ε at the intermediate steps (its last step, to ᾱ = 1, drops the
    faulty term, so only the path and the distribution betray it: see the Gaussian test)."""
    g = torch.Generator().manual_seed(0)
    ab = hd.alpha_bars(hd.beta_schedule())
    x0 = torch.randn(64, generator=g, dtype=torch.float64) * 3
    x_T = torch.randn(64, generator=g, dtype=torch.float64)
    eps = (x_T - ab[-1].sqrt() * x0) / (1 - ab[-1]).sqrt()
    states = _paper_sample(_point_mass_oracle(x0, ab), x_T, ab, 20)
    stray = max(float((x - (math.sqrt(a) * x0 + math.sqrt(1 - a) * eps)).abs().max()) for a, x in states[:-1])
    assert stray > 0.5


def _gaussian_oracle(m: torch.Tensor, s: torch.Tensor, ab: torch.Tensor):
    """The exact noise predictor E[ε | x_t] of data N(m, s²) (per coordinate)."""
    def predict(x, t):
        a = ab[t]
        return (1 - a).sqrt() * (x - a.sqrt() * m) / (a * s**2 + 1 - a)
    return predict


GAUSS_M = torch.tensor([2.0, -1.0, 0.0], dtype=torch.float64)
GAUSS_S = torch.tensor([0.1, 3.0, 1.0], dtype=torch.float64)


def _affine_moments(run, ab):
    """DDIM (η = 0) with a Gaussian's exact ε̂ is affine in x_T: pushing x_T = mean ± std of
    the exact q(x_T) through it gives the output's mean and std without sampling."""
    mean_T = ab[-1].sqrt() * GAUSS_M
    std_T = (ab[-1] * GAUSS_S**2 + 1 - ab[-1]).sqrt()
    hi, lo = run(mean_T + std_T), run(mean_T - std_T)
    return (hi + lo) / 2, (hi - lo) / 2


@pytest.mark.parametrize("steps,rtol", [(100, 0.05), (50, 0.1), (20, 0.2)])
def test_deterministic_ddim_maps_the_gaussian_marginal_onto_the_data(steps, rtol):
    """Data N(m, s²) with its exact ε̂, started from the exact q(x_T): the mean is kept
    exactly; the std comes out within the discretisation error of `steps` steps (an
    under-dispersion, worst on the narrowest coordinate: 4 % at 100 steps for s = 0.1)."""
    ab = hd.alpha_bars(hd.beta_schedule())
    oracle = _gaussian_oracle(GAUSS_M, GAUSS_S, ab)
    mean, std = _affine_moments(lambda x: hd.ddim_sample(oracle, x, ab, steps), ab)
    assert torch.allclose(mean, GAUSS_M, atol=1e-9)
    assert torch.allclose(std, GAUSS_S, rtol=rtol) and (std <= GAUSS_S * (1 + 1e-9)).all()


def test_the_papers_ddim_step_gets_the_gaussian_wrong():
    ab = hd.alpha_bars(hd.beta_schedule())
    oracle = _gaussian_oracle(GAUSS_M, GAUSS_S, ab)
    mean, std = _affine_moments(lambda x: _paper_sample(oracle, x, ab, 20)[-1][1], ab)
    assert not torch.allclose(std, GAUSS_S, rtol=0.5) or not torch.allclose(mean, GAUSS_M, atol=0.1)


def test_stochastic_ddim_samples_the_gaussian_data():
    """η = 1 (DDPM's variance) on N(m, s²) with its exact ε̂: mean and std of 40 000 draws
    agree with (m, s) within 4.5 standard errors (two-sided α ≈ 1e-5 each, seeded)."""
    ab = hd.alpha_bars(hd.beta_schedule())
    m = torch.tensor([2.0, -1.0], dtype=torch.float64)
    s = torch.tensor([0.5, 2.0], dtype=torch.float64)
    g = torch.Generator().manual_seed(3)
    n = 40_000
    x_T = ab[-1].sqrt() * m + (ab[-1] * s**2 + 1 - ab[-1]).sqrt() * torch.randn(n, 2, generator=g, dtype=torch.float64)
    out = hd.ddim_sample(_gaussian_oracle(m, s, ab), x_T, ab, 100, eta=1.0, generator=g)
    se_mean, se_std = s / math.sqrt(n), s / math.sqrt(2 * n)
    assert ((out.mean(0) - m).abs() < 4.5 * se_mean).all()
    # the ancestral step with DDPM's σ² under-disperses slightly on a Gaussian: allow 1 %
    assert ((out.std(0) - s).abs() < 4.5 * se_std + 0.01 * s).all()


def test_ddim_step_needs_noise_when_stochastic():
    with pytest.raises(ValueError, match="noise"):
        hd.ddim_step(torch.zeros(3), torch.zeros(3), 0.5, 0.8, eta=1.0)


# -- classifier-free guidance ---------------------------------------------------------------------


def test_guidance_combines_eps_u_plus_w_times_the_difference():
    g = torch.Generator().manual_seed(0)
    eu, ec = torch.randn(5, 7, generator=g), torch.randn(5, 7, generator=g)
    assert torch.equal(hd.guided(eu, ec, 0.0), eu)
    assert torch.allclose(hd.guided(eu, ec, 1.0), ec)
    assert torch.allclose(hd.guided(eu, ec, 3.0), eu + 3.0 * (ec - eu))
    omega = 2.0  # Zhou et al.'s Algorithm 1 form (1 + ω) ε_c − ω ε_u is w = 1 + ω
    assert torch.allclose(hd.guided(eu, ec, 1 + omega), (1 + omega) * ec - omega * eu, atol=1e-6)


class _StubDenoiser(torch.nn.Module):
    """ε̂ = the first coordinate of the condition vector, broadcast: tells the branches apart."""

    def __init__(self, cond):
        super().__init__()
        self.cond = cond

    def forward(self, x, t, cond):
        return cond[:, :1].expand_as(x).clone()


@pytest.mark.parametrize("guidance", [1.0, 2.5])
def test_sampling_feeds_both_branches_through_the_guidance_formula(guidance):
    """One DDIM step (ᾱ_T → clean) with a stub ε̂: x₀ = (x_T − √(1 − ᾱ_T) ε)/√ᾱ_T with
    ε = ε_u + w (ε_c − ε_u), ε_u and ε_c read from the null and class rows."""
    vectors, cats, _ = _clusters(8)
    model = HyperDiffusion(**{**TINY, "ddim_steps": 1, "guidance": guidance, "prior": "standard"},
                           condition_on="category").fit(_data(vectors, cats), seed=0)
    table = model.model.cond.table.weight
    model.model = _StubDenoiser(model.model.cond)
    out = model.sample(4, condition="b", seed=9)
    x_T = torch.randn((4, n_weights(TOY_HIDDEN)), generator=torch.Generator().manual_seed(9))
    eps = hd.guided(table[0, 0], table[2, 0], guidance)  # row 0: no condition; row 1 + index of "b"
    ab_T = float(hd.alpha_bars(hd.beta_schedule())[-1])
    z = (x_T - math.sqrt(1 - ab_T) * eps) / math.sqrt(ab_T)
    assert torch.allclose(out.array, z * model.std + model.mean, atol=1e-4)


# -- params ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("key,value", [
    ("d_model", 0), ("d_model", 12.5), ("layers", -1), ("heads", True), ("epochs", 0), ("batch_size", "64"),
    ("chunk_size", 0), ("ddim_steps", 0), ("ddim_steps", 101), ("tokens", "neuron"), ("lr", 0.0),
    ("lr", float("nan")), ("lr_final", 1.0), ("ema", 1.0), ("ema", -0.1), ("eta", 1.5), ("guidance", float("inf")),
    ("condition_on", "text"), ("p_uncond", 1.0), ("prior", "gaussian"), ("hidden", []), ("hidden", [21, 0]),
    ("hidden", "21"), ("weight_decay", -1.0),
])
def test_bad_params_are_refused_naming_the_key(key, value):
    with pytest.raises(ConfigError, match=f"hyperdiffusion: {key}="):
        HyperDiffusion(**{key: value})


def test_heads_must_divide_d_model():
    with pytest.raises(ConfigError, match="d_model=30 .* heads=4"):
        HyperDiffusion(d_model=30, heads=4)


def test_guidance_without_an_unconditional_branch_is_refused():
    with pytest.raises(ConfigError, match="p_uncond"):
        HyperDiffusion(condition_on="category", p_uncond=0.0, guidance=2.0)


def test_params_round_trip_through_json():
    model = HyperDiffusion(hidden=(21, 21), condition_on="category")
    assert json.loads(json.dumps(model.params)) == model.params
    assert model.params["hidden"] == [21, 21]


# -- fit, sample, state ---------------------------------------------------------------------------


def test_unfitted_state_is_empty():
    model = HyperDiffusion(**TINY)
    assert model.state_dict() == {} and not model.fitted and model.metadata() == {}


def test_width_mismatch_is_refused_at_fit():
    vectors, _, _ = _clusters(4)
    with pytest.raises(ConfigError, match="6-21-21-3 networks .*6-8-3"):
        HyperDiffusion(**TINY, hidden=[21, 21]).fit(_data(vectors))


def test_fit_and_sample_are_deterministic_and_leave_the_global_rng_alone():
    vectors, _, _ = _clusters(8)
    before = torch.get_rng_state()
    a = HyperDiffusion(**TINY).fit(_data(vectors), seed=4)
    b = HyperDiffusion(**TINY).fit(_data(vectors), seed=4)
    c = HyperDiffusion(**TINY).fit(_data(vectors), seed=5)
    assert all(torch.equal(a.state_dict()[k], b.state_dict()[k]) for k in a.state_dict())
    assert not torch.equal(a.state_dict()["denoiser.embed_w"], c.state_dict()["denoiser.embed_w"])
    assert torch.equal(a.sample(3, seed=1).array, b.sample(3, seed=1).array)
    assert torch.equal(torch.get_rng_state(), before)


def test_metadata_holds_the_training_curve_as_json(toy_fit):
    meta = json.loads(json.dumps(toy_fit.metadata()))
    curve = meta["training"]
    assert len(curve["loss"]) == len(curve["wall_s"]) == TINY["epochs"]
    assert all(math.isfinite(v) and v > 0 for v in curve["loss"])
    assert curve["wall_s"] == sorted(curve["wall_s"])
    assert meta["hidden"] == list(TOY_HIDDEN) and meta["width"] == n_weights(TOY_HIDDEN)


def test_nbytes_counts_the_saved_tensors(toy_fit):
    state = toy_fit.state_dict()
    assert toy_fit.nbytes == sum(t.numel() * t.element_size() for t in state.values())
    params = sum(p.numel() for p in toy_fit.model.parameters())
    assert toy_fit.nbytes >= 4 * params


def test_sample_nbytes_covers_the_arrays_and_grows(toy_fit):
    sizes = [toy_fit.sample_nbytes(n) for n in (1, 100, 10_000, 10**9)]
    assert sizes == sorted(sizes) and sizes[-1] >= 5 * 4 * 10**9 * n_weights(TOY_HIDDEN)


def test_layout_reaches_the_samples_and_survives_saving(tmp_path):
    vectors, _, _ = _clusters(4)
    data = _data(vectors, features="directions", raw_units=True)
    model = HyperDiffusion(**TINY).fit(data, seed=0)
    name, loaded = modelio.load_generator(modelio.save_generator(model, "hyperdiffusion", tmp_path / "g.safetensors"))
    for m in (model, loaded):
        s = m.sample(2, seed=0)
        assert s.hidden == TOY_HIDDEN and s.features == "directions" and s.raw_units and s.representation == "naive_mlp"
    assert torch.equal(model.sample(2, seed=0).array, loaded.sample(2, seed=0).array)


def test_condition_is_refused_by_an_unconditional_model(toy_fit):
    with pytest.raises(ConfigError, match="trained unconditionally .*condition must be None"):
        toy_fit.sample(2, condition="metal", seed=0)


def test_conditions_are_checked_against_the_training_classes():
    vectors, cats, _ = _clusters(4)
    model = HyperDiffusion(**TINY, condition_on="category").fit(_data(vectors, cats), seed=0)
    assert model.metadata()["classes"] == ["a", "b"]
    with pytest.raises(ConfigError, match=r"unknown condition\(s\) \['c'\]"):
        model.sample(2, condition="c", seed=0)
    with pytest.raises(ConfigError, match="3 conditions given for n=2"):
        model.sample(2, condition=["a", "b", "a"], seed=0)
    assert model.sample(2, condition=["a", "b"], seed=0).array.shape == (2, n_weights(TOY_HIDDEN))


def test_category_conditioning_needs_categories():
    vectors, _, _ = _clusters(4)
    with pytest.raises(Exception, match="no category"):
        HyperDiffusion(**TINY, condition_on="category").fit(_data(vectors), seed=0)


# -- from_state --------------------------------------------------------------------------------------


def _state(model):
    return dict(model.params), {k: v.clone() for k, v in model.state_dict().items()}, model.metadata()


def test_from_state_rebuilds_the_same_sampler(toy_fit):
    params, tensors, meta = _state(toy_fit)
    loaded = HyperDiffusion.from_state(params, tensors, meta)
    assert torch.equal(loaded.sample(3, seed=2).array, toy_fit.sample(3, seed=2).array)


@pytest.mark.parametrize("key", ["denoiser.embed_w", "denoiser.blocks.0.qkv.weight", "data_std", "prior_basis"])
def test_from_state_names_a_misshapen_tensor(toy_fit, key):
    params, tensors, meta = _state(toy_fit)
    tensors[key] = tensors[key][..., :-1]
    with pytest.raises(ModelFileError, match=f"tensor '{key}' has shape"):
        HyperDiffusion.from_state(params, tensors, meta)


def test_from_state_names_a_non_finite_tensor(toy_fit):
    params, tensors, meta = _state(toy_fit)
    tensors["denoiser.out_b"][0, 0] = float("nan")
    with pytest.raises(ModelFileError, match="'denoiser.out_b' must be finite"):
        HyperDiffusion.from_state(params, tensors, meta)


def test_from_state_names_missing_and_extra_tensors(toy_fit):
    params, tensors, meta = _state(toy_fit)
    del tensors["data_mean"]
    with pytest.raises(ModelFileError, match="lacks tensor 'data_mean'"):
        HyperDiffusion.from_state(params, tensors, meta)
    params, tensors, meta = _state(toy_fit)
    tensors["stray"] = torch.zeros(1)
    with pytest.raises(ModelFileError, match="unexpected tensor.*stray"):
        HyperDiffusion.from_state(params, tensors, meta)


def test_from_state_refuses_params_the_tensors_do_not_fit(toy_fit):
    params, tensors, meta = _state(toy_fit)
    with pytest.raises(ModelFileError, match="has shape"):
        HyperDiffusion.from_state({**params, "d_model": 32}, tensors, meta)
    with pytest.raises(ModelFileError, match="classes"):
        HyperDiffusion.from_state({**params, "condition_on": "category"}, tensors, meta)


# -- learning --------------------------------------------------------------------------------------

#: Significance level of the statistical learning checks (deterministic given the seeds).
ALPHA = 1e-3
LEARN = {"d_model": 64, "layers": 2, "heads": 4, "chunk_size": 16, "epochs": 150, "batch_size": 32,
         "lr": 2e-3, "lr_final": 1e-4, "ddim_steps": 25}


@pytest.fixture(scope="module")
def two_clusters():
    vectors, cats, centres = _clusters(32)
    model = HyperDiffusion(**LEARN, condition_on="category", p_uncond=0.2).fit(_data(vectors, cats), seed=0)
    return model, torch.as_tensor(centres, dtype=torch.float32)


def _nearest(samples: torch.Tensor, centres: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(index of the nearest centre, distance to it / the centres' separation) per sample."""
    d = torch.cdist(samples, centres)
    dist, which = d.min(dim=1)
    return which, dist / (centres[0] - centres[1]).norm()


def test_unconditional_samples_land_near_both_clusters(two_clusters):
    """H0 "a sample lands within a quarter of the separation of a centre with probability
    ≤ 1/2" (the midpoint, or noise, lands farther) is rejected at α = 1e-3 by a one-sided
    binomial test; and neither cluster is dropped: the share of cluster a is consistent with
    1/2 (two-sided binomial test not rejecting at α)."""
    model, centres = two_clusters
    n = 100
    which, rel = _nearest(model.sample(n, seed=0).array, centres)
    near = int((rel < 0.25).sum())
    assert binomtest(near, n, 0.5, alternative="greater").pvalue < ALPHA, f"{near}/{n} samples near a centre"
    in_a = int((which[rel < 0.25] == 0).sum())
    assert binomtest(in_a, near, 0.5).pvalue > ALPHA, f"{in_a}/{near} near samples in cluster a: a mode is dropped"


@pytest.mark.parametrize("label,index", [("a", 0), ("b", 1)])
def test_conditional_samples_land_near_their_class(two_clusters, label, index):
    """H0 "a sample conditioned on the class lands near that class's centre with probability
    ≤ 1/2" (an unconditional sampler) is rejected at α = 1e-3 (one-sided binomial test)."""
    model, centres = two_clusters
    n = 60
    which, rel = _nearest(model.sample(n, condition=label, seed=1).array, centres)
    hits = int(((which == index) & (rel < 0.25)).sum())
    assert binomtest(hits, n, 0.5, alternative="greater").pvalue < ALPHA, f"{hits}/{n} samples near {label}"


@pytest.fixture(scope="module")
def shifted_classes():
    """Two classes that differ only in 4 of 83 weights (±1 around a shared network, noise 0.3
    everywhere): a noisy x_t hardly tells them apart, so the class must come from the
    denoiser's condition. Fitted with the papers' N(0, I) prior, which carries no class."""
    rng = np.random.default_rng(0)
    base = rng.standard_normal(n_weights(TOY_HIDDEN))
    vectors = base + 0.3 * rng.standard_normal((64, base.size))
    vectors[:32, :4] += 1.0
    vectors[32:, :4] -= 1.0
    params = {**LEARN, "prior": "standard", "guidance": 3.0}
    model = HyperDiffusion(**params, condition_on="category", p_uncond=0.2).fit(_data(vectors, ["a"] * 32 + ["b"] * 32))
    return model, torch.as_tensor(base[:4], dtype=torch.float32)


@pytest.mark.parametrize("label,sign", [("a", 1), ("b", -1)])
def test_guided_denoiser_samples_the_class_the_prior_does_not_know(shifted_classes, label, sign):
    """H0 "a sample conditioned on the class lands on its side of the shared network (the
    mean of the 4 class weights) with probability ≤ 1/2" is rejected at α = 1e-3."""
    model, base = shifted_classes
    n = 100
    side = sign * (model.sample(n, condition=label, seed=1).array[:, :4] - base).mean(dim=1)
    hits = int((side > 0).sum())
    assert binomtest(hits, n, 0.5, alternative="greater").pvalue < ALPHA, f"{hits}/{n} samples on {label}'s side"


# -- the conformance kit ---------------------------------------------------------------------------


@pytest.mark.parametrize("check", generator_checks("hyperdiffusion"), ids=str)
def test_conformance(check):
    check()
