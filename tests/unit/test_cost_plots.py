"""The accuracy-against-cost plots, Python side: the reference starts off the axes and off
the front, shared bytes are amortised over the section's materials, FLOPs per evaluation get
a panel, a dB metric (or one that reaches zero) gets a linear axis, ticks print in readable
units, and the front follows the series shown. The browser side is
tests/e2e/test_cost_plots_browser.py."""

from __future__ import annotations

import json
import re
from xml.etree import ElementTree

import pandas as pd
import pytest

from brdfbench_leaderboard import chart_html, html, pareto, view

MATERIALS = tuple(f"m{i}" for i in range(6))
#: label: (plugin, error, fit time s, evals/s, bytes, FLOP/eval, shared bytes)
CONFIGS = {
    "merl": ("merl", 4e-9, 4.5e-5, 5.3e6, 34_992_000, 45, 0),
    "pca": ("pca", 0.0163, 0.12, 4.07e6, 624, 45, 131_545_920),
    "nbrdf": ("nbrdf", 0.0234, 0.16, 3.38e6, 2700, 1399, 0),
    "ggx": ("ggx", 0.0476, 0.45, 8.2e6, 64, 50, 0),
    "lambert": ("lambert", 0.262, 0.24, 2.2e8, 24, 3, 0),
}


def frame(configs=CONFIGS, metric="l1_log_cos", unit="log(1+1/sr)", higher=False, materials=MATERIALS) -> pd.DataFrame:
    """A store's rows: each configuration's accuracy (spread over materials) and costs."""
    rows = []
    for label, (plugin, err, fit, evals, size, flops, shared) in configs.items():
        for i, mat in enumerate(materials):
            cell = dict(representation=label, config_hash=f"h-{label}", plugin=plugin, params="{}", material=mat)
            rows += [dict(cell, metric=metric, value=err * (1 + 0.05 * i), unit=unit, higher_is_better=higher),
                     dict(cell, metric="fit_time", value=fit, unit="s", higher_is_better=False),
                     dict(cell, metric="evals_per_s", value=evals, unit="evals/s", higher_is_better=True),
                     dict(cell, metric="model_bytes", value=float(size), unit="B", higher_is_better=False),
                     dict(cell, metric="flops_per_eval", value=float(flops), unit="FLOP", higher_is_better=False)]
            if shared:
                rows.append(dict(cell, metric="shared_bytes", value=float(shared), unit="B", higher_is_better=False))
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"], df["category"] = "ok", "", 1.0, "metal"
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    df["scene"], df["harness"], df["sampler"], df["spp"], df["concurrent_jobs"] = "brdf_space", "accuracy", "", 0, 1
    return df


def section(df=None) -> view.TableSection:
    return view.build(frame() if df is None else df, "s").sections[0]


def panel(c: pareto.Chart, cost: str) -> pareto.Panel:
    return next(p for p in c.panels if p.cost.name == cost)


def labels(points) -> list[str]:
    return [p.row.label for p in points]


def test_the_reference_starts_hidden_off_the_axes_and_the_front():
    s = section()
    c = pareto.chart(s)
    ref = next(k for k, r in enumerate(s.rows) if r.label == "merl")
    assert s.rows[ref].reference and c.hidden == frozenset({ref})
    fit = panel(c, "fit_time")
    assert "merl" in labels(fit.points)  # drawn once its box is ticked
    assert labels(fit.front) == ["pca"]  # among the shown: merl would dominate every one
    everything = pareto.front(fit.points, False, False, hidden=frozenset())
    assert labels(everything) == ["merl"]
    # its legend box is the last one and starts unticked; every other one starts ticked
    boxes = re.findall(r'<input type="checkbox"( checked)? data-series="p-s(\d+)-">', chart_html.legend("p", c))
    assert [int(k) for _, k in boxes][-1] == ref and [bool(on) for on, _ in boxes] == [True] * (len(boxes) - 1) + [False]
    # the page without scripts draws it nowhere, and its axes fit the others
    root = ElementTree.fromstring(pareto.figure(c, "p"))
    ids = {g.get("id") for g in root.iter("{http://www.w3.org/2000/svg}g")}
    assert ids and not any(i.startswith(f"p-s{ref}-") for i in ids)
    assert all(f"p-s{k}-fit_time" in ids for k in range(len(s.rows)) if k != ref)


def test_the_page_embeds_every_point_and_marks_the_reference():
    page = html.render(frame(), "s")
    data = json.loads(re.search(r'<script type="application/json" id="s0-pareto-data" data-cost-chart>(.*?)</script>',
                                page).group(1))
    fit = next(p for p in data["panels"] if p["cost"] == "fit_time")
    by_label = {p["label"]: p for p in fit["points"]}
    assert set(by_label) == set(CONFIGS)
    assert by_label["merl"]["ref"] and not any(p["ref"] for name, p in by_label.items() if name != "merl")
    assert by_label["pca"]["x"] == pytest.approx(0.12) and by_label["pca"]["lo"] < by_label["pca"]["y"] < by_label["pca"]["hi"]
    assert data["yLog"] is True and data["yUp"] is False and not fit["xUp"]


def test_bytes_per_material_amortise_the_shared_bytes_over_the_section():
    s = section()
    n = len(s.materials)
    c = pareto.chart(s)
    assert c.materials == n == 6
    pts = {p.row.label: p for p in panel(c, "model_bytes").points}
    assert pts["pca"].x == pytest.approx(624 + 131_545_920 / n) and pts["pca"].shared == pytest.approx(131_545_920 / n)
    assert pts["nbrdf"].x == 2700 and pts["nbrdf"].shared == 0
    page = html.render(frame(), "s")
    assert "divided by N = 6, the materials of this section" in page
    assert "<code>pca</code> 624 B + 132 MB / 6 = 21.9 MB" in page


def test_a_panel_of_flops_per_evaluation():
    c = pareto.chart(section())
    assert [p.cost.name for p in c.panels] == ["fit_time", "evals_per_s", "model_bytes", "flops_per_eval"]
    flops = panel(c, "flops_per_eval")
    assert {p.row.label: p.x for p in flops.points}["nbrdf"] == 1399
    assert labels(flops.front) == ["lambert", "pca"]  # fewest FLOPs, then the most accurate that costs more


def test_a_db_metric_is_drawn_on_a_linear_axis():
    db = frame(metric="psnr_ldr", unit="dB", higher=True)
    db.loc[db.metric == "psnr_ldr", "value"] = db.loc[db.metric == "psnr_ldr", "value"] * 1e3 + 20  # 20…282 dB
    c = pareto.chart(section(db))
    assert c.y_log is False and c.primary.name == "psnr_ldr"
    data = chart_html.payload(c, "p")
    assert data["yLog"] is False and all(not p["yTicks"] for p in data["panels"])
    assert "accuracy axis linear" in html.render(db, "s")


def test_figures_at_or_below_zero_get_a_linear_axis_and_stay_on_it():
    df = frame(metric="ssim_ldr", unit="1", higher=True)
    df.loc[(df.metric == "ssim_ldr") & (df.representation == "lambert"), "value"] = -0.2
    c = pareto.chart(section(df))
    assert c.y_log is False
    assert "lambert" in labels(panel(c, "fit_time").points) and not panel(c, "fit_time").omitted


def test_a_positive_error_keeps_its_log_axis():
    assert pareto.chart(section()).y_log is True


def test_ticks_print_in_readable_units():
    data = chart_html.payload(pareto.chart(section()), "p")
    ticks = {p["cost"]: {label for _, label, _ in p["xTicks"]} for p in data["panels"]}
    assert {"100 ms", "1 ms", "10 µs"} <= ticks["fit_time"]
    assert {"1 kB", "10 MB", "100 B"} <= ticks["model_bytes"]
    assert {"10 M evals/s", "100 M evals/s"} <= ticks["evals_per_s"]
    assert {"1 kFLOP", "10 FLOP"} <= ticks["flops_per_eval"]
    ys = {label for _, label, _ in data["panels"][0]["yTicks"]}
    assert {"0.01", "0.1", "10⁻⁹"} <= ys


def test_the_front_follows_the_series_shown():
    c = pareto.chart(section())
    evals = panel(c, "evals_per_s")
    k = {p.row.label: p.k for p in evals.points}
    assert labels(evals.front) == ["lambert", "ggx", "pca"]  # fastest first, then each more accurate one
    without = pareto.front(evals.points, True, False, hidden=c.hidden | {k["lambert"], k["ggx"]})
    assert labels(without) == ["pca"]  # pca now beats nbrdf on both axes (4.07 M evals/s against 3.38 M)


def test_gpu_timings_join_a_front_only_where_no_cpu_timing_is_shown():
    gpu, cpu = (pareto.Point(None, x, y, None, None, on, 0.0, k) for k, (x, y, on) in
                enumerate([(1.0, 0.1, True), (10.0, 0.2, False)]))
    assert pareto.front([gpu, cpu], False, False) == [cpu]
    assert pareto.front([gpu, cpu], False, False, hidden={1}) == [gpu]
    assert pareto.front([gpu, cpu], False, False, hidden={0, 1}) == []


def test_a_label_cannot_end_the_data_script():
    configs = {"</script><b>x": ("evil", 0.1, 1.0, 1e6, 100, 10, 0), "ok": ("ok", 0.2, 2.0, 2e6, 200, 20, 0)}
    page = html.render(frame(configs), "s")
    assert "</script><b>" not in page
    text = re.search(r'id="s0-pareto-data" data-cost-chart>(.*?)</script>', page).group(1)
    assert "</script><b>x" in {p["label"] for p in json.loads(text)["panels"][0]["points"]}
