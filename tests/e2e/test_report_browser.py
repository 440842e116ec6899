"""The report's main table and heat map in a real browser at the width a researcher reads
it (issue 29): at 1400 × 900 the ranking, fit time, evals/s and bytes are in view without
scrolling; the rank and name stay when the table scrolls sideways; the reference stays
above the ranking whatever the sort; the column toggle works with the page's own CSS; the
heat map colours every ranked figure, hardest material first."""

from __future__ import annotations

import pytest
from report_frames import frame  # tests/report_frames.py

from brdfbench_leaderboard import html


@pytest.fixture(scope="module")
def page(chromium, tmp_path_factory):
    df = frame(12, shared={"nbrdf": 2.5e8})
    path = tmp_path_factory.mktemp("report") / "leaderboard.html"
    path.write_text(html.render(df, str(path.parent / "brdfbench.sqlite")), encoding="utf-8")
    chromium.viewport(1400, 900)
    chromium.get(path.as_uri())
    chromium.save_screenshot(str(path.parent / "first-screen.png"))  # what the first screen shows
    return chromium


def _rect(driver, element) -> dict:
    return driver.execute_script("const r = arguments[0].getBoundingClientRect();"
                                 "return {left: r.left, right: r.right, top: r.top, bottom: r.bottom};", element)


def test_no_console_errors(page):
    assert not [e for e in page.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]


def test_the_first_screen_holds_rank_fit_time_evals_and_bytes_of_every_row(page):
    table = page.find_element("id", "s0-table")
    heads = {h.get_attribute("data-metric") or h.text.split("\n")[0]: h
             for h in table.find_elements("css selector", "thead th") if h.is_displayed()}
    for name in ("rank", "representation", "l1_log_cos", "fit_time", "evals_per_s", "model_bytes", "materials"):
        assert name in heads, sorted(heads)
        assert _rect(page, heads[name])["right"] <= 1400, name
    last = table.find_elements("css selector", "tbody.ranked tr")[-1]
    assert _rect(page, last)["bottom"] <= 900, "the last ranked row is below the first screen"
    width = page.execute_script("return document.documentElement.scrollWidth")
    assert width <= 1400, f"the page scrolls sideways ({width} px)"


def test_the_column_toggle_shows_the_rest(page):
    extra = page.find_element("css selector", "#s0-table th.extra")
    assert not extra.is_displayed()
    page.find_element("css selector", "label.columns-toggle").click()
    assert extra.is_displayed()
    page.find_element("css selector", "label.columns-toggle").click()
    assert not extra.is_displayed()


def test_rank_and_name_stay_when_the_table_scrolls_sideways(page):
    page.viewport(700, 900)
    try:
        box = page.find_element("css selector", "#s0 ~ .main-table .scroll, .main-table .scroll")
        name = page.find_element("css selector", "#s0-table tbody.ranked tr td.name")
        figure = page.find_element("css selector", "#s0-table tbody.ranked tr td:last-child")
        before = (_rect(page, name)["left"], _rect(page, figure)["left"])
        scrolled = page.execute_script("arguments[0].scrollLeft = 400; return arguments[0].scrollLeft;", box)
        assert scrolled > 50, "the table does not overflow at 700 px: nothing to test"
        after = (_rect(page, name)["left"], _rect(page, figure)["left"])
        assert after[0] == pytest.approx(before[0], abs=1), "the name column scrolled away"
        assert after[1] < before[1] - 50
    finally:
        page.execute_script("document.querySelector('.main-table .scroll').scrollLeft = 0;")
        page.viewport(1400, 900)


def test_the_reference_stays_above_the_ranking_whatever_the_sort(page):
    head = page.find_element("css selector", "#s0-table th[data-metric='l1_log_cos']")
    for _ in range(2):  # ascending, then descending
        head.click()
        first = page.find_element("css selector", "#s0-table tbody tr")
        assert first.find_element("css selector", "td.rank").text == "ref."
        assert "merl" in first.text
    ranked = [r.find_element("css selector", "td.name").text.split("\n")[0]
              for r in page.find_elements("css selector", "#s0-table tbody.ranked tr")]
    assert ranked == ["lambert", "ggx", "nbrdf"]  # descending error
    assert "merl" not in ranked
    sorted_badge = page.execute_script("return getComputedStyle(arguments[0], '::after').content", head)
    assert sorted_badge in ('"▼"', '"\\25BC"')


def test_the_heat_map_colours_every_ranked_figure_hardest_first(page):
    table = page.find_element("id", "s0-heatmap")
    rows = table.find_elements("css selector", "tbody tr")
    assert len(rows) == 12
    assert rows[0].find_element("css selector", "td code").text == "mat-00"  # the sharpest lobe
    coloured = table.find_elements("css selector", "td.heat")
    assert len(coloured) == 12 * 3
    colours = {c.value_of_css_property("background-color") for c in coloured}
    assert len(colours) > 6  # a scale, not one colour
    assert not table.find_elements("css selector", "td.heat-ref[style]")  # the reference is not coloured


def test_the_per_metric_tables_keep_the_reference_apart_too(page):
    page.execute_script("document.querySelectorAll('details').forEach(d => d.open = true)")
    head = page.find_element("css selector", "#s0-l1_log_cos thead th:nth-child(3)")
    for _ in range(2):
        head.click()
        first = page.find_element("css selector", "#s0-l1_log_cos tbody tr")
        assert first.find_element("css selector", "td").text == "ref." and "merl" in first.text
