"""The report's main table, provenance header and per-material drill-down (issue 29):
compact columns with the rest behind a toggle, the reference apart from the ranking,
readable units, no interval for a handful of materials, the machines that measured the
figures, and a heat map whose hardest materials are named by category and lobe sharpness."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from brdfbench_leaderboard import drilldown, html, markdown, view

from report_frames import CATEGORIES, CONFIGS, frame  # tests/report_frames.py


def section(df: pd.DataFrame) -> view.TableSection:
    return next(s for s in view.build(df, "store.sqlite").sections if s.kind == "table")


# -- the view ---------------------------------------------------------------------------------------


def test_the_reference_is_its_own_row_never_ranked():
    s = section(frame())
    ref = [r for r in s.rows if r.reference]
    assert [r.label for r in ref] == ["merl"] and ref[0].rank is None
    assert [r.label for r in s.rows if r.rank is not None] == ["nbrdf", "ggx", "lambert"]


@pytest.mark.parametrize("n, interval", [(4, False), (5, True), (8, True)])
def test_no_interval_with_fewer_than_five_materials(n, interval):
    cell = next(r for r in section(frame(n)).rows if r.label == "ggx").cell("l1_log_cos")
    assert cell.complete and (cell.lo is not None) == interval


def test_per_material_figures_and_lobe_widths_reach_the_section():
    s = section(frame(6))
    assert len(s.per_material["l1_log_cos"]) == 6 * len(CONFIGS)
    assert s.lobe_widths["mat-00"] == pytest.approx(0.01)


def test_hosts_name_the_machine_and_its_torch():
    h = view.build(frame(), "s").hosts
    assert len(h) == 1 and h[0].cpu_model == "AMD EPYC 9654" and h[0].cores == 2 and h[0].torch == "2.13.0+cpu"
    old = view.build(frame(platform="Linux x86_64 Python 3.11.7"), "s").hosts[0]
    assert old.torch == ""


# -- the HTML table ---------------------------------------------------------------------------------


def _main_table(page: str, sid: str = "s0") -> str:
    start = page.index(f'id="{sid}-table"')
    return page[start:page.index("</table>", start)]


def test_the_compact_view_hides_every_column_but_the_first_look():
    page = html.render(frame(), "store.sqlite")
    table = _main_table(page)
    head = table[:table.index("</thead>")]
    shown = re.findall(r'<th(?! class="extra")[^>]*data-metric="([^"]+)"', head)
    hidden = re.findall(r'<th class="extra"[^>]*data-metric="([^"]+)"', head)
    assert shown == ["l1_log_cos", "fit_time", "evals_per_s", "model_bytes"]
    assert set(hidden) == {"l1", "peak_rss_fit"}
    assert 'class="columns-toggle"' in page and "show all 9 columns" in page


def test_the_reference_sits_in_its_own_row_group_above_the_ranking():
    table = _main_table(html.render(frame(), "store.sqlite"))
    ref = table.index('<tbody class="reference">')
    ranked = table.index('<tbody class="ranked">')
    assert ref < ranked and "ref." in table[ref:ranked] and "<code>merl</code>" in table[ref:ranked]
    assert "<code>merl</code>" not in table[ranked:]
    assert 'class="best"' not in table[ref:ranked]  # far more accurate, never "best"


def test_costs_print_in_readable_units_with_the_exact_figure_in_the_tooltip():
    table = _main_table(html.render(frame(), "store.sqlite"))
    assert ">1.5 s<" in table and ">5.8 M evals/s<" in table and ">2.7 kB" in table and ">954 MB<" in table
    assert "9.536e+08" in table  # the exact figure, in the tooltip
    assert "e+08 B" not in re.sub(r'title="[^"]*"', "", table)


def test_a_shared_part_is_shown_under_bytes_per_material():
    table = _main_table(html.render(frame(shared={"nbrdf": 2.5e8}), "store.sqlite"))
    assert "+ 250 MB shared" in table


def test_the_sort_state_is_never_drawn_as_the_better_direction_arrow():
    page = html.render(frame(), "store.sqlite")
    head = _main_table(page).split("</thead>")[0]
    assert "↓" not in head and "↑" not in head and "lower is better" in head
    css = page[page.index("<style>"):page.index("</style>")]
    assert "\\25B2" in css and "\\2193" not in css and "\\2191" not in css


def test_the_header_names_store_code_and_machine():
    page = html.render(frame(), "/data/res/brdfbench.sqlite")
    header = page[page.index('<dl class="provenance">'):page.index("</dl>")]
    for text in ("/data/res/brdfbench.sqlite", "brdfbench 0.1", "AMD EPYC 9654", "2 cores", "2 threads", "no GPU",
                 "torch 2.13.0+cpu"):
        assert text in header, text


# -- Markdown ----------------------------------------------------------------------------------------


def test_markdown_sets_the_reference_apart_and_names_the_machine():
    text = markdown.render(frame(), "store.sqlite")
    ref = text.index("**Reference**")
    ranking = text.index("**Ranking:**")
    assert ref < ranking and "| ref. | `merl` |" in text[ref:ranking]
    assert "`merl`" not in text[ranking:text.index("### Per metric")]
    assert "- box: AMD EPYC 9654, 2 cores, 2 threads, no GPU" in text
    assert "1.5 s" in text and "954 MB" in text


# -- the drill-down ----------------------------------------------------------------------------------


def test_the_hardest_materials_are_the_sharpest_here_and_the_trend_is_found():
    d = drilldown.build(section(frame(8)))
    assert d.materials[0] == "mat-00" and d.materials[-1] == "mat-07"
    assert [r.label for r in d.configs] == ["nbrdf", "ggx", "lambert", "merl"]  # the reference last
    assert d.sharpness is not None and d.sharpness.rho < -0.9 and d.sharpness.p < drilldown.ALPHA
    assert "sharper lobes are harder" in drilldown.summary(d)
    assert {c.name for c in d.by_category} == set(CATEGORIES)
    assert d.by_category[0].name == "metal"  # mat-00 and mat-04: the sharpest of each half


def test_no_trend_is_claimed_where_sharpness_does_not_matter():
    flat = tuple((label, plugin, params, err, fit, size, 0.0) for label, plugin, params, err, fit, size, _ in CONFIGS)
    d = drilldown.build(section(frame(8, flat)))  # only the 5 % noise differs between materials
    assert d.sharpness is not None and d.sharpness.p >= drilldown.ALPHA
    assert f"no trend at the {drilldown.ALPHA:g} level" in drilldown.summary(d)


def test_difficulty_does_not_depend_on_the_direction_of_the_metric():
    """A higher-is-better metric (PSNR-like) ranks the same materials hardest."""
    df = frame(8)
    psnr = df[df.metric == "l1_log_cos"].assign(metric="psnr", unit="dB", higher_is_better=True)
    psnr["value"] = -10 * np.log10(psnr["value"])
    s = section(pd.concat([psnr, df[df.metric != "l1_log_cos"]]))
    assert s.primary.name in ("psnr", "l1")
    d = drilldown.build(s)
    assert d.materials[0] == "mat-00"


def test_the_heat_map_links_each_material_to_the_figures_the_page_has():
    from brdfbench_leaderboard.html_parts import anchor

    report = view.build(frame(4), "s")
    s = report.sections[0]
    d = drilldown.build(s)
    body = [html.DRILLDOWN_MARK.format(sid="s0"), f'<div id="{anchor("s0", "lobe", "mat-01")}"></div>']
    filled = "".join(html._fill_drilldowns(body, report, {"s0": d}))
    assert f'href="#{anchor("s0", "lobe", "mat-01")}"' in filled
    assert f'href="#{anchor("s0", "lobe", "mat-02")}"' not in filled  # no such figure on the page
    assert filled.count('class="heat"') == 4 * 3  # every ranked figure coloured; the reference not


def test_the_heat_map_is_on_the_page_with_its_colour_scale():
    page = html.render(frame(), "store.sqlite")
    assert 'id="s0-heatmap"' in page and "linear-gradient" in page and "(better)" in page
    assert page.index('id="s0-heatmap"') > page.index('id="s0-table"')


def test_a_store_of_the_reference_alone_ranks_nothing_and_says_so():
    df = frame(6, CONFIGS[:1])
    text = markdown.render(df, "s")
    assert "No configuration to rank beside the reference yet." in text
    assert "| 1 | `merl`" not in text and "| ref. | `merl`" in text  # nor in the per-metric tables
    page = html.render(df, "s")
    assert "No configuration to rank beside the reference yet." in page
    assert "<tr><td>1</td>" not in page and "<tr><td>ref.</td>" in page


def test_the_reference_alone_is_plotted_rather_than_an_empty_chart():
    from brdfbench_leaderboard import pareto

    alone = pareto.chart(section(frame(6, CONFIGS[:1])))
    assert alone is not None and not alone.hidden
    assert pareto.chart(section(frame(6))).hidden  # beside other configurations it starts hidden


def test_every_link_of_the_page_has_its_target():
    page = html.render(frame(), "s")  # no calibration rows: no machine-speed table to link to
    ids = set(re.findall(r'\bid="([^"]+)"', page))
    targets = set(re.findall(r'href="#([^"]+)"', page))
    assert targets and targets <= ids, targets - ids
