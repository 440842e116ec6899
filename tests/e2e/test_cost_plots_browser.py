"""The accuracy-against-cost plots in a real browser (headless Chromium, 1400 × 1000): the
reference starts unticked and off the axes; ticking it brings it back and extends the
accuracy axis; hiding a series rescales the axes and recomputes the Pareto front, which
agrees with the Python one (`pareto.front`); no two labels of a panel overlap; the panels
follow the window's width, two a row, with text of 12 px or more; a dB metric's axis is
linear; the page logs no console error. The page is built from a synthetic store.

Uses the shared `chromium` fixture (tests/e2e/conftest.py), skipped where Chromium or
its driver cannot start.
"""

from __future__ import annotations

import itertools
import math

import pandas as pd
import pytest

from brdfbench_leaderboard import html, pareto, view

MATERIALS = tuple(f"m{i}" for i in range(6))
#: label: (error, fit time s, evals/s, bytes, FLOP/eval, shared bytes, psnr dB): the default
#: run's figures, where labels crowd (ggx beside cook_torrance, pca beside nbrdf)
CONFIGS = {
    "merl": (4e-9, 4.5e-5, 5.34e6, 34_992_000, 45, 0, 100.0),
    "pca": (0.0163, 0.122, 4.07e6, 624, 45, 131_545_920, 41.0),
    "triplane_gated_brief": (0.0189, 0.184, 1.88e6, 35_152, 865, 0, 40.0),
    "tripleplane_brief": (0.0201, 0.183, 2.72e6, 35_116, 843, 0, 39.5),
    "nbrdf_brief": (0.0234, 0.161, 3.38e6, 2700, 1399, 0, 45.0),
    "ggx": (0.0476, 0.45, 8.22e6, 64, 50, 0, 28.5),
    "cook_torrance": (0.0548, 0.364, 9.09e6, 64, 42, 0, 28.0),
    "naive_mlp_brief": (0.0603, 0.265, 1.35e7, 2700, 1356, 0, 30.0),
    "blinn_phong": (0.1617, 0.244, 8.95e6, 56, 29, 0, 25.0),
    "lambert": (0.262, 0.24, 2.22e8, 24, 3, 0, 18.0),
}


def _frame() -> pd.DataFrame:
    """An accuracy section (l1_log_cos, log axis) and a rendered one (psnr_ldr in dB, linear)."""
    rows = []
    for label, (err, fit, evals, size, flops, shared, psnr) in CONFIGS.items():
        plugin = label.removesuffix("_brief")
        for i, mat in enumerate(MATERIALS):
            cell = dict(representation=label, config_hash=f"h-{label}", plugin=plugin, params="{}", material=mat,
                        category="metal")
            costs = [dict(cell, metric="fit_time", value=fit, unit="s", higher_is_better=False),
                     dict(cell, metric="model_bytes", value=float(size), unit="B", higher_is_better=False),
                     dict(cell, metric="flops_per_eval", value=float(flops), unit="FLOP", higher_is_better=False)]
            if shared:
                costs.append(dict(cell, metric="shared_bytes", value=float(shared), unit="B", higher_is_better=False))
            brdf = dict(scene="brdf_space", harness="accuracy")
            rows += [dict(c, **brdf) for c in costs]
            rows += [dict(cell, **brdf, metric="l1_log_cos", value=err * (1 + 0.08 * i), unit="log(1+1/sr)",
                          higher_is_better=False),
                     dict(cell, **brdf, metric="evals_per_s", value=evals, unit="evals/s", higher_is_better=True)]
            render = dict(scene="sphere_envmap", harness="render")
            rows += [dict(c, **render) for c in costs]
            rows += [dict(cell, **render, metric="psnr_ldr", value=psnr + 0.5 * i, unit="dB", higher_is_better=True),
                     dict(cell, **render, metric="render_samples_per_s", value=evals * 2, unit="samples/s",
                          higher_is_better=True)]
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"] = "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    df["sampler"], df["spp"], df["concurrent_jobs"] = "", 0, 1
    return df


@pytest.fixture(scope="module")
def report() -> view.Report:
    return view.build(_frame(), "s")


@pytest.fixture(scope="module")
def charts(report) -> dict[str, tuple[view.TableSection, pareto.Chart]]:
    """Plot id → (section, chart), as html.render numbers the sections."""
    return {f"s{i}-pareto": (s, pareto.chart(s)) for i, s in enumerate(report.sections) if s.kind == "table"}


@pytest.fixture(scope="module")
def page(chromium, tmp_path_factory):
    target = tmp_path_factory.mktemp("cost-plots") / "leaderboard.html"
    target.write_text(html.render(_frame(), "s"), encoding="utf-8")
    chromium.viewport(1400, 1000)
    chromium.get(target.as_uri())
    return chromium


#: Per panel of one chart: its limits, its front (series indices), its visible labels'
#: boxes and its y ticks' values and heights (within the panel, which a click may scroll).
STATE = """
return Array.from(document.getElementById(arguments[0]).querySelectorAll('svg[data-cost]')).map(svg => {
  const o = svg.getBoundingClientRect();
  return {
  cost: svg.dataset.cost,
  xlim: svg.dataset.xlim.split(' ').map(Number),
  ylim: svg.dataset.ylim.split(' ').map(Number),
  front: svg.querySelector('path.front').dataset.front.split(' ').filter(s => s).map(Number),
  labels: Array.from(svg.querySelectorAll('text.label')).filter(t => t.getClientRects().length).map(t => {
    const r = t.getBoundingClientRect(); return [r.left - o.left, r.top - o.top, r.right - o.left, r.bottom - o.top,
                                                 t.textContent]; }),
  shown: Array.from(svg.querySelectorAll('g[data-series]')).filter(g => getComputedStyle(g).display !== 'none')
    .map(g => Number(g.dataset.series)),
  yticks: Array.from(svg.querySelectorAll('text.tick-y')).map(t => [Number(t.dataset.value),
    t.getBoundingClientRect().top - o.top]),
  width: o.width, host: svg.parentNode.clientWidth, viewBox: svg.viewBox.baseVal.width,
  };
});
"""


def _state(page, plot_id: str) -> dict[str, dict]:
    return {p["cost"]: p for p in page.execute_script(STATE, plot_id)}


def _box(page, plot_id: str, k: int):
    return page.find_element("css selector", f'.legend[data-chart="{plot_id}"] input[data-series="{plot_id}-s{k}-"]')


def _python_front(chart: pareto.Chart, cost: str, hidden) -> list[int]:
    panel = next(p for p in chart.panels if p.cost.name == cost)
    return [p.k for p in pareto.front(panel.points, panel.cost.higher_is_better, chart.primary.higher_is_better,
                                      frozenset(hidden))]


def _index(section: view.TableSection, label: str) -> int:
    return next(k for k, r in enumerate(section.rows) if r.label == label)


def test_the_page_draws_every_panel_without_console_errors(page, charts):
    errors = [e for e in page.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors
    for plot_id, (_, chart) in charts.items():
        assert sorted(_state(page, plot_id)) == sorted(p.cost.name for p in chart.panels)


def test_the_reference_starts_unticked_and_off_the_axes(page, charts):
    for plot_id, (section, chart) in charts.items():
        merl = _index(section, "merl")
        box = _box(page, plot_id, merl)
        boxes = page.find_elements("css selector", f'.legend[data-chart="{plot_id}"] input')
        assert not box.is_selected() and boxes[-1] == box
        assert all(b.is_selected() for b in boxes[:-1])
        for cost, panel in _state(page, plot_id).items():
            assert merl not in panel["shown"] and len(panel["shown"]) == len(section.rows) - 1
            assert panel["front"] == _python_front(chart, cost, {merl}), cost
            assert merl not in panel["front"]
    accuracy = _state(page, "s0-pareto")
    assert all(p["ylim"][0] > 1e-3 for p in accuracy.values())  # the models fill the plot: merl's 4e-9 is off it


def test_ticking_the_reference_brings_it_back_and_extends_the_accuracy_axis(page, charts):
    section, chart = charts["s0-pareto"]
    merl = _index(section, "merl")
    before = _state(page, "s0-pareto")
    _box(page, "s0-pareto", merl).click()
    try:
        after = _state(page, "s0-pareto")
        for cost, panel in after.items():
            assert merl in panel["shown"]
            assert panel["ylim"][0] < 4e-9 < before[cost]["ylim"][0]
            assert panel["front"] == _python_front(chart, cost, set()), cost
        assert after["fit_time"]["front"] == [merl]  # the target itself beats every model on fit time and error
    finally:
        _box(page, "s0-pareto", merl).click()
    assert _state(page, "s0-pareto") == before


def test_hiding_a_series_rescales_the_axes_and_recomputes_the_front(page, charts):
    section, chart = charts["s0-pareto"]
    merl, lambert = _index(section, "merl"), _index(section, "lambert")
    before = _state(page, "s0-pareto")
    assert before["evals_per_s"]["front"][0] == lambert  # the fastest evaluation
    _box(page, "s0-pareto", lambert).click()
    try:
        after = _state(page, "s0-pareto")
        for cost, panel in after.items():
            assert lambert not in panel["shown"]
            assert panel["ylim"][1] < before[cost]["ylim"][1]  # lambert had the largest error
            assert panel["front"] == _python_front(chart, cost, {merl, lambert}), cost
        evals = after["evals_per_s"]
        assert evals["xlim"][1] < before["evals_per_s"]["xlim"][1] / 5  # its 222 M evals/s set the axis's end
        assert evals["front"] != before["evals_per_s"]["front"] and lambert not in evals["front"]
        assert all(after[c]["ylim"][0] <= v <= after[c]["ylim"][1] for c in after for v, _ in after[c]["yticks"])
    finally:
        _box(page, "s0-pareto", lambert).click()
    assert _state(page, "s0-pareto") == before


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def test_no_two_labels_of_a_panel_overlap(page, charts):
    for plot_id, (_, chart) in charts.items():
        state = _state(page, plot_id)
        assert len(state) == len(chart.panels)
        for cost, panel in state.items():
            boxes = panel["labels"]
            assert len(boxes) >= len(panel["shown"]) // 2, (cost, boxes)  # most points are named in place
            clashes = [(a[4], b[4]) for a, b in itertools.combinations(boxes, 2) if _overlap(a, b)]
            assert not clashes, (plot_id, cost, clashes)


def test_the_panels_follow_the_window_width_two_a_row(page):
    def measure():
        return page.execute_script(
            "const svgs = Array.from(document.querySelectorAll('#s0-pareto svg[data-cost]'));"
            "const sizes = Array.from(document.querySelectorAll('#s0-pareto svg text'))"
            "  .map(t => parseFloat(getComputedStyle(t).fontSize));"
            "return {widths: svgs.map(s => s.getBoundingClientRect().width), tops: svgs.map(s => s.getBoundingClientRect().top),"
            "  hosts: svgs.map(s => s.parentNode.clientWidth), boxes: svgs.map(s => s.viewBox.baseVal.width),"
            "  content: document.getElementById('s0-pareto').clientWidth, page: document.documentElement.clientWidth,"
            "  font: Math.min(...sizes)};")

    wide = measure()
    assert wide["content"] == pytest.approx(wide["page"] - 48, abs=1)  # the page's content box (1400 px less a scroll bar)
    assert wide["widths"] == pytest.approx(wide["hosts"], abs=1) and wide["widths"] == pytest.approx(wide["boxes"], abs=1)
    assert wide["widths"][0] > 0.45 * wide["content"] and wide["tops"][0] == wide["tops"][1]  # two a row
    assert wide["font"] >= 12  # drawn at its own pixel size: no scaling shrinks it
    page.viewport(1000, 1000)
    try:
        from selenium.webdriver.support.ui import WebDriverWait

        WebDriverWait(page, 5).until(lambda _: measure()["widths"][0] < wide["widths"][0] - 100)
        narrow = measure()
        assert narrow["content"] == pytest.approx(narrow["page"] - 48, abs=1) and narrow["page"] <= 1000
        assert narrow["widths"] == pytest.approx(narrow["hosts"], abs=1)
        assert narrow["widths"] == pytest.approx(narrow["boxes"], abs=1) and narrow["font"] >= 12
        assert narrow["widths"][0] == pytest.approx(wide["widths"][0] * (narrow["content"] - 24) / (wide["content"] - 24),
                                                    abs=2)
    finally:
        page.viewport(1400, 1000)
        WebDriverWait(page, 5).until(lambda _: measure()["widths"][0] == pytest.approx(wide["widths"][0], abs=1))


def test_a_db_metric_has_a_linear_axis_and_an_error_a_log_one(page, charts):
    rendered = next(pid for pid, (s, _) in charts.items() if s.primary.name == "psnr_ldr")
    assert len(_state(page, rendered)) == len(charts[rendered][1].panels) == 4
    for ticks in (p["yticks"] for p in _state(page, rendered).values()):
        steps = {round(b[0] - a[0], 9) for a, b in zip(ticks, ticks[1:])}
        pixels = [a[1] - b[1] for a, b in zip(ticks, ticks[1:])]
        assert len(ticks) >= 3 and len(steps) == 1 and max(pixels) - min(pixels) < 1.5  # even in value and on screen
    for ticks in (p["yticks"] for p in _state(page, "s0-pareto").values()):
        per_decade = [(a[1] - b[1]) / math.log10(b[0] / a[0]) for a, b in zip(ticks, ticks[1:])]
        assert len(ticks) >= 3 and max(per_decade) - min(per_decade) < 1.5  # even in the logarithm
