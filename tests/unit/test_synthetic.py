"""The embedded synthetic dataset: determinism, MERL validity, caching and physics sanity."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.data import Dataset
from brdfbench.data import synthetic as S
from brdfbench.errors import ConfigError


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """The 'small' dataset in a fresh cache, every material loaded once (generated, written, read back)."""
    cache = tmp_path_factory.mktemp("cache")
    ds = S.synthetic_dataset("small", seed=0, cache_dir=str(cache))
    return cache, ds, [ds.load(name) for name in ds.materials]


@pytest.fixture(scope="module")
def grid():
    """Cell-centre direction pairs straight from brdfbench.merl (independent of the generator's cache)."""
    wi, wo = merl.grid_directions()
    return wi, wo, ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy().reshape(merl.SHAPE)


# --------------------------------------------------------------------------- dataset shape


def test_small_dataset_metadata(small):
    cache, ds, mats = small
    assert isinstance(ds, Dataset) and ds.name == "synthetic" and len(ds) == 6
    # a set other than the default 24 is other data: its size is in the fingerprint
    assert ds.fingerprint == f"synthetic-{S.GENERATOR_VERSION}-seed0-n6"
    assert S.synthetic_dataset("default", seed=0, cache_dir=str(cache)).fingerprint == f"synthetic-{S.GENERATOR_VERSION}-seed0"
    assert set(ds.categories.values()) == set(S.CATEGORIES)
    assert len(set(ds.materials)) == 6
    for m in mats:
        assert m.category == ds.categories[m.name]
        assert m.name.startswith(f"synth-{m.category}-")
        assert m.source == str(cache / "synthetic" / f"{S.GENERATOR_VERSION}-seed0" / f"{m.name}.binary")


def test_default_size_and_any_size_contains_all_categories():
    names = S.material_names("default")
    assert len(names) == 24 and len(set(names)) == 24
    for n in (6, 7, 13):
        cats = S.synthetic_dataset(n).categories
        assert set(cats.values()) == set(S.CATEGORIES)
    assert S.synthetic_dataset("12").materials == S.material_names(12)


@pytest.mark.parametrize("size", ["huge", "", 0, -3, 1001, 2.5, True, None, "0"])
def test_bad_size_raises_config_error_naming_value(size):
    with pytest.raises(ConfigError) as info:
        S.synthetic_dataset(size)
    assert repr(size) in str(info.value)


@pytest.mark.parametrize("seed", [-1, 1.5, "zero", True])
def test_bad_seed_raises_config_error(seed):
    with pytest.raises(ConfigError, match="seed"):
        S.synthetic_dataset("small", seed=seed)


def test_cache_root_precedence(monkeypatch, tmp_path):
    monkeypatch.setenv("BRDFBENCH_CACHE", str(tmp_path / "env"))
    assert S.cache_root(str(tmp_path / "arg")) == tmp_path / "arg"
    assert S.cache_root() == tmp_path / "env"
    monkeypatch.delenv("BRDFBENCH_CACHE")
    assert S.cache_root() == Path("~/.cache/brdfbench").expanduser()


# --------------------------------------------------------------------------- determinism


def test_same_seed_same_bytes_and_size_independent(small, tmp_path):
    cache, ds6, _ = small
    names6 = ds6.materials
    ds8 = S.synthetic_dataset(8, seed=0, cache_dir=str(tmp_path))
    assert ds8.materials[:6] == names6
    last = names6[-1]
    a = Path(ds6.load(last).source).read_bytes()
    b = Path(ds8.load(last).source).read_bytes()
    assert a == b


def test_different_seeds_differ(small):
    _, ds, mats = small
    assert all(S.material_params(i, 1) != S.material_params(i, 0) for i in range(6))
    assert S.material_names(6, 1) != ds.materials
    name1, cat1, table1 = S.generate_material(0, seed=1)
    assert cat1 == mats[0].category  # the category cycle does not depend on the seed
    assert not np.array_equal(table1.raw, mats[0].table.raw)


def test_file_round_trip_equals_generated_table(small):
    _, _, mats = small
    name, category, table = S.generate_material(1, seed=0)
    assert (name, category) == (mats[1].name, mats[1].category)
    assert np.array_equal(table.raw, mats[1].table.raw)
    reread = merl.read_binary(mats[1].source)
    assert np.array_equal(reread.raw, table.raw)


# --------------------------------------------------------------------------- MERL validity


def test_values_finite_non_negative_and_plausible(small):
    _, _, mats = small
    for m in mats:
        raw = m.table.raw
        assert np.isfinite(raw).all()
        valid = m.table.valid
        v = m.table.values[:, valid]
        assert (v >= 0).all(), m.name
        assert 0.005 < np.median(v) < 1.0, m.name
        assert v.max() < 2e4, m.name
        # invalid cells are marked exactly as the reference does: negative in every channel
        assert (raw[:, ~valid] < 0).all()


def test_below_horizon_cells_are_invalid(small, grid):
    _, _, mats = small
    wi, wo, _ = grid
    below = ((wi[:, 2] <= 0) | (wo[:, 2] <= 0)).numpy().reshape(merl.SHAPE)
    assert below.any() and not below.all()
    for m in mats:
        assert not m.table.valid[below].any(), m.name


def test_invalid_grazing_fraction_small_but_nonzero(small, grid):
    _, _, mats = small
    wi, wo, above = grid
    cos_max = math.cos(math.radians(S.GRAZING_DEG))
    grazing = above & ((wi[:, 2] < cos_max) | (wo[:, 2] < cos_max)).numpy().reshape(merl.SHAPE)
    for m in mats:
        dropped = above & ~m.table.valid
        assert not dropped[~grazing].any(), f"{m.name}: invalid cells away from grazing angles"
        frac = dropped.sum() / grazing.sum()
        assert 0.0003 < frac < 0.03, (m.name, frac)


def test_reciprocity_of_table_and_of_the_generator(small):
    _, _, mats = small
    g = torch.Generator().manual_seed(7)
    n = 2000
    theta = torch.rand(2, n, generator=g, dtype=torch.float64) * (math.pi / 2)
    phi = torch.rand(2, n, generator=g, dtype=torch.float64) * (2 * math.pi)
    dirs = torch.stack((torch.sin(theta) * torch.cos(phi), torch.sin(theta) * torch.sin(phi), torch.cos(theta)), -1)
    wi, wo = dirs[0], dirs[1]
    for i, m in enumerate(mats):
        assert torch.equal(m.table.lookup(wi, wo), m.table.lookup(wo, wi)), m.name
        p = S.material_params(i, 0)
        fwd = S.evaluate(p, S.geometry(wi, wo))
        bwd = S.evaluate(p, S.geometry(wo, wi))
        torch.testing.assert_close(fwd, bwd, rtol=1e-12, atol=0.0)


def test_grid_evaluation_matches_direct_evaluation(grid):
    """The broadcast grid fast path equals evaluating at the grid's direction pairs."""
    g, above, _ = S.grid_geometry()
    wi, wo, expected_above = grid
    assert np.array_equal(above, expected_above)
    idx = torch.randint(0, merl.N_CELLS, (20_000,), generator=torch.Generator().manual_seed(3))
    flat = S.geometry(wi[idx], wo[idx])
    for i in (0, 3):  # coated + two lobes; fabric with Oren–Nayar, sheen and retro-reflection
        p = S.material_params(i, 0)
        grid = S.evaluate(p, g).reshape(3, -1)[:, idx]
        torch.testing.assert_close(grid, S.evaluate(p, flat), rtol=1e-10, atol=1e-14)


# --------------------------------------------------------------------------- caching


def test_second_call_reuses_cache(small, monkeypatch):
    cache, ds, mats = small
    mtimes = {m.name: Path(m.source).stat().st_mtime_ns for m in mats}

    def boom(*args, **kwargs):
        raise AssertionError("regenerated a cached material")

    monkeypatch.setattr(S, "generate_material", boom)
    again = S.synthetic_dataset("small", seed=0, cache_dir=str(cache))
    for name in again.materials:
        m = again.load(name)
        assert Path(m.source).stat().st_mtime_ns == mtimes[name]
        assert np.array_equal(m.table.raw, mats[ds.materials.index(name)].table.raw)


def test_damaged_cache_file_is_regenerated(tmp_path):
    ds = S.synthetic_dataset(1, cache_dir=str(tmp_path))
    name = ds.materials[0]
    folder = tmp_path / "synthetic" / f"{S.GENERATOR_VERSION}-seed0"
    folder.mkdir(parents=True)
    (folder / f"{name}.binary").write_bytes(b"\x00" * 100)
    m = ds.load(name)
    assert m.table.raw.shape == (3, *merl.SHAPE)
    assert (folder / f"{name}.binary").stat().st_size == merl.FILE_BYTES


def test_tampered_cache_file_is_regenerated_with_a_warning(tmp_path, caplog):
    """A valid MERL file of the same size put in the cache is not this material: regenerate it."""
    ds = S.synthetic_dataset(1, cache_dir=str(tmp_path))
    name = ds.materials[0]
    original = ds.load(name).table.raw
    path = tmp_path / "synthetic" / f"{S.GENERATOR_VERSION}-seed0" / f"{name}.binary"
    merl.write_binary(path, merl.MerlTable(np.full((3, *merl.SHAPE), 0.5)))
    assert path.stat().st_size == merl.FILE_BYTES
    again = S.synthetic_dataset(1, cache_dir=str(tmp_path))
    with caplog.at_level("WARNING", logger="brdfbench.data.synthetic"):
        m = again.load(name)
    assert np.array_equal(m.table.raw, original)
    assert any(str(path) in r.getMessage() and "regenerating" in r.getMessage() for r in caplog.records)
    assert again.fingerprint == ds.fingerprint == f"synthetic-{S.GENERATOR_VERSION}-seed0-n{len(ds)}"


def test_untampered_cache_is_reused_and_its_digest_cached(tmp_path, monkeypatch):
    from brdfbench.data import content_hash

    ds = S.synthetic_dataset(1, cache_dir=str(tmp_path))
    name = ds.materials[0]
    ds.load(name)
    path = tmp_path / "synthetic" / f"{S.GENERATOR_VERSION}-seed0" / f"{name}.binary"
    assert (path.parent / f"{name}.binary.sha256").read_text().strip() == content_hash.sha256_file(path)
    old = 1_000_000_000 * 10**9
    os.utime(path, ns=(old, old))  # settled: its digest may be cached
    S.synthetic_dataset(1, cache_dir=str(tmp_path)).load(name)

    def boom(*args, **kwargs):
        raise AssertionError("regenerated or re-hashed an untampered cache file")

    monkeypatch.setattr(S, "generate_material", boom)
    monkeypatch.setattr(content_hash, "sha256_file", boom)
    assert S.synthetic_dataset(1, cache_dir=str(tmp_path)).load(name).source == str(path)


def test_cache_file_without_a_record_is_regenerated_and_compared(tmp_path, caplog):
    ds = S.synthetic_dataset(1, cache_dir=str(tmp_path))
    name = ds.materials[0]
    original = ds.load(name).table.raw
    folder = tmp_path / "synthetic" / f"{S.GENERATOR_VERSION}-seed0"
    record = folder / f"{name}.binary.sha256"
    record.unlink()  # as a cache written before records existed
    with caplog.at_level("WARNING", logger="brdfbench.data.synthetic"):
        assert np.array_equal(ds.load(name).table.raw, original)
    assert record.is_file() and not caplog.records  # identical bytes: nothing to warn about
    record.unlink()
    merl.write_binary(folder / f"{name}.binary", merl.MerlTable(np.full((3, *merl.SHAPE), 0.5)))
    with caplog.at_level("WARNING", logger="brdfbench.data.synthetic"):
        assert np.array_equal(ds.load(name).table.raw, original)
    assert any("differed from the generator" in r.getMessage() for r in caplog.records)


# --------------------------------------------------------------------------- physics sanity


def test_distributions_are_normalised():
    theta = torch.linspace(0, math.pi / 2, 100_001, dtype=torch.float64)
    fres = S.Fresnel("dielectric")
    for lobe in (
        S.Lobe("sgd", 0.03**2, 1.2, (1, 1, 1), fres),
        S.Lobe("sgd", 0.4**2, 0.3, (1, 1, 1), fres),
        S.Lobe("abc", 2 / 0.05**2, 1.0, (1, 1, 1), fres),  # b = 1: the closed form's log case
        S.Lobe("abc", 2 / 0.5**2, 2.0, (1, 1, 1), fres),  # b = 2: the other log case
        S.Lobe("abc", 2 / 0.2**2, 0.6, (1, 1, 1), fres),
    ):
        d = S.distribution(lobe, torch.cos(theta))
        total = 2 * math.pi * torch.trapezoid(d * torch.cos(theta) * torch.sin(theta), theta)
        assert abs(float(total) - 1) < 1e-4, lobe


def test_smith_shadowing_matches_exact_beckmann():
    """With b = 0 the shifted-gamma lobe is Beckmann, whose Smith Λ has a closed form."""
    from scipy.special import erf

    m = 0.2
    lobe = S.Lobe("sgd", m * m, 0.0, (1, 1, 1), S.Fresnel("dielectric"))
    c = np.linspace(0.01, 0.99, 97)
    nu = c / np.sqrt(1 - c * c) / m
    lam = (erf(nu) - 1) / 2 + np.exp(-nu * nu) / (2 * nu * np.sqrt(np.pi))
    ci, co = torch.from_numpy(c), torch.from_numpy(c[::-1].copy())
    expected = 1 / (1 + lam + lam[::-1])
    np.testing.assert_allclose(S.smith_g2(lobe, ci, co).numpy(), expected, atol=2e-5)


def test_fresnel_limits():
    c = torch.tensor([1.0, 0.5, 1e-9], dtype=torch.float64)
    # conductor at normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2)
    n, k = (0.15, 0.42, 1.37), (3.7, 2.4, 1.75)
    f = S.fresnel(S.Fresnel("conductor", eta=n, k=k), c)
    expected = [((a - 1) ** 2 + b**2) / ((a + 1) ** 2 + b**2) for a, b in zip(n, k)]
    torch.testing.assert_close(f[:, 0], torch.tensor(expected, dtype=torch.float64))
    # a conductor with k = 0 is a dielectric; both reach 1 at grazing
    d = S.fresnel(S.Fresnel("dielectric", eta=(1.5,) * 3), c)
    torch.testing.assert_close(S.fresnel(S.Fresnel("conductor", eta=(1.5,) * 3, k=(0.0,) * 3), c), d)
    torch.testing.assert_close(d[:, 0], torch.full((3,), 0.04, dtype=torch.float64))
    assert (d[:, 2] > 0.999999).all() and (f[:, 2] > 0.999999).all()


def test_tabulated_coat_transmission_matches_fresnel():
    c = torch.rand(10_000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    c = torch.cat([c, c * 1e-4, torch.tensor([0.0, 1.0], dtype=torch.float64)])  # incl. near grazing
    direct = 1 - S.fresnel(S.Fresnel("dielectric", eta=(1.5,) * 3), c)[0]
    torch.testing.assert_close(S.coat_transmission(1.5, c), direct, rtol=1e-5, atol=1e-12)


def test_entry_point_spec_builds_the_dataset(tmp_path):
    from brdfbench.data.specs import SYNTHETIC

    ds = SYNTHETIC.load()(size="small", seed=3, cache_dir=str(tmp_path))
    assert ds.materials == S.material_names("small", 3) and ds.fingerprint.endswith("seed3-n6")


def _ggx_fit_residual(values: np.ndarray, cells: np.ndarray) -> float:
    """Best relative RMS error of kd + ks·GGX microfacet term (Smith-GGX G2) over `cells`."""
    from scipy.optimize import minimize_scalar

    g, _, _ = S.grid_geometry()
    ch = np.broadcast_to(g.cos_h.numpy(), merl.SHAPE)[cells]
    ci, co = g.cos_i.numpy()[cells], g.cos_o.numpy()[cells]
    y = values[cells]

    def residual(log_alpha):
        a2 = math.exp(2 * log_alpha)
        d = a2 / (math.pi * (ch * ch * (a2 - 1) + 1) ** 2)
        lam = lambda c: (np.sqrt(1 + a2 * (1 - c * c) / (c * c)) - 1) / 2  # noqa: E731
        basis = d / (1 + lam(ci) + lam(co)) / (4 * ci * co)
        a = np.stack([np.ones_like(basis), basis], 1) / y[:, None]
        coef = np.linalg.lstsq(a, np.ones_like(y), rcond=None)[0]
        coef = np.clip(coef, 0, None)  # physically meaningful weights only
        return float(np.sqrt(np.mean((a @ coef - 1) ** 2)))

    best = min((residual(la), la) for la in np.linspace(math.log(1e-3), 0, 15))
    res = minimize_scalar(residual, bounds=(best[1] - 0.5, best[1] + 0.5), method="bounded", options={"xatol": 1e-3})
    return min(best[0], float(res.fun))


def test_not_exactly_a_single_lambert_plus_ggx(small):
    """Near the specular peak (θd < 10°, θh < 60°, where Fresnel is ~constant) a GGX lobe
    plus a constant fits an exact GGX table almost perfectly, but not the synthetic metals."""
    _, _, mats = small
    g, above, _ = S.grid_geometry()
    cells = np.zeros_like(above)
    cells[:, :10, ::5] = True  # near θd = 0 the value hardly depends on φd: every 5th is plenty
    cells &= above
    cells &= np.broadcast_to(g.cos_h.numpy(), merl.SHAPE) > math.cos(math.radians(60))

    # control: the fitter recovers an exact GGX lobe (so the test below can fail)
    ch = np.broadcast_to(g.cos_h.numpy(), merl.SHAPE)
    a2 = 0.13**2
    lam = lambda c: (np.sqrt(1 + a2 * (1 - c * c) / (c * c)) - 1) / 2  # noqa: E731
    ci, co = g.cos_i.numpy().clip(1e-9), g.cos_o.numpy().clip(1e-9)
    ggx = 0.02 + 0.7 * a2 / (math.pi * (ch * ch * (a2 - 1) + 1) ** 2) / (1 + lam(ci) + lam(co)) / (4 * ci * co)
    assert _ggx_fit_residual(ggx, cells) < 0.01

    metals = [m for m in mats if m.category in ("metal", "phenolic", "metallic-paint")]
    residuals = [_ggx_fit_residual(m.table.values.mean(0), cells & m.table.valid) for m in metals]
    assert max(residuals) > 0.1, residuals
