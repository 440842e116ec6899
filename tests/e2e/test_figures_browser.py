"""The cells' figures of the HTML report in a real browser (headless Chromium, 1400 × 1000),
on a page real runs wrote: lobe panels at least 400 px wide with radial labels of 12 px or
more; the log/linear switch redraws the slices and an inclination box hides its slices;
a click on a render opens it enlarged, Escape or a click closes it; the grid shows the
display renders; no console error.

Uses the shared `chromium` fixture (tests/e2e/conftest.py), skipped where Chromium or its
driver cannot start.
"""

from __future__ import annotations

from pathlib import Path

import pytest

QUICK = ["dataset.params.size=small", "harness=quick", "limit=2"]

VISIBLE_PATHS = """
return Array.from(arguments[0].querySelectorAll('g[data-ti] path'))
  .filter(p => p.getClientRects().length && getComputedStyle(p).display !== 'none').map(p => p.getAttribute('d'));
"""


@pytest.fixture(scope="module")
def results(tmp_path_factory, cli_session) -> Path:
    """An accuracy sweep with lobes and a render sweep with display renders."""
    root = tmp_path_factory.mktemp("figures")
    res = root / "res"
    out = cli_session("-m", "representation=merl,lambert,ggx", *QUICK, f"results_dir={res}", cwd=root)
    assert out.returncode == 0, out.stderr
    out = cli_session("harness=render", "scene=sphere_envmap", "-m", "representation=merl,lambert",
                      "dataset.params.size=small", "limit=2", "scene.params.width=24", "scene.params.height=24",
                      "scene.params.spp=4", "harness.display_spp=64", f"results_dir={res}", cwd=root)
    assert out.returncode == 0, out.stderr
    return res


@pytest.fixture(scope="module")
def page(chromium, results):
    chromium.viewport(1400, 1000)
    chromium.get((results / "leaderboard.html").as_uri())
    return chromium


def _errors(page) -> list:
    return [e for e in page.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]


def test_the_page_loads_without_console_errors(page):
    assert not _errors(page)
    assert page.find_elements("css selector", ".lobes .lobe-panel svg")
    assert page.find_elements("css selector", "table.images img[data-enlarge]")


def test_lobe_panels_are_large_with_readable_radial_labels(page):
    panels = page.find_elements("css selector", ".lobes .lobe-panel svg")
    sizes = [page.execute_script("const r = arguments[0].getBoundingClientRect(); return [r.width, r.height];", p)
             for p in panels]
    assert all(w >= 400 and h >= 200 for w, h in sizes), sizes
    # rendered label size: the attribute (viewBox units) times the panel's scale
    smallest = page.execute_script(
        "const s = arguments[0]; const k = s.getBoundingClientRect().width / s.viewBox.baseVal.width;"
        "return Math.min(...Array.from(s.querySelectorAll('text')).map(t => k * Number(t.getAttribute('font-size'))));",
        panels[0])
    assert smallest >= 12, smallest
    units = page.execute_script("return Array.from(arguments[0].querySelectorAll('text')).map(t => t.textContent)",
                                panels[0])
    assert any("1/sr" in u for u in units)


def test_the_linear_switch_redraws_the_slices_and_log_restores_them(page):
    figure = page.find_element("css selector", ".lobes")
    page.execute_script("arguments[0].scrollIntoView()", figure)
    log = page.execute_script(VISIBLE_PATHS, figure)
    assert log
    figure.find_element("css selector", 'input[data-lobe-scale="linear"]').click()
    linear = page.execute_script(VISIBLE_PATHS, figure)
    assert linear and len(linear) == len(log) and set(linear).isdisjoint(log)
    labels = page.execute_script("return Array.from(arguments[0].querySelectorAll('text.lobe-lin'))"
                                 ".filter(t => t.getClientRects().length).length", figure)
    assert labels >= 2  # the linear scale's own ring labels are shown
    figure.find_element("css selector", 'input[data-lobe-scale="log"]').click()
    assert page.execute_script(VISIBLE_PATHS, figure) == log
    assert not _errors(page)


def test_an_inclination_box_hides_its_slices(page):
    figure = page.find_element("css selector", ".lobes")
    before = page.execute_script(VISIBLE_PATHS, figure)
    box = figure.find_element("css selector", 'input[data-lobe-ti="0"]')
    box.click()
    hidden = page.execute_script(VISIBLE_PATHS, figure)
    assert 0 < len(hidden) < len(before)
    box.click()
    assert page.execute_script(VISIBLE_PATHS, figure) == before


def test_a_click_enlarges_a_render_and_escape_or_a_click_closes_it(page):
    from selenium.webdriver.common.keys import Keys

    thumb = page.find_element("css selector", "table.images img[data-enlarge]")
    page.execute_script("arguments[0].scrollIntoView({block: 'center'})", thumb)
    small = thumb.size["width"]
    thumb.click()
    boxes = page.find_elements("css selector", ".lightbox img")
    assert len(boxes) == 1
    big = boxes[0]
    assert big.get_attribute("src") == thumb.get_attribute("src")
    assert big.size["width"] >= 2 * small
    page.find_element("tag name", "body").send_keys(Keys.ESCAPE)
    assert not page.find_elements("css selector", ".lightbox")
    thumb.click()
    page.find_element("css selector", ".lightbox").click()
    assert not page.find_elements("css selector", ".lightbox")
    broken = page.execute_script(
        "return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src);")
    assert not broken, broken
    assert not _errors(page)


def test_the_grid_shows_display_renders_with_labelled_rows_and_colour_bars(page):
    table = page.find_element("css selector", "table.images")
    sources = [i.get_attribute("src") for i in table.find_elements("css selector", "tr:first-child img, tbody tr img")]
    renders = [s for s in sources if "/renders/" in s]
    assert renders and all(s.endswith(".display.png") for s in renders), renders
    rows = [th.text.split("\n")[0] for th in table.find_elements("css selector", 'th[scope="row"]')]
    assert rows == ["render", "FLIP map", "relative error"]
    assert len(table.find_elements("css selector", ".colour-bar .ramp")) == 2
    assert "PSNR" in table.text and "FLIP" in table.text
