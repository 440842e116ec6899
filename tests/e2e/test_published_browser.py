"""The published-figures table in a real browser (headless Chromium through its WebDriver) at
1400 × 1000: every verdict is in view without scrolling sideways, the table no wider than
its box. The page is written from a small store with the rows a default run compares
(neural models, analytic fits, the table, a rendered scene), so the long setup and reason
texts are there to push the columns.

Skipped, saying why, only where Chromium or its driver cannot start (tests/e2e/conftest.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from brdfbench.report import write_reports
from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row

WIDTH, HEIGHT = 1400, 1000
#: label → (plugin, {metric: (value, unit, higher is better)}) in BRDF space
ACCURACY = {
    "nbrdf_brief": ("nbrdf", {"hdr_rmse": (0.24, "1/sr", False), "hdr_mae": (0.0127, "1/sr", False),
                              "model_bytes": (2700.0, "B", False), "flops_per_eval": (1399.0, "FLOP", False),
                              "fit_time": (0.16, "s", False)}),
    "naive_mlp_brief": ("naive_mlp", {"hdr_rmse": (0.96, "1/sr", False), "model_bytes": (2700.0, "B", False)}),
    "tripleplane_brief": ("tripleplane", {"hdr_rmse": (0.32, "1/sr", False), "model_bytes": (35116.0, "B", False)}),
    "triplane_gated_brief": ("triplane_gated", {"hdr_rmse": (0.31, "1/sr", False),
                                                "model_bytes": (35152.0, "B", False)}),
    "cook_torrance": ("cook_torrance", {"model_bytes": (64.0, "B", False)}),
    "ggx": ("ggx", {"model_bytes": (64.0, "B", False)}),
    "merl": ("merl", {"model_bytes": (34992000.0, "B", False)}),
}
#: label → (plugin, figures) on the rendered sphere
RENDERED = {
    "nbrdf_brief": ("nbrdf", {"ssim_ldr": (0.997, "", True), "psnr_ldr": (45.0, "dB", True),
                              "render_samples_per_s": (1.0e7, "samples/s", True)}),
    "ggx": ("ggx", {"ssim_ldr": (0.954, "", True), "render_samples_per_s": (1.18e7, "samples/s", True)}),
}


def _write(root: Path) -> Path:
    store = ResultsStore(root / "brdfbench.sqlite")
    common = dict(run_id="r", dataset="synthetic", dataset_fingerprint="fp", status="ok", message="", seed=0,
                  package_version="0.1.0", git_sha="abc", timestamp=1.0)
    for scene, configs in (("brdf_space", ACCURACY), ("sphere_envmap", RENDERED)):
        for label, (plugin, figures) in configs.items():
            h = f"{label}-{scene}"
            store.write_config(ConfigRecord(h, label, plugin, "0.1.0", "accuracy" if scene == "brdf_space" else
                                            "render", {"representation": plugin}))
            for i in range(3):
                store.write_cell([Row(config_hash=h, material=f"m{i}", category="plastic", metric=m, value=v, unit=u,
                                      higher_is_better=hib, scene=scene, **common)
                                  for m, (v, u, hib) in figures.items()])
    paths = write_reports(root)
    return next(p for p in paths if p.name == "leaderboard.html")


@pytest.fixture(scope="module")
def page(chromium, tmp_path_factory):
    chromium.viewport(WIDTH, HEIGHT)
    chromium.get(_write(tmp_path_factory.mktemp("published")).as_uri())
    return chromium


#: The published table's verdict cells (header included): their right edges, the viewport's
#: width, and how far the table's box scrolls sideways.
EDGES = """
const table = document.getElementById('published-table');
const heads = Array.from(table.tHead.rows[0].cells);
const column = heads.findIndex(c => c.textContent.trim().startsWith('verdict'));
const cells = [heads[column], ...Array.from(table.tBodies[0].rows).map(r => r.cells[column])];
const box = table.parentElement;
return {rights: cells.map(c => c.getBoundingClientRect().right), lefts: cells.map(c => c.getBoundingClientRect().left),
        texts: cells.map(c => c.textContent), inner: window.innerWidth,
        overflow: box.scrollWidth - box.clientWidth};
"""


def test_every_verdict_is_in_view_at_1400_px(page):
    got = page.execute_script(EDGES)
    assert got["inner"] == WIDTH
    assert len(got["rights"]) > 10, got["texts"]  # the header and the measured rows
    assert any("not comparable (hardware)" in t for t in got["texts"])
    assert any(t.startswith("agrees") for t in got["texts"])
    offscreen = [(t[:40], r) for t, r in zip(got["texts"], got["rights"]) if r > got["inner"]]
    assert not offscreen, offscreen
    assert min(got["lefts"]) >= 0
    assert got["overflow"] <= 0, f"the published table scrolls sideways by {got['overflow']} px"
