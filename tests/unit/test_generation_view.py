"""The generation section of the report, from a store written by hand: Table 1's rows and
columns, intervals over draws, the published figures in their display scale, the ceiling
row never marked best, and both renderers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row
from brdfbench_leaderboard import generation_render, markdown, view
from brdfbench_leaderboard.generation_view import GenerationSection, draw_cell

CONFIGS = {"h_train": ("training_set", "training_set"), "h_pcan": ("pca_nbrdf", "pca_nbrdf"),
           "h_hyper": ("hyperdiffusion", "hyperdiffusion")}
#: (metric, distance, unit, higher_is_better, category) -> figure per config and draw
FIGURES = {
    ("mmd", "l1", "1/sr", False, "set"): {"h_train": [0.2, 0.22, 0.24], "h_pcan": [0.5, 0.6, 0.7],
                                          "h_hyper": [0.3, 0.35, 0.4]},
    ("cov", "rmse", "%", True, "set"): {"h_train": [60, 62, 64], "h_pcan": [30, 30, 30], "h_hyper": [50, 52, 54]},
    ("one_nna", "l1", "% (ideal 50)", False, "set"): {"h_train": [50, 50, 50], "h_pcan": [95, 96, 97],
                                                      "h_hyper": [40, 41, 42]},
    ("category_count", "", "samples", False, "mirror"): {"h_train": [3, 3, 3], "h_pcan": [1, 2, 3],
                                                         "h_hyper": [0, 0, 0]},
}


@pytest.fixture(scope="module")
def section(tmp_path_factory) -> GenerationSection:
    store = ResultsStore(tmp_path_factory.mktemp("gen") / "brdfbench.sqlite")
    for h, (label, plugin) in CONFIGS.items():
        store.write_config(ConfigRecord(h, label, plugin, "0.1.0", "generation", {"generator": plugin}))
        for draw in range(3):
            rows = [Row(run_id="r", config_hash=h, dataset="neumerl", dataset_fingerprint="fp", material=f"draw-{draw}",
                        category=cat, metric=m, value=float(v[h][draw]), unit=unit, higher_is_better=hib,
                        status="ok", message="", seed=0, package_version="0.1.0", git_sha="abc", timestamp=1.0,
                        scope="set", distance=d)
                    for (m, d, unit, hib, cat), v in FIGURES.items()]
            store.write_cell(rows)
    report = view.build(store.frame(), "test")
    (s,) = report.sections
    return s


def test_columns_follow_table_1_and_figures_are_means_over_draws_with_t_intervals(section):
    assert section.kind == "generation" and section.draws == 3
    assert [c.plugin for c in section.columns] == ["training_set", "pca_nbrdf", "hyperdiffusion"]
    mmd = next(r for r in section.rows if r.metric == "mmd")
    cell = mmd.cells["h_pcan"]
    x = np.array([0.5, 0.6, 0.7])
    half = stats.t.ppf(0.975, 2) * x.std(ddof=1) / np.sqrt(3)
    assert cell.value == pytest.approx(0.6) and cell.n == 3
    assert (cell.lo, cell.hi) == pytest.approx((0.6 - half, 0.6 + half))


def test_published_figures_sit_beside_ours_in_the_paper_display_scale(section):
    mmd = next(r for r in section.rows if r.metric == "mmd" and r.distance == "l1")
    assert mmd.label == "MMD BRDF-L1 (×0.001)" and mmd.scale == 1e-3
    assert mmd.published == {"h_train": 2.51, "h_pcan": 9.22, "h_hyper": 4.02}  # Hu 2026, Table 4.5
    cov = next(r for r in section.rows if r.metric == "cov")
    assert cov.published["h_hyper"] == 50.0 and cov.scale == 1.0


def test_the_training_set_is_the_ceiling_never_the_best(section):
    mmd = next(r for r in section.rows if r.metric == "mmd")
    assert mmd.best() == "h_train" and mmd.best(section.ceilings) == "h_hyper"
    nna = next(r for r in section.rows if r.metric == "one_nna")
    assert nna.best(section.ceilings) == "h_hyper"  # 41 is closer to 50 than 96
    assert section.categories[0].label == "mirror" and section.categories[0].best(section.ceilings) is None


def test_both_renderers_draw_the_section(section):
    md = "\n".join(generation_render.markdown(section))
    assert "| MMD BRDF-L1 (×0.001) ↓ | 2.200e-04 [1.703e-04, 2.697e-04] (2.51) | 6.000e-04 [" in md
    assert "| COV % RMSE ↑ | 62 [57.03, 66.97] (55.8) | 30 (28.3) |" in md  # one value over draws: no interval
    assert "**3.500e-04" in md and "1-NNA % BRDF-L1 →50" in md and "| mirror | 3 | 2 | 0 |" in md
    page = "\n".join(generation_render.html_section(section, "s0"))
    assert page.count('class="best"') == 3 and "paper 9.22" in page
    assert "Dataset `neumerl`: generators" in markdown.render_view(view.Report("t", "now", [], [], [section], False))


def test_one_draw_has_no_interval_and_equal_draws_a_zero_width_one():
    one = draw_cell(np.array([0.4]))
    assert (one.value, one.lo, one.hi, one.n) == (0.4, None, None, 1)
    same = draw_cell(np.array([30.0, 30.0, 30.0]))
    assert (same.lo, same.hi, same.n) == (30.0, 30.0, 3)
