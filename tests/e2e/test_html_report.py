"""The HTML report in a real browser (headless Chromium through its WebDriver): the page a
run writes loads from a file with no console error and no network request, every plot
and image is drawn, a table sorts when its header is clicked, a legend toggles its series.

The screenshot goes to `$BRDFBENCH_SCREENSHOT` when set (for a note), else the test's
temporary folder. Skipped, saying why, only where Chromium or its driver cannot start.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

QUICK = ["dataset.params.size=small", "harness=quick", "limit=2"]


@pytest.fixture(scope="module")
def results(tmp_path_factory, cli_session) -> Path:
    """A results folder written by real runs: an accuracy sweep and a small render sweep."""
    root = tmp_path_factory.mktemp("html")
    res = root / "res"
    out = cli_session("-m", "representation=merl,lambert", *QUICK, f"results_dir={res}", cwd=root)
    assert out.returncode == 0, out.stderr
    out = cli_session("harness=render", "scene=sphere_envmap", "-m", "representation=merl,lambert",
                      "dataset.params.size=small", "limit=2", "scene.params.width=24", "scene.params.height=24",
                      "scene.params.spp=4", f"results_dir={res}", cwd=root)
    assert out.returncode == 0, out.stderr
    return res


@pytest.fixture(scope="module")
def page(chromium, results):
    chromium.get((results / "leaderboard.html").as_uri())
    return chromium


def test_a_run_writes_the_page_beside_the_markdown(results):
    text = (results / "leaderboard.html").read_text(encoding="utf-8")
    assert (results / "leaderboard.md").is_file()
    assert text.startswith("<!DOCTYPE html>") and "<svg" in text
    for fetch in ('src="http', "src='http", 'href="http', "url(http", "@import"):
        assert fetch not in text, f"the page fetches something: {fetch}"


def test_page_loads_without_console_errors_or_network(page):
    errors = [e for e in page.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert not errors, errors
    requests = [json.loads(e["message"])["message"] for e in page.get_log("performance")]
    urls = [m["params"]["request"]["url"] for m in requests if m.get("method") == "Network.requestWillBeSent"]
    remote = [u for u in urls if not u.startswith(("file:", "data:", "about:"))]
    assert not remote, remote


def test_every_plot_and_image_is_drawn(page):
    plots = page.find_elements("css selector", ".plot svg")
    assert len(plots) >= 2  # the accuracy section's and the render section's accuracy-against-cost charts
    for svg in plots:
        size = page.execute_script("const r = arguments[0].getBoundingClientRect(); return [r.width, r.height];", svg)
        assert size[0] > 100 and size[1] > 100, size
        assert svg.find_elements("css selector", "path")
    broken = page.execute_script(
        "return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src);")
    assert not broken, broken


def _column(page, table_id: str, index: int) -> list[str]:
    return page.execute_script(
        "return Array.from(document.getElementById(arguments[0]).tBodies[0].rows)"
        ".map(r => r.cells[arguments[1]].getAttribute('data-sort') ?? r.cells[arguments[1]].textContent.trim());",
        table_id, index)


def test_a_table_sorts_when_its_header_is_clicked(page):
    table = page.find_element("id", "s0-table")
    headers = table.find_elements("css selector", "thead th")
    names = [h.text for h in headers]
    column = next(i for i, n in enumerate(names) if n.startswith("evals/s"))
    headers[column].click()
    values = [float(v) for v in _column(page, "s0-table", column)]
    assert values == sorted(values) and headers[column].get_attribute("aria-sort") == "ascending"
    headers[column].click()
    values = [float(v) for v in _column(page, "s0-table", column)]
    assert values == sorted(values, reverse=True) and headers[column].get_attribute("aria-sort") == "descending"
    label = names.index("representation")
    headers[label].click()
    labels = _column(page, "s0-table", label)
    assert labels == sorted(labels, key=str.lower)


def test_the_legend_toggles_a_series(page):
    box = page.find_element("css selector", ".legend input[data-series]")
    prefix = box.get_attribute("data-series")
    hidden = "return Array.from(document.querySelectorAll('[id^=\"' + arguments[0] + '\"]'))" \
             ".map(e => getComputedStyle(e).display);"
    assert "none" not in page.execute_script(hidden, prefix)
    box.click()
    shown = page.execute_script(hidden, prefix)
    assert shown and set(shown) == {"none"}
    box.click()
    assert "none" not in page.execute_script(hidden, prefix)


def test_screenshot(page, tmp_path):
    page.set_window_size(1400, 2400)
    target = Path(os.environ.get("BRDFBENCH_SCREENSHOT") or tmp_path / "leaderboard.png")
    target.parent.mkdir(parents=True, exist_ok=True)
    assert page.save_screenshot(str(target))
    assert target.stat().st_size > 10_000


def test_the_report_rebuilds_from_a_store_a_sweep_is_still_writing(tmp_path, cli, synthetic_cache):
    """`brdfbench report` while a sweep runs: it reads the cells written so far (WAL), writes
    both pages, and the sweep goes on to finish unharmed."""
    import subprocess
    import sys
    import time

    from brdfbench.store.sqlite import ResultsStore

    res = tmp_path / "res"
    env = {**os.environ, "BRDFBENCH_CACHE": str(synthetic_cache)}
    sweep = subprocess.Popen([sys.executable, "-m", "brdfbench.cli", "representation=lambert",
                              "dataset.params.size=small", "harness=quick", "limit=4", f"results_dir={res}"],
                             cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and sweep.poll() is None:
            if (res / "brdfbench.sqlite").is_file() and not ResultsStore(res / "brdfbench.sqlite").frame().empty:
                break
            time.sleep(0.2)
        running = sweep.poll() is None
        out = cli("report", "--results", str(res), cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        assert "lambert" in (res / "leaderboard.html").read_text(encoding="utf-8")
    finally:
        stdout, stderr = sweep.communicate(timeout=600)
    assert sweep.returncode == 0, stderr
    assert "4 done" in stdout
    assert running, "the sweep ended before the report was built: nothing was read mid-sweep"
