"""The section "Published fits against our fits", from a store written by hand: each published
fit paired with our fits of its model (each loss its own row) over the materials where both
are ok, failures left out and counted, the dataset's caveat, absent without published fits;
both renderers; and a published match selecting a published fit by its `source`."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from brdfbench.store.sqlite import ConfigRecord, ResultsStore, Row
from brdfbench_leaderboard import html, markdown, published, published_fits_render, view
from brdfbench_leaderboard.published_data import representation_spec
from brdfbench_leaderboard.published_fits_view import build

MATERIALS = [f"m{i}" for i in range(6)]
METRICS = {"l1_log_cos": ("log(1+1/sr)", False), "hdr_rmse": ("1/sr", False)}
COMMON = dict(run_id="r", seed=0, package_version="0.1.0", git_sha="abc", timestamp=1.0)


def _figure(h: str, material: str, metric: str) -> float:
    """A distinct, reproducible figure per (config, material, metric)."""
    return 0.01 * (1 + sum(map(ord, h)) % 7) + 0.001 * int(material[1:]) + (0.1 if metric == "hdr_rmse" else 0.0)


#: config hash → (label, plugin, plugin params, materials that fail)
CONFIGS = {
    "h_pub_sgd": ("published_fit", "published_fit", {"source": "bagher_sgd", "material": None}, {"m5"}),
    "h_sgd": ("sgd", "sgd", {"n_samples": 32768, "restarts": 4}, {"m4"}),
    "h_sgd_l2": ("sgd", "sgd", {"n_samples": 32768, "restarts": 4, "loss": "ngan_l2"}, set()),
    "h_pub_ward": ("published_fit", "published_fit", {"source": "ngan_ward", "material": None}, set()),
    "h_ward": ("ward", "ward", {"n_samples": 32768, "restarts": 4, "loss": "ngan_l2"}, set()),
    "h_pub_he": ("published_fit", "published_fit", {"source": "ngan_he", "material": None}, set(MATERIALS)),
    "h_ggx": ("ggx", "ggx", {}, set()),
}


def _write(store: ResultsStore, configs: dict, dataset: str, scene: str = "brdf_space",
           metrics: dict = METRICS, harness: str = "accuracy") -> None:
    for h, (label, plugin, params, fails) in configs.items():
        store.write_config(ConfigRecord(h, label, plugin, "0.1.0", harness,
                                        {"representation": plugin, "params": params, "seed": 0}))
        for m in MATERIALS:
            where = dict(config_hash=h, dataset=dataset, dataset_fingerprint=f"fp-{dataset}", material=m,
                         category="plastic", scene=scene, **COMMON)
            if m in fails:
                store.write_cell([Row(metric="error", value=None, unit="", higher_is_better=False, status="failed",
                                      message=f"no published fit of {m!r}", **where)])
            else:
                store.write_cell([Row(metric=k, value=_figure(h, m, k), unit=u, higher_is_better=hib, status="ok",
                                      message="", **where) for k, (u, hib) in metrics.items()])


@pytest.fixture(scope="module")
def frame(tmp_path_factory) -> pd.DataFrame:
    store = ResultsStore(tmp_path_factory.mktemp("fits") / "brdfbench.sqlite")
    _write(store, CONFIGS, "nbrdf_release")
    _write(store, {"h_pub_syn": CONFIGS["h_pub_sgd"][:3] + (set(MATERIALS),),
                   "h_sgd_syn": CONFIGS["h_sgd"][:3] + (set(),)}, "synthetic")
    return store.frame()


def _section(fits, dataset: str):
    (s,) = [s for s in fits.sections if s.dataset == dataset]
    return s


def _source(section, source: str):
    (f,) = [f for f in section.sources if f.source == source]
    return f


def test_pairs_are_matched_on_the_materials_where_both_are_ok(frame):
    s = _section(build(frame), "nbrdf_release")
    assert s.metrics == ["l1_log_cos", "hdr_rmse"] and s.materials == 6  # the ranking metric first
    sgd = _source(s, "bagher_sgd")
    assert sgd.model == "sgd" and "Bagher, Soler and Holzschuch" in sgd.paper
    assert [(o.config_hash, o.loss) for o in sgd.ours] == [("h_sgd", "l1_log_cos"), ("h_sgd_l2", "ngan_l2")]
    default, l2 = sgd.ours
    assert [(o.label, o.loss) for o in sgd.ours] == [("sgd", "l1_log_cos"), ("sgd", "ngan_l2")]  # labelled by loss
    # published fails on m5, ours (default loss) on m4: both are ok on m0..m3
    assert (default.materials, default.failed) == (4, 1) and (l2.materials, l2.failed) == (5, 0)
    for o, common in ((default, MATERIALS[:4]), (l2, MATERIALS[:5])):
        for p in o.metrics:
            theirs = np.mean([_figure("h_pub_sgd", m, p.metric) for m in common])
            ours = np.mean([_figure(o.config_hash, m, p.metric) for m in common])
            assert p.n == len(common)
            assert (p.published, p.ours) == pytest.approx((theirs, ours))
            assert p.difference == pytest.approx(ours - theirs)
            assert p.better == ("ours" if ours < theirs else "published")


def test_failures_are_excluded_and_counted(frame):
    s = _section(build(frame), "nbrdf_release")
    sgd = _source(s, "bagher_sgd")
    assert (sgd.ok, sgd.failed) == (5, ("m5",))
    he = _source(s, "ngan_he")  # every one of its cells failed here, and we have no fit of its model
    assert he.model == "he" and not he.ours and he.ok == 0 and len(he.failed) == 6
    assert he.note == "no fit of ours of `he` in this section: run `representation=he` beside it"
    ward = _source(s, "ngan_ward")
    (o,) = ward.ours
    assert o.config_hash == "h_ward" and o.authors_loss and o.materials == 6  # Ngan et al. fitted with ngan_l2
    assert not any(o.config_hash == "h_ggx" for f in s.sources for o in f.ours)
    md = "\n".join(published_fits_render.markdown(build(frame)))
    assert "failed on 1 (m5), left out" in md and "4 (ours failed on 1)" in md


def test_a_source_no_brdfbench_model_evaluates_is_said_so(tmp_path):
    from brdfbench_leaderboard.published_fits_view import model_of

    path = tmp_path / "mine.fit"
    path.write_text("alum-bronze = Aggregate(Lambertian(albedo = [0.1, 0.1, 0.1]), Mystery(albedo = [0.05, 0.05, 0.05]))\n",
                    encoding="utf-8")
    assert model_of(str(path)) == (None, "no brdfbench model evaluates these fits")
    assert model_of("ngan_he") == ("he", "")


def test_the_caveats_name_what_the_fits_were_made_against(frame):
    fits = build(frame)
    assert "fitted by them to the measured MERL data" in fits.note
    caveat = _section(fits, "nbrdf_release").caveat
    assert "published NBRDF networks approximating the MERL measurements" in caveat
    assert "not the data the published fits were made against" in caveat
    syn = _section(fits, "synthetic")
    assert "A synthetic set has no published fits" in syn.caveat
    (f,) = syn.sources
    assert f.ok == 0 and len(f.failed) == 6 and [o.materials for o in f.ours] == [0]
    md = "\n".join(published_fits_render.markdown(fits))
    assert "networks approximating the MERL measurements" in md and "A synthetic set has no published fits" in md


def test_the_section_is_absent_without_published_fits(frame):
    plain = frame[frame.plugin != "published_fit"]
    assert build(plain) is None and build(frame.iloc[0:0]) is None
    assert published_fits_render.markdown(None) == [] and published_fits_render.html_section(None) == []
    assert "Published fits against our fits" not in markdown.render(plain, "s")
    assert "Published fits against our fits" not in html.render(plain, "s")


def test_markdown_renders_the_section(frame):
    text = markdown.render(frame, "store.sqlite")
    assert text.index("## Published fits against our fits") < text.index("## Published figures beside ours")
    assert "#### `bagher_sgd`: Bagher, Soler and Holzschuch" in text and "evaluated with `sgd`" in text
    row = next(line for line in text.splitlines() if "loss `ngan_l2`" in line and "`hdr_rmse`" in line
               and "sgd" in line)
    p = next(p for f in _section(build(frame), "nbrdf_release").sources if f.source == "bagher_sgd"
             for o in f.ours if o.loss == "ngan_l2" for p in o.metrics if p.metric == "hdr_rmse")
    assert published_fits_render.difference_text(p, 5) in row and row.count("|") == 7


def test_html_renders_the_section_with_unique_ids_and_escaped_text(frame):
    page = html.render(frame, "store.sqlite")
    assert page.index('<h2 id="published-fits">') < page.index('<h2 id="published">')
    ids = re.findall(r'\bid="([^"]+)"', page)
    assert [i for i, n in Counter(ids).items() if n > 1] == []
    section = page[page.index('<h2 id="published-fits">'):page.index('<h2 id="published">')]
    assert section.count('<table class="published"') == 2  # bagher_sgd and ngan_ward on nbrdf_release
    assert "No material where both the published fit and <code>sgd</code> have a figure." in section  # synthetic
    assert "&quot;Experimental Analysis of BRDF Models&quot;" in section  # titles escaped
    assert re.search(r'rowspan="2"', section) and 'class="best"' in section
    assert "<script" not in section and "<code>nbrdf_release</code>" in section


def test_a_match_selects_a_published_fit_by_its_source():
    assert representation_spec("published_fit(source=bagher_sgd)") == ("published_fit", (("source", "bagher_sgd"),))
    assert representation_spec("ggx") == ("ggx", ())
    with pytest.raises(ValueError, match="name\\(key=value"):
        representation_spec("published_fit(source)")
    ms = {(m.model, m.our_metric): m for m in published.matches() if m.seed == "seed 001" and m.table == "Table 1"}
    assert {k for k in ms if k[1] == "mae_ldr"} == {("GGX", "mae_ldr"), ("NBRDF adaptive sampling", "mae_ldr"),
                                                     ("SGD (Bagher 2012)", "mae_ldr"), ("ABC (Low 2012)", "mae_ldr")}
    sgd, abc = ms[("SGD (Bagher 2012)", "rmse_ldr")], ms[("ABC (Low 2012)", "ssim_ldr")]
    assert (sgd.representation, sgd.params) == ("published_fit", (("source", "bagher_sgd"),))
    assert abc.params == (("source", "low_lowsmooth_e2"),) and "low_lowsmooth_e2 is our choice" in abc.setup
    for m in ms.values():  # every Table 1 row we match is in the figures file
        assert published.find(m, published.figures()) is not None, m.model

    def row(source):
        return view.Row("h", "published_fit", "published_fit", {"params": {"source": source, "material": None}},
                        None, {})
    assert published.selects(sgd, row("bagher_sgd")) and not published.selects(sgd, row("low_lowsmooth_e2"))
    assert published.selects(abc, row("low_lowsmooth_e2"))
    assert not published.selects(sgd, view.Row("h", "published_fit", "published_fit", None, None, {}))
    ggx = ms[("GGX", "mae_ldr")]
    assert published.selects(ggx, view.Row("h", "ggx (loss=low_e2)", "ggx", {"params": {"loss": "low_e2"}}, None, {}))


def test_published_table_1_rows_compare_with_our_published_fits(tmp_path: Path):
    """A render section of nbrdf_release with both published-fit sources: each Table 1 match finds
    only its own source's figure, with a verdict (measured materials, no recipe)."""
    store = ResultsStore(tmp_path / "brdfbench.sqlite")
    image = {"mae_ldr": ("1", False), "rmse_ldr": ("1", False), "ssim_ldr": ("1", True)}
    _write(store, {"h_b": CONFIGS["h_pub_sgd"][:3] + (set(),),
                   "h_l": ("published_fit", "published_fit", {"source": "low_lowsmooth_e2", "material": None}, set())},
           "nbrdf_release", scene="sphere_envmap", metrics=image, harness="render")
    rows = published.compare(view.build(store.frame(), "s"))
    got = {(c.match.model, c.match.our_metric): c for c in rows if c.match.seed == "seed 001"
           and c.match.table == "Table 1" and c.section is not None}
    for model, h in (("SGD (Bagher 2012)", "h_b"), ("ABC (Low 2012)", "h_l")):
        for metric in image:
            c = got[(model, metric)]
            assert c.ours.value == pytest.approx(np.mean([_figure(h, m, metric) for m in MATERIALS]))
            assert c.verdict in (published.AGREES, published.DIFFERS) and not c.mismatch


def test_two_fits_with_one_loss_keep_apart_by_their_parameters(tmp_path: Path):
    store = ResultsStore(tmp_path / "brdfbench.sqlite")
    _write(store, {"h_p": CONFIGS["h_pub_sgd"][:3] + (set(),),
                   "h_a": ("sgd", "sgd", {"n_samples": 1024, "restarts": 4}, set()),
                   "h_b": ("sgd", "sgd", {"n_samples": 32768, "restarts": 4}, set())}, "merl_folder")
    s = _section(build(store.frame()), "merl_folder")
    (f,) = s.sources
    assert sorted(o.label for o in f.ours) == ["sgd (n_samples=1024)", "sgd (n_samples=32768)"]
    assert {o.loss for o in f.ours} == {"l1_log_cos"} and "the data the published fits were made against" in s.caveat
