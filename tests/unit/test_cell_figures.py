"""The figures of the cells' files (leaderboard.cell_figures, lobe_svg, figures_html) and the
display renders behind the render grids (brdfbench.harness.render).

Lobes: one panel per configuration (none for the reference, the target itself), the table
drawn last, dashed and dark, one radial scale per material in 1/sr with readable labels, a
log and a linear path per slice. Render grids: labelled rows, colour bars in the maps'
colormaps, each render's stored PSNR and FLIP for its material, enlargeable images, the
ids the heat map links to. Display renders: a sampler fitted to the material and their own
spp, run control only, while the measured render and its metrics keep theirs.

The results folder is written here: a store frame, lobe slices and EXR renders indexed as
the harnesses index them (`brdfbench.artifacts`).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pandas as pd
import pytest
import torch

from brdfbench import artifacts
from brdfbench.harness import lobes
from brdfbench.harness.render import (DISPLAY_CANDIDATES, DisplayRenders, RenderConfig, RenderScorer, TableReference,
                                      fitted_sampler, save_image)
from brdfbench_leaderboard import cell_figures, figures_html, lobe_svg, view
from brdfbench_leaderboard.html_parts import anchor

SVG = "{http://www.w3.org/2000/svg}"
MATERIALS = {"m-metal": "metal", "m-plastic": "plastic"}
CONFIGS = ("merl", "ggx", "lambert")  # merl: the target itself (the reference row)
#: (config, material) → (psnr_ldr, flip_ldr): distinct per material, so a caption shows its own
FIGURES = {("ggx", "m-metal"): (31.25, 0.125), ("ggx", "m-plastic"): (36.5, 0.0625),
           ("lambert", "m-metal"): (18.75, 0.375), ("lambert", "m-plastic"): (27.0, 0.25),
           ("merl", "m-metal"): (100.0, 0.0), ("merl", "m-plastic"): (100.0, 0.0)}


def _lobe(theta_i: float, peak: float, width_deg: float, base: float) -> list[list[float]]:
    """One slice, [θo][rgb] in 1/sr: a constant plus a Gaussian lobe about the mirror direction."""
    values = [base + peak * math.exp(-(((t - theta_i) / width_deg) ** 2)) for t in lobes.THETA_O_DEG]
    return [[v, v, v] for v in values]


def _slices(peak: float, width: float, base: float) -> list[list[list[float]]]:
    return [_lobe(t, peak, width, base) for t in lobes.THETA_I_DEG]


def _frame() -> pd.DataFrame:
    rows = []
    for label in CONFIGS:
        for material, category in MATERIALS.items():
            cell = dict(representation=label, plugin=label, params="{}", material=material, category=category)
            rows.append(dict(cell, config_hash=f"a-{label}", scene="brdf_space", harness="accuracy",
                             metric="l1_log_cos", value=0.01 * (1 + CONFIGS.index(label)), unit="log(1+1/sr)",
                             higher_is_better=False))
            psnr, flip = FIGURES[(label, material)]
            render = dict(cell, config_hash=f"r-{label}", scene="sphere_envmap", harness="render")
            rows += [dict(render, metric="psnr_ldr", value=psnr, unit="dB", higher_is_better=True),
                     dict(render, metric="flip_ldr", value=flip, unit="1", higher_is_better=False),
                     dict(render, metric="ssim_ldr", value=0.9, unit="1", higher_is_better=True)]
    df = pd.DataFrame(rows)
    df["status"], df["message"], df["timestamp"] = "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    df["sampler"], df["spp"], df["concurrent_jobs"] = "", 0, 1
    return df


def _write_cells(res: Path) -> None:
    """Lobe slices for the accuracy configurations, display renders for the render ones."""
    table = {"m-metal": _slices(200.0, 3.0, 0.05), "m-plastic": _slices(2.0, 12.0, 0.15)}
    models = {"merl": table, "ggx": {"m-metal": _slices(120.0, 5.0, 0.04), "m-plastic": _slices(1.5, 15.0, 0.14)},
              "lambert": {m: _slices(0.0, 1.0, 0.2) for m in MATERIALS}}
    scene = res / "renders" / "sphere_envmap" / "k"
    for material in MATERIALS:
        ref = scene / "reference" / f"{material}.x.display.exr"
        save_image(ref, torch.full((32, 32, 3), 0.5), exposure=0.0)
        for label in CONFIGS:
            path = artifacts.index_path(res, f"a-{label}", material).with_suffix(".lobes.json")
            lobes.write(path, models[label][material], table[material], label, material)
            artifacts.record(res, f"a-{label}", material, "lobes", path)
            exr = scene / label / f"{material}.display.exr"
            save_image(exr, torch.full((32, 32, 3), 0.5 + 0.1 * CONFIGS.index(label)), exposure=0.0)
            meta = dict(exposure=0.0, simulator="direct_mis", spp=512, sampler="ggx_vndf",
                        sampler_params={"alpha": 0.12}, display_sampler="fitted", measured_spp=64,
                        measured_sampler="cosine")
            artifacts.record(res, f"r-{label}", material, "image", exr, png=exr.with_suffix(".png").name, **meta)
            artifacts.record(res, f"r-{label}", material, "reference", ref, png=ref.with_suffix(".png").name, **meta)


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> tuple[Path, view.TableSection, view.TableSection]:
    res = tmp_path_factory.mktemp("cells")
    _write_cells(res)
    report = view.build(_frame(), "s")
    accuracy = next(s for s in report.sections if s.kind == "table" and s.harness == "accuracy")
    render = next(s for s in report.sections if s.kind == "table" and s.harness == "render")
    return res, accuracy, render


def _groups(svg: str) -> list[ElementTree.Element]:
    return list(ElementTree.fromstring(svg).iter(f"{SVG}g"))


# --------------------------------------------------------------------------- lobes


def test_a_lobe_panel_per_configuration_and_none_for_the_reference(results):
    res, section, _ = results
    figures = cell_figures.lobe_figures(section, res, section.material_categories, "p")
    assert [f.material for f in figures] == sorted(MATERIALS)
    labels = [section.rows[k].label for k in range(len(section.rows))]
    for f in figures:
        shown = [section.rows[p.row].label for p in f.panels]
        assert sorted(shown) == ["ggx", "lambert"], shown  # merl is the dashed table line itself
        assert "merl" in labels and not f.missing
        for p in f.panels:  # each panel: its own configuration only, every inclination
            ids = [g.get("id") for g in _groups(p.svg)]
            assert {i.rsplit("-", 1)[-1] for i in ids} == {str(j) for j in range(len(lobes.THETA_I_DEG))}
            assert {re.sub(r"-\d+$", "", i) for i in ids} == {f"p{figures.index(f)}-{p.row}-s{p.row}",
                                                              f"p{figures.index(f)}-{p.row}-table"}


def test_the_table_is_drawn_last_dashed_and_dark_on_top_of_the_model(results):
    res, section, _ = results
    for f in cell_figures.lobe_figures(section, res, section.material_categories, "p"):
        for p in f.panels:
            groups = _groups(p.svg)
            kinds = ["table" if "-table-" in g.get("id") else "model" for g in groups]
            assert kinds == sorted(kinds), kinds  # "model" < "table": every table group after every model one
            for g in groups:
                if "-table-" in g.get("id"):
                    assert g.get("stroke-dasharray") and g.get("stroke") == lobe_svg.TABLE_COLOUR
                else:
                    assert not g.get("stroke-dasharray") and g.get("stroke") != lobe_svg.TABLE_COLOUR
                    assert float(g.get("stroke-width")) > 1.5  # thick enough to show under the dashes


def test_panels_are_twice_the_old_size_with_readable_radial_labels_in_1_per_sr(results):
    res, section, _ = results
    svg = cell_figures.lobe_figures(section, res, section.material_categories, "p")[0].panels[0].svg
    root = ElementTree.fromstring(svg)
    assert float(root.get("width")) >= 440  # the old panel was 272 px wide, three to a row
    texts = list(root.iter(f"{SVG}text"))
    assert all(float(t.get("font-size")) >= 12 for t in texts)
    words = [t.text for t in texts]
    assert any("1/sr" in w for w in words)
    assert "10⁻³" in words and sum(w.startswith("10") and w[2:3] in "⁻⁰¹²³⁴⁵⁶⁷⁸⁹" for w in words) >= 3  # decades
    assert "0" in words  # the linear scale starts at 0


def test_one_scale_per_material_log_and_linear_paths_of_every_slice(results):
    res, section, _ = results
    metal = next(f for f in cell_figures.lobe_figures(section, res, section.material_categories, "p")
                 if f.material == "m-metal")
    rings = set()
    for p in metal.panels:
        root = ElementTree.fromstring(p.svg)
        rings.add(tuple((t.get("class"), t.text) for t in root.iter(f"{SVG}text") if t.get("class")))
        for g in root.iter(f"{SVG}g"):
            log, lin = g.findall(f"{SVG}path")
            assert log.get("class") == "lobe-log" and lin.get("class") == "lobe-lin" and lin.get("display") == "none"
            assert log.get("d") != lin.get("d")
    assert len(rings) == 1  # both panels label the same rings: one scale
    # the linear rim is a round number at or above the largest value (the table's 200.05 1/sr peak)
    values = [float(v) for cls, v in next(iter(rings)) if cls == "lobe-lin"]
    assert 200.05 <= max(values) <= 400


def test_the_linear_radius_is_proportional_to_the_value():
    theta = np.radians(np.array([0.0, 45.0]))
    floor = -3
    # radial coordinates in decades above 1e-3: 2 → 0.1 1/sr, 3 → 1 1/sr
    svg = lobe_svg.lobe_panels([45.0], theta, [np.array([3.0, 3.0])], {0: [np.array([2.0, 2.0])]}, "q", floor)
    groups = {g.get("id"): g.findall(f"{SVG}path") for g in _groups(svg)}
    cx, cy = lobe_svg.centre()
    top = 1.0  # the largest value, 1 1/sr, is a round rim: nice_step(1) = 0.2, five rings
    (x0, y0), _ = [tuple(map(float, t[1:].split(","))) for t in groups["q-s0-0"][1].get("d").split()]
    assert x0 == pytest.approx(cx, abs=0.06) and cy - y0 == pytest.approx(lobe_svg.RADIUS * 0.1 / top, abs=0.06)
    (x0, y0), _ = [tuple(map(float, t[1:].split(","))) for t in groups["q-table-0"][1].get("d").split()]
    assert cy - y0 == pytest.approx(lobe_svg.RADIUS, abs=0.06)


def test_thinning_keeps_a_sharp_peak_and_drops_points_on_a_straight_run():
    theta = np.radians(np.asarray(lobes.THETA_O_DEG, dtype=float))
    flat = np.full(theta.size, 1.0)  # a circle: many points are needed
    spike = np.where(np.abs(np.degrees(theta) - 30) < 0.5, 3.0, 1.0)
    d = lobe_svg._path(theta, spike, 3.0, 0.0, 0.0)
    ys = [float(t[1:].split(",")[1]) for t in d.split()]
    assert min(ys) == pytest.approx(-lobe_svg.RADIUS * math.cos(math.radians(30)), abs=0.06)  # the peak stays
    assert len(d.split()) < theta.size
    assert lobe_svg._path(theta, flat, 3.0, 0.0, 0.0).count("L") < theta.size - 1


def test_lobe_figures_carry_the_heat_maps_anchor_and_the_controls(results):
    res, section, _ = results
    page = "".join(figures_html.lobes(section, "s0", res))
    for material in MATERIALS:
        assert f'id="{anchor("s0", "lobe", material)}"' in page
    assert page.count('data-lobe-scale="linear"') == len(MATERIALS)
    assert page.count("data-lobe-ti=") == len(MATERIALS) * len(lobes.THETA_I_DEG)
    assert "l1_log_cos 0.02" in page  # ggx's figure for the material, in its panel's title


# --------------------------------------------------------------------------- render grids


def test_render_rows_have_labels_anchors_and_each_renders_stored_figures(results):
    res, _, section = results
    page = "".join(figures_html.images(section, "s1", res))
    for material in MATERIALS:
        block = page[page.index(f'id="{anchor("s1", "render", material)}"'):]
        block = block[:block.index("</table>")]
        for kind in ("render", "FLIP map", "relative error"):
            assert f'<th scope="row" class="label">{kind}' in block
        for label in ("ggx", "lambert"):
            psnr, flip = FIGURES[(label, material)]
            assert f"PSNR {psnr:.4g} dB · FLIP {flip:.4g}" in block, (label, material)
        assert "<code>merl</code>" not in block  # the target itself: the reference column is its render
        assert "shown at 512 spp, sampler ggx_vndf(alpha=0.12) (fitted to the material)" in block
        assert "metrics measured at 64 spp, sampler cosine" in block
    assert page.count("data-enlarge") == len(MATERIALS) * (1 + 3 * 2)  # reference + 3 images per configuration


def test_colour_bars_use_the_colormaps_of_the_maps(results, tmp_path):
    res, _, section = results
    page = "".join(figures_html.images(section, "s1", res))
    for cmap, top in ((cell_figures.FLIP_CMAP, 1.0), (cell_figures.RELATIVE_CMAP, cell_figures.REL_ERROR_MAX)):
        assert page.count(f'data-cmap="{cmap}"') == len(MATERIALS)
        stops = cell_figures.colour_stops(cmap)
        assert all(c in page for c in stops)
        # the map's own pixels at 0 and at saturation are the bar's ends
        from PIL import Image

        target = tmp_path / f"{cmap}.png"
        cell_figures._write_map(target, np.array([[0.0, top]]), cmap, top)
        pixels = np.asarray(Image.open(target))[0]
        assert ["#%02x%02x%02x" % tuple(int(v) for v in p[:3]) for p in pixels] == [stops[0], stops[-1]]
    assert "≥ 100%" in page


def test_a_render_without_files_says_so_and_keeps_its_figures(results, tmp_path):
    res, _, section = results
    bare = tmp_path / "bare"
    bare.mkdir()
    assert cell_figures.image_rows(section, bare, section.material_categories) == []
    cells = {c.label: c for r in cell_figures.image_rows(section, res, section.material_categories) for c in r.cells
             if r.material == "m-metal"}
    assert cells["ggx"].figures == {"psnr_ldr": 31.25, "flip_ldr": 0.125}


# --------------------------------------------------------------------------- display renders


def test_display_keys_are_run_control_and_the_measured_ones_are_hashed():
    base = RenderConfig()
    shown = RenderConfig(display_spp=1024, display_sampler="cosine")
    assert shown.hashed() == base.hashed()
    assert RenderConfig(spp=128).hashed() != base.hashed()
    assert RenderConfig(sampler="ggx").hashed() != base.hashed()
    assert base.display_sampler == "fitted"


def test_the_fitted_display_sampler_suits_the_material(small_dataset):
    diffuse = fitted_sampler(small_dataset.load("synth-rubber-green-04"))
    sharp = fitted_sampler(small_dataset.load("synth-metallic-paint-blue-02"))
    assert diffuse == ("cosine", {})
    assert sharp[0] == "ggx_vndf" and sharp[1]["alpha"] <= 0.12
    assert sharp in [(n, p) for n, p in DISPLAY_CANDIDATES]
    assert fitted_sampler(small_dataset.load("synth-metallic-paint-blue-02")) == sharp  # deterministic


def test_display_renders_leave_the_measured_render_and_its_metrics_alone(small_dataset, tmp_path):
    """The measured image and metrics are the measured simulator's (its spp and sampler);
    the display pair is rendered apart, at its own spp with the fitted sampler, and recorded
    with both settings for the report's caption."""
    from brdfbench import images
    from brdfbench.plugins import registry
    from brdfbench.render.build import build_simulator

    scene = registry.get("scenes", "sphere_envmap").load()(width=12, height=12, spp=4)
    built: list[tuple[str, dict, int]] = []

    def build(sampler, params, spp):
        built.append((sampler, dict(params), spp))
        return build_simulator(scene, sampler=sampler, sampler_params=params, spp=spp, backend="torch")

    measured = build("cosine", {}, None)
    display = DisplayRenders(lambda s, p: build(s, p, 32), "fitted", {}, 32)
    specs = [registry.get("metrics", "psnr_ldr")]
    harness = RenderScorer(measured, specs, out_dir=tmp_path / "renders", dataset_fingerprint="fp",
                            record_to=(tmp_path, "h"), image_meta={"simulator": measured.name, "spp": 4,
                                                                  "sampler": "cosine"}, display=display)
    material = small_dataset.load("synth-metallic-paint-blue-02")
    model = TableReference(material)
    got = {m.metric: m.value for m in harness.measure(model, material, "table")}
    # the measured figure: the scene's 4 spp with cosine, what a plain render at that setting scores
    plain = measured.render(model, seed=0, material=material.name)
    reference = harness.reference(material)
    metric = specs[0].load()(exposure=0.0)
    metric.update(plain, reference)
    assert got["psnr_ldr"] == pytest.approx(float(metric.compute()))
    assert built == [("cosine", {}, None), (*fitted_sampler(material), 32)] and measured.spp == 4
    assert built[1][0] != "cosine"  # a sharp lobe: the display sampler is not the measured one
    entry = artifacts.lookup(tmp_path, "h", material.name)
    image, ref = entry["image"], entry["reference"]
    assert image["path"].endswith(".display.exr") and ref["path"].endswith(".display.exr")
    assert (image["spp"], image["sampler"], image["sampler_params"]) == (32, *built[1][:2])
    assert (image["measured_spp"], image["measured_sampler"], image["display_sampler"]) == (4, "cosine", "fitted")
    measured_exr = tmp_path / Path(image["path"]).parent / f"{material.name}.exr"
    assert torch.equal(images.read_exr(measured_exr), plain)  # the measured render is saved as it was scored


def test_the_first_look_shows_display_renders_with_the_fitted_sampler():
    import yaml

    root = Path(__file__).resolve().parents[2]
    profile = yaml.safe_load((root / "conf/profile/first_look.yaml").read_text(encoding="utf-8"))
    render = profile["hydra"]["sweeper"]["sections"]["render"]
    harness = yaml.safe_load((root / "conf/harness/render.yaml").read_text(encoding="utf-8"))
    assert render["harness.display_spp"] >= 256
    assert render.get("harness.display_sampler", harness["display_sampler"]) == "fitted"
    # the measured renders keep the scene's spp and the default sampler
    assert "harness.spp" not in render and "harness.sampler" not in render and harness["sampler"] == "cosine"
