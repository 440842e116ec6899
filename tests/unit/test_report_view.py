"""The report's view model and its two renderers: intervals, missing materials, the Pareto
front, the published figures, and bad input (empty store, unknown units, unreadable data)."""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from brdfbench import citations
from brdfbench_leaderboard import html, lobe_svg, markdown, pareto, published, published_data, view

ALPHA = 0.01  # significance level of the statistical checks here


def _frame(reps=(("good", 0.1, 10.0, 2000), ("fast", 0.5, 0.01, 24)), materials=("a", "b", "c")) -> pd.DataFrame:
    rows = []
    for rep, err, fit, size in reps:
        for i, mat in enumerate(materials):
            cell = dict(representation=rep, config_hash=f"h-{rep}", plugin=rep, params="{}", material=mat,
                        category="metal" if i % 2 else "plastic")
            rows += [dict(cell, metric="l1_log_cos", value=err * (1 + 0.1 * i), unit="log", higher_is_better=False),
                     dict(cell, metric="fit_time", value=fit, unit="s", higher_is_better=False),
                     dict(cell, metric="evals_per_s", value=1e6 / fit, unit="evals/s", higher_is_better=True),
                     dict(cell, metric="model_bytes", value=float(size), unit="B", higher_is_better=False)]
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"] = "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    df["scene"], df["harness"], df["sampler"], df["spp"], df["concurrent_jobs"] = "brdf_space", "accuracy", "", 0, 1
    return df


def test_bootstrap_interval_is_seeded_and_brackets_the_mean():
    values = np.random.default_rng(3).lognormal(size=40)
    lo, hi = view.bootstrap_interval(values)
    assert lo < values.mean() < hi
    assert (lo, hi) == view.bootstrap_interval(values)  # the same store gives the same report


def test_bootstrap_interval_covers_the_true_mean_at_its_level():
    """Over 300 samples of 30 normal values, a 95 % interval must cover the true mean in
    about 95 % of them; the percentile bootstrap runs a little narrow at n = 30, so the test
    is one-sided against 90 % at ALPHA."""
    rng = np.random.default_rng(11)
    covered = sum(lo <= 0.0 <= hi for lo, hi in (view.bootstrap_interval(rng.normal(size=30), resamples=1000,
                                                                          seed=k) for k in range(300)))
    assert stats.binomtest(covered, 300, 0.90, alternative="less").pvalue > ALPHA, covered


def test_a_missing_material_leaves_no_mean_and_no_rank():
    df = _frame()
    df = df[~((df.representation == "good") & (df.material == "c"))]
    section = view.build(df, "s").sections[0]
    good = next(r for r in section.rows if r.label == "good")
    cell = good.cell("l1_log_cos")
    assert cell.value is None and cell.missing == 1 and cell.partial == pytest.approx(0.1 * 1.05)
    assert good.rank is None and section.rows[-1] is good  # the complete one ranks; the other follows
    line = next(line for line in markdown.render(df, "s").splitlines() if line.startswith("| – | `good`"))
    assert "– (0.105 over 2/3)" in line


def test_cost_columns_follow_their_aggregate_and_direction():
    section = view.build(_frame(), "s").sections[0]
    metrics = section.metrics
    assert metrics["evals_per_s"].higher_is_better and metrics["evals_per_s"].aggregate == "median"
    assert [r.label for r in section.ranking("evals_per_s")] == ["fast", "good"]
    assert [r.label for r in section.rows] == ["good", "fast"]  # ranked by accuracy


def test_categories_break_down_the_ranking_metric():
    section = view.build(_frame(), "s").sections[0]
    assert [c.name for c in section.categories] == ["metal", "plastic"]
    metal = section.categories[0]
    assert metal.materials == 1 and metal.cells["h-good"].value == pytest.approx(0.11)


def _points(xs, ys):
    return [pareto.Point(None, x, y, None, None) for x, y in zip(xs, ys)]


def test_pareto_front_of_a_known_set():
    pts = _points([1, 2, 3, 4, 5], [5, 3, 4, 1, 2])
    front = pareto.pareto_front(pts, x_higher_is_better=False, y_higher_is_better=False)
    assert [(p.x, p.y) for p in front] == [(1, 5), (2, 3), (4, 1)]
    front = pareto.pareto_front(pts, x_higher_is_better=True, y_higher_is_better=False)
    assert [(p.x, p.y) for p in front] == [(5, 2), (4, 1)]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(0.01, 100), st.floats(0.01, 100)), min_size=1, max_size=12),
       st.booleans(), st.booleans())
def test_pareto_front_is_exactly_the_undominated_points(pairs, x_up, y_up):
    pts = _points(*zip(*pairs))
    front = {(p.x, p.y) for p in pareto.pareto_front(pts, x_up, y_up)}

    def beats(a, b):  # a at least as good on both axes and better on one
        ge = (a.x >= b.x if x_up else a.x <= b.x) and (a.y >= b.y if y_up else a.y <= b.y)
        return ge and (a.x, a.y) != (b.x, b.y)

    undominated = {(p.x, p.y) for p in pts if not any(beats(q, p) for q in pts)}
    assert front == undominated


def test_chart_leaves_out_incomplete_and_non_positive_figures():
    df = _frame()
    df.loc[(df.representation == "fast") & (df.metric == "fit_time"), "value"] = 0.0
    c = pareto.chart(view.build(df, "s").sections[0])
    fit = next(p for p in c.panels if p.cost.name == "fit_time")
    assert [p.row.label for p in fit.points] == ["good"] and fit.omitted == ["fast"]


def test_published_agreement_rules():
    assert published.agreement(1.5, 1.0, "hdr_rmse", "1/sr")[0]
    assert not published.agreement(3.0, 1.0, "hdr_rmse", "1/sr")[0]
    assert published.agreement(30.0, 28.0, "psnr_ldr", "dB")[0] and not published.agreement(33.0, 28.0, "psnr_ldr", "dB")[0]
    assert published.agreement(0.98, 0.99, "ssim_ldr", "1")[0] and not published.agreement(0.95, 0.99, "ssim_ldr", "1")[0]


def test_every_match_names_a_published_row_with_its_source():
    figures = published.figures()
    for m in published.matches():
        p = published.find(m, figures)
        assert p is not None, m
        assert p.source.startswith("seed 00")  # the data's key; a report shows the citation
        where, _ = published.citation(p.source, p.table)
        assert where.split(",")[0] in {c.short for c in citations.PAPERS.values()}, where


def test_published_figures_beside_ours_say_whether_they_reproduce():
    df = _frame(reps=(("nbrdf", 0.01, 1.0, 2700),))
    df = pd.concat([df, df[df.metric == "l1_log_cos"].assign(metric="hdr_rmse", value=0.65, unit="1/sr")])
    report = view.build(df, "s")
    rows = {(c.match.table, c.match.metric): c for c in published.compare(report) if c.match.representation == "nbrdf"}
    # 0.65 beside Timonen et al.'s 0.6534, but over synthetic materials on this project's recipe:
    # no verdict, the mismatch named (the factor-of-two rule is in test_published_verdicts)
    assert rows[("Table 4", "RMSE-HDR")].verdict == "not comparable (dataset, recipe)"
    assert rows[("Table 3", "total memory")].verdict == "agrees"  # 2700 B beside 2.25 kB
    assert rows[("Table 4.1", "PSNR")].verdict == "not measured"  # no rendered section here
    page = html.render(df, "s")
    assert "Timonen et al., Table 4" in page and "agrees" in page
    assert not citations.LABEL.search(page)  # the papers by author, never by internal label
    # the recipe behind each of our figures: the configuration is named, and the section says
    # which configurations train on the papers' own recipes
    assert "<code>triplane_gated_paper</code>" in page and "papers&#x27; own recipes" in page
    assert all(name in published.PUBLISHED_RECIPES for name in ("nbrdf_reference", "hyperdiffusion_paper"))


def test_a_published_match_without_its_row_is_reported(monkeypatch):
    bogus = published.Match("seed 002", "Table 4", "No Such Model", "RMSE-HDR", "nbrdf", "hdr_rmse", "brdf_space", 1, "")
    monkeypatch.setattr(published, "matches", lambda: [bogus])
    [row] = published.compare(view.build(_frame(), "s"))
    assert row.verdict == "published figure missing" and "No Such Model" in row.detail


def test_unreadable_published_data_is_said_not_raised(monkeypatch):
    def broken(name):
        raise OSError(f"{name}: no such file")

    monkeypatch.setattr(published_data, "_rows", broken)
    page = html.render(_frame(), "s")
    assert "could not be read" in page and "seed_figures.csv" in page


def test_empty_store_pages():
    empty = pd.DataFrame(columns=_frame().columns)
    assert "empty" in html.render(empty, "s") and "empty" in markdown.render(empty, "s")


def test_an_unknown_unit_is_shown_as_stored():
    df = _frame()
    df.loc[df.metric == "l1_log_cos", "unit"] = "furlongs"
    assert "furlongs" in markdown.render(df, "s")
    assert "furlongs" in html.render(df, "s")


def test_page_is_one_file_with_its_plots_inline():
    page = html.render(_frame(), "s")
    assert page.count("<svg") == 1 and "<script>" in page and "<style>" in page
    assert 'class="sortable"' in page and 'data-series="s0-pareto-s0-"' in page
    assert "src=" not in page  # no image without renders


def test_a_size_sweep_of_one_plugin_is_joined_in_order_of_size():
    df = _frame(reps=(("nbrdf", 0.1, 1.0, 700), ("fast", 0.5, 0.01, 24)))
    wide = _frame(reps=(("nbrdf", 0.05, 2.0, 2700),)).assign(config_hash="h-nbrdf-wide", params='{"hidden": [21, 21]}')
    df = pd.concat([df.assign(params=df.params.where(df.plugin != "nbrdf", '{"hidden": [8, 8]}')), wide])
    section = view.build(df, "s").sections[0]
    assert [r.label for r in section.rows] == ["nbrdf (hidden=[21, 21])", "nbrdf (hidden=[8, 8])", "fast"]
    chart = pareto.chart(section)
    bytes_panel = next(p for p in chart.panels if p.cost.name == "model_bytes")
    curves = pareto.size_curves(bytes_panel)
    assert list(curves) == ["nbrdf"] and [p.x for p in curves["nbrdf"]] == [700.0, 2700.0]
    markup = pareto.figure(chart, "p")
    assert markup.count('id="p-size-') == 1 and 'id="p-size-nbrdf"' in markup


def _circles(markup: str) -> dict[str, tuple[float, float]]:
    """{series group id: (cx, cy)} of a pareto SVG, parsed as XML (so the markup must be well formed)."""
    root = ElementTree.fromstring(markup)
    ns = "{http://www.w3.org/2000/svg}"
    return {g.get("id"): (float(g.find(f"{ns}circle").get("cx")), float(g.find(f"{ns}circle").get("cy")))
            for g in root.iter(f"{ns}g") if g.find(f"{ns}circle") is not None}


def test_pareto_svg_places_points_on_log_axes():
    df = _frame(reps=(("a", 0.1, 1.0, 100), ("b", 0.01, 10.0, 1000), ("c", 0.001, 100.0, 10000)))
    section = view.build(df, "s").sections[0]
    markup = pareto.figure(pareto.chart(section), "p")
    pts = _circles(markup)
    k = {r.label: i for i, r in enumerate(section.rows)}
    fit = {label: pts[f"p-s{i}-fit_time"] for label, i in k.items()}
    # fit time 1, 10, 100 s: equal steps to the right; error 0.1 → 0.001: equal steps down (SVG's y grows down)
    assert fit["a"][0] < fit["b"][0] < fit["c"][0] and fit["a"][1] < fit["b"][1] < fit["c"][1]
    assert abs((fit["b"][0] - fit["a"][0]) - (fit["c"][0] - fit["b"][0])) < 0.2
    assert abs((fit["a"][1] - fit["b"][1]) - (fit["b"][1] - fit["c"][1])) < 0.2


def test_lobe_svg_radius_is_decades_above_the_floor():
    theta = np.radians(np.array([-30.0, 0.0, 30.0]))
    markup = lobe_svg.lobe_panels([45.0], theta, [np.array([0.0, 2.0, np.nan])], {3: [np.array([1.0, 1.0, 1.0])]},
                                  "q", -3)
    root = ElementTree.fromstring(markup)
    ns = "{http://www.w3.org/2000/svg}"
    groups = {g.get("id"): g.find(f"{ns}path").get("d") for g in root.iter(f"{ns}g")}
    assert set(groups) == {"q-table-0", "q-s3-0"}
    cx, cy = lobe_svg.PANEL_W / 2, lobe_svg.TITLE_H + lobe_svg.RADIUS + 18.0
    # the table: the floor at the centre, two decades (the top, rmax = 2) straight up, the NaN left out
    (x0, y0), (x1, y1) = [tuple(map(float, p[1:].split(","))) for p in groups["q-table-0"].split()]
    assert (x0, y0) == (round(cx, 1), round(cy, 1)) and abs(x1 - cx) < 0.06 and abs(cy - y1 - lobe_svg.RADIUS) < 0.06
    assert len(groups["q-s3-0"].split()) == 3


def _with_widths(df: pd.DataFrame, widths: dict[str, float]) -> pd.DataFrame:
    cells = df.drop_duplicates(["config_hash", "material"])
    extra = cells.assign(metric="target_lobe_half_width", unit="rad", higher_is_better=False,
                         value=cells.material.map(widths))
    return pd.concat([df, extra], ignore_index=True)


def test_the_sharpest_tenth_is_split_off_by_lobe_width():
    materials = [f"m{i:02d}" for i in range(20)]
    widths = {m: 0.5 - 0.02 * i for i, m in enumerate(materials)}  # m19, m18 the sharpest
    df = _with_widths(_frame(materials=materials), widths)
    section = view.build(df, "s").sections[0]
    assert "target_lobe_half_width" not in section.metrics  # a property of the target, never a column
    split = section.sharpness
    assert split.sharpest == ("m19", "m18") and split.rest == 18
    assert split.widths == {"m19": pytest.approx(0.12), "m18": pytest.approx(0.14)}
    good = next(r for r in section.rows if r.label == "good")
    sharp, rest = (split.cells[(good.config_hash, "l1_log_cos", part)] for part in (True, False))
    assert sharp.value == pytest.approx(0.1 * (1 + 0.1 * 18.5))
    assert rest.value == pytest.approx(np.mean([0.1 * (1 + 0.1 * i) for i in range(18)]))
    text = markdown.render(df, "s")
    assert "### The sharpest tenth of the targets" in text and "m19 (0.12 rad), m18 (0.14 rad)" in text
    assert "The sharpest tenth" in html.render(df, "s")


@pytest.mark.parametrize("case", ["few materials", "a width missing", "no widths"])
def test_no_split_without_a_width_for_every_one_of_ten_materials(case):
    materials = [f"m{i:02d}" for i in range(9 if case == "few materials" else 12)]
    widths = {m: 0.1 * (i + 1) for i, m in enumerate(materials)}
    if case == "a width missing":
        widths.pop("m03")
    df = _frame(materials=materials) if case == "no widths" else _with_widths(_frame(materials=materials), widths)
    df = df.dropna(subset=["value"])
    section = view.build(df, "s").sections[0]
    assert section.sharpness is None and "sharpest tenth" not in markdown.render(df, "s")


def test_every_published_recipe_the_report_names_is_a_shipped_config():
    from importlib import resources

    conf = resources.files("brdfbench_conf")
    shipped = {p.name.removesuffix(".yaml") for group in ("representation", "generator")
               for p in conf.joinpath(group).iterdir()}
    assert set(published.PUBLISHED_RECIPES) <= shipped
