"""Constrained-synthesis categories (Zhou et al., C.3): statistics, thresholds and rules on
tables with known answers, a fitted representation, and a few synthetic materials."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.plugins import registry
from brdfbench.harness import lobes
from brdfbench.protocols.representation import Material, Representation
from brdfbench.data import categories as C

THETA_H = merl.grid_angles().theta_h.reshape(merl.SHAPE)[:, 0, 0].numpy()  # the 90 θh centres


def _table(base=(0.0, 0.0, 0.0), lobe=(1.0, 1.0, 1.0), peak=0.0, sigma=0.1, valid=None) -> merl.MerlTable:
    """base/π plus a Gaussian lobe in θh, peak × lobe colour × exp(−θh²/2σ²), on every cell."""
    gauss = np.exp(-THETA_H**2 / (2 * sigma**2))[:, None, None]
    rgb = [b / math.pi + peak * c * gauss for b, c in zip(base, lobe)]
    values = np.stack([np.broadcast_to(x, merl.SHAPE) for x in rgb])
    return merl.MerlTable.from_values(values, valid)


def _uniform(rgb) -> merl.MerlTable:
    return merl.MerlTable.from_values(np.broadcast_to(np.asarray(rgb, float).reshape(3, 1, 1, 1), (3, *merl.SHAPE)))


SHARP_WHITE = dict(base=(0.6, 0.1, 0.05), lobe=(1.0, 1.0, 1.0), peak=1000.0, sigma=0.05)
BROAD_COLOURED = dict(base=(0.1, 0.3, 0.5), lobe=(1.0, 0.4, 0.1), peak=50.0, sigma=0.35)


# --------------------------------------------------------------------------- rules on known tables


def test_categories_are_zhou_et_als_seven_in_order():
    assert C.CATEGORIES == ("diffuse", "metallic", "low-specular", "mid-specular", "high-specular", "plastic", "mirror")


def test_lambertian_albedo_half_is_diffuse_only():
    s = C.statistics(_uniform([0.5 / math.pi] * 3))
    assert s.max == pytest.approx((0.5 / math.pi,) * 3) and s.mean == pytest.approx((0.5 / math.pi,) * 3)
    assert s.n_exceeding == 0 and s.n_cells == int(merl.grid_above_horizon().sum())
    assert s.half_width == math.inf and s.specular_spread == 0.0
    assert C.classify(s) == {"diffuse"}


def test_bright_uniform_table_is_metallic_not_plastic():
    s = C.statistics(_uniform([3.0, 2.0, 1.5]))
    assert s.all_exceed and s.n_exceeding == s.n_cells
    assert C.classify(s) == {"metallic", "low-specular"}
    # White and bright everywhere: a specular part but no diffuse part, so not plastic either.
    assert C.categories(_uniform([2.0, 2.0, 2.0])) == {"metallic", "low-specular"}


def test_sharp_white_lobe_over_coloured_base_is_high_specular_plastic_mirror():
    s = C.statistics(_table(**SHARP_WHITE))
    assert s.max_norm == pytest.approx(1000 + 0.6 / math.pi, rel=1e-6)
    assert s.specular_spread == pytest.approx(0.55 / math.pi, rel=1e-6)  # the base's red − blue
    assert s.half_width == pytest.approx(0.05 * math.sqrt(2 * math.log(2)), abs=0.005)
    assert C.classify(s) == {"high-specular", "plastic", "mirror"}


def test_broad_coloured_lobe_is_low_specular_only():
    s = C.statistics(_table(**BROAD_COLOURED))
    assert 50 < s.max_norm < 51 and s.half_width > C.MIRROR_WIDTH
    assert s.specular_spread > C.PLASTIC_TOLERANCE * s.max_norm
    assert C.classify(s) == {"low-specular"}


@pytest.mark.parametrize("peak,expected", [(50.0, "low-specular"), (300.0, "mid-specular"), (700.0, "high-specular")])
def test_specular_ranges_use_the_published_thresholds(peak, expected):
    cats = C.categories(_table(base=(0.2, 0.2, 0.2), peak=peak, sigma=0.05))
    assert cats & {"low-specular", "mid-specular", "high-specular"} == {expected}


def test_few_exceptions_keep_a_material_diffuse():
    """e counts cells: a narrow lobe over fewer than 8e4 counted cells is still diffuse."""
    s = C.statistics(_table(base=(0.5, 0.5, 0.5), peak=5.0, sigma=0.001))
    assert 0 < s.n_exceeding < C.EXCEPTIONS
    assert "diffuse" in C.classify(s)
    wide = C.statistics(_table(base=(0.5, 0.5, 0.5), peak=5.0, sigma=0.2))
    assert wide.n_exceeding >= C.EXCEPTIONS and "diffuse" not in C.classify(wide)


def test_mirror_needs_a_specular_peak():
    """A dark row that halves quickly but never leaves the diffuse range has no lobe."""
    s = C.statistics(_table(base=(0.0, 0.0, 0.0), peak=0.05, sigma=0.05))
    assert s.half_width < C.MIRROR_WIDTH and s.lobe_peak < C.F_DIFFUSE
    assert "mirror" not in C.classify(s)


# --------------------------------------------------------------------------- lobe half-width


@pytest.mark.parametrize("sigma", [0.03, 0.1, 0.25, 0.5])
def test_half_width_of_a_gaussian_lobe_is_sigma_sqrt_2ln2(sigma):
    w_true = sigma * math.sqrt(2 * math.log(2))
    w = C.statistics(_table(peak=100.0, sigma=sigma)).half_width
    i = np.searchsorted(THETA_H, w_true)
    step = THETA_H[i] - THETA_H[i - 1]  # the sqrt-warped grid's spacing there
    assert abs(w - w_true) <= step


def test_half_width_edge_cases():
    th = np.linspace(0, 1.5, 16)
    assert C.lobe_half_width(th, np.ones(16)) == math.inf  # flat: never halves
    assert math.isnan(C.lobe_half_width(th, np.zeros(16)))  # no peak
    assert math.isnan(C.lobe_half_width(th, np.full(16, np.nan)))  # no valid sample
    # Linear interpolation between the samples around half.
    assert C.lobe_half_width([0.0, 0.1, 0.2], [4.0, 3.0, 1.0]) == pytest.approx(0.15)
    # Invalid samples are skipped; a rise at grazing after the first crossing is ignored.
    assert C.lobe_half_width([0.0, 0.1, 0.2, 0.3, 1.5], [4.0, np.nan, 2.0, 0.5, 3.0]) == pytest.approx(0.2)


@pytest.mark.parametrize("sigma", [0.02, 0.1])
def test_the_harness_records_the_width_the_rules_measure(sigma):
    table = _table(base=(0.05, 0.05, 0.05), peak=100.0, sigma=sigma)
    assert lobes.table_half_width(table) == C.statistics(table).half_width
    assert lobes.RES_THETA_H == merl.RES_THETA_H


def test_the_recorded_width_is_capped_or_absent_where_there_is_no_lobe():
    assert lobes.table_half_width(_uniform((0.2, 0.2, 0.2))) == pytest.approx(math.pi / 2)  # never halves
    assert lobes.table_half_width(_uniform((0.0, 0.0, 0.0))) is None  # no positive peak


# --------------------------------------------------------------------------- thresholds


def test_kmeans_boundaries_are_midpoints_in_the_gaps():
    groups = ([5.0, 6.0, 7.0], [200.0, 210.0, 220.0], [2000.0, 2100.0, 2200.0])
    values = [v for g in groups for v in g][::-1]
    (f1, f2), centres = C.kmeans_boundaries(values)
    assert centres == pytest.approx((6.0, 210.0, 2100.0))
    assert (f1, f2) == pytest.approx((108.0, 1155.0))
    assert C.kmeans_boundaries(values) == ((f1, f2), centres)  # deterministic


def test_kmeans_refuses_too_few_distinct_values_and_non_finite():
    with pytest.raises(ValueError, match="3 distinct"):
        C.kmeans_boundaries([1.0, 1.0, 2.0, 2.0])
    with pytest.raises(ValueError, match="finite"):
        C.kmeans_boundaries([1.0, 2.0, np.inf])


def test_thresholds_recover_the_gaps_between_clusters_of_max_reflectance():
    peaks = [10.0, 12.0, 14.0, 300.0, 320.0, 340.0, 3000.0, 3200.0, 3400.0]
    members = [_table(base=(0.2, 0.2, 0.2), peak=p, sigma=0.05) for p in peaks]
    t = C.thresholds(members)
    assert 14 < t.f_specular1 < 300 and 340 < t.f_specular2 < 3000
    assert t.f_diffuse == C.F_DIFFUSE and len(t.centres) == 3 and "K-means" in t.source
    # Each reference member falls in its own cluster's class.
    counts = C.count_categories(members, t)
    assert (counts["low-specular"], counts["mid-specular"], counts["high-specular"]) == (3, 3, 3)


def test_small_reference_set_falls_back_to_published_thresholds():
    members = [_table(peak=p) for p in (10.0, 200.0)]
    with pytest.warns(UserWarning, match="too small"):
        t = C.thresholds(members)
    assert (t.f_specular1, t.f_specular2) == C.PUBLISHED_SPECULAR == (C.PUBLISHED.f_specular1, C.PUBLISHED.f_specular2)
    assert "published" in t.source and "2 members" in t.source


def test_thresholds_validate():
    with pytest.raises(ValueError, match="empty"):
        C.thresholds([])
    with pytest.raises(ValueError, match="f_specular1"):
        C.Thresholds(f_specular1=600.0, f_specular2=100.0)
    with pytest.raises(ValueError, match="channel"):
        C.Thresholds(channel="alpha")
    with pytest.raises(ValueError, match="f_diffuse"):
        C.Thresholds(f_diffuse=float("nan"))
    s = C.statistics(_uniform([0.1] * 3), f_diffuse=1.0)
    with pytest.raises(ValueError, match="f_diffuse"):
        C.classify(s, C.PUBLISHED)  # statistics taken at another f_diffuse
    assert C.classify(s, C.Thresholds(f_diffuse=1.0)) == {"diffuse"}


def test_channel_picks_the_statistic_of_the_specular_ranges():
    """A blue lobe: ‖f‖∞ puts it high, the red channel (Zhou et al., Fig. 21) low."""
    s = C.statistics(_table(base=(0.2, 0.2, 0.2), lobe=(0.05, 0.1, 1.0), peak=1000.0, sigma=0.05))
    assert s.max_of("blue") == s.max_norm > 1000 > 100 > s.max_of("red") > 50
    assert "high-specular" in C.classify(s, C.Thresholds(channel="max"))
    assert "low-specular" in C.classify(s, C.Thresholds(channel="red"))


# --------------------------------------------------------------------------- bad input


class _Nan(Representation):
    def _eval(self, wi, wo):
        return torch.full((wi.shape[0], 3), float("nan"), dtype=wi.dtype)

    def fit(self, target, *, seed=0):
        return self

    def state_dict(self):
        return {}

    @classmethod
    def from_state(cls, params, tensors, metadata):
        return cls()


def test_bad_members_are_named_by_index():
    good = _uniform([0.1] * 3)
    no_valid = merl.MerlTable(np.full((3, *merl.SHAPE), merl.INVALID_RAW))
    with pytest.raises(ValueError, match="member 1: no valid cell"):
        C.count_categories([good, no_valid])
    raw = good.raw.copy()
    raw[1, 3, 4, 5] = np.nan
    with pytest.raises(ValueError, match=r"member 2: non-finite table value at channel 1, cell \(3, 4, 5\)"):
        C.thresholds([good, good, merl.MerlTable(raw)])
    with pytest.raises(ValueError, match="member 1: non-finite value"):
        C.count_categories([good, _Nan()])
    with pytest.raises(TypeError, match="member 0: expected a MerlTable"):
        C.count_categories([np.zeros(3)])


def test_invalid_cells_are_not_counted():
    valid = np.ones(merl.SHAPE, dtype=bool)
    valid[:, 80:, :] = False
    s = C.statistics(_table(base=(0.5, 0.5, 0.5), valid=valid))
    assert s.n_cells == int((valid.reshape(-1) & merl.grid_above_horizon().numpy()).sum())


# --------------------------------------------------------------------------- tables, fits, counts


@pytest.mark.parametrize("params", [SHARP_WHITE, BROAD_COLOURED], ids=["sharp-white", "broad-coloured"])
def test_table_and_its_fitted_merl_representation_agree(params):
    table = _table(**params)
    rep = registry.get("representations", "merl").create().fit(Material("lobe", table))
    a, b = C.statistics(table), C.statistics(rep)
    assert b.max == a.max and b.mean == pytest.approx(a.mean, rel=1e-9)  # summed in chunks
    assert (b.n_cells, b.n_exceeding, b.min_norm) == (a.n_cells, a.n_exceeding, a.min_norm)
    assert b.half_width == pytest.approx(a.half_width, rel=1e-12)
    assert b.specular_spread == pytest.approx(a.specular_spread, rel=1e-12)
    assert C.classify(a) == C.classify(b)
    assert C.categories(Material("lobe", table)) == C.classify(a)


def test_count_categories_lists_all_seven_with_zeros():
    counts = C.count_categories([_uniform([0.1] * 3), _uniform([0.15] * 3), _table(**SHARP_WHITE)])
    assert list(counts) == list(C.CATEGORIES)
    assert counts == {"diffuse": 2, "metallic": 0, "low-specular": 0, "mid-specular": 0,
                      "high-specular": 1, "plastic": 1, "mirror": 1}
    assert C.count_categories([]) == dict.fromkeys(C.CATEGORIES, 0)


def test_synthetic_materials_sanity():
    """A felt, a phenolic, a gold and a chrome of the embedded set, at the published thresholds."""
    from brdfbench.data.synthetic import generate_material

    found = {}
    for i in (7, 9, 11):
        name, _, table = generate_material(i, seed=0)
        found[name.split("-")[1]] = C.categories(table)
    assert "diffuse" in found["fabric"]
    assert {"high-specular", "plastic", "mirror"} <= found["phenolic"]
    assert "plastic" not in found["metal"] and "diffuse" not in found["metal"]  # gold: a coloured lobe
