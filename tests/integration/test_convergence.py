"""The convergence harness: Monte Carlo error against the model's own high-spp render, per spp
rung and sampler, in the runner, the store and the leaderboard."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pandas as pd
import pytest
import torch

from brdfbench import mitsuba_env, scenes
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.harness.convergence import ConvergenceLadder, derive_seed, fit_slope, sampler_label
from brdfbench.render.build import build_simulator
from brdfbench.report import write_reports
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.store.sqlite import ResultsStore
from brdfbench_leaderboard import markdown
from brdfbench_representations.analytic import GGX
from brdfbench_representations.lambert import Lambert

LADDER = (1, 2, 4, 8, 16, 32, 64)
MATERIAL = SimpleNamespace(name="test-material")


def _harness(tmp_path, sampler="cosine", params=None, *, backend="torch", ladder=LADDER, reference_spp=1024,
             width=16):
    """A harness on a small sphere_envmap; the torch backend unless asked, so the numbers do
    not depend on which Mitsuba variant a machine can load."""
    scene = scenes.sphere_envmap(width=width, height=width)
    build = lambda spp: build_simulator(scene, sampler=sampler, sampler_params=params, spp=spp,  # noqa: E731
                                        backend=backend)
    return ConvergenceLadder(build, ladder, reference_spp, metrics=_rung_metrics(), out_dir=tmp_path,
                              dataset_fingerprint="test", save_images=False)


def _rung_metrics():
    """The shipped option's per-rung metrics, as specs."""
    return [registry.get("metrics", name) for name in harness_config("convergence").metrics]


def _lambert() -> Lambert:
    model = Lambert()
    model.albedo = torch.tensor([0.8, 0.5, 0.3], dtype=torch.float64)
    return model


def _values(measurements) -> dict[str, float]:
    """Figures by name, per-rung ones as `metric@spp=n`."""
    return {(f"{m.metric}@spp={m.spp}" if m.spp else m.metric): m.value for m in measurements}


# --------------------------------------------------------------------------- the estimator's rate


def test_a_lambertian_with_cosine_sampling_converges_as_one_over_root_spp(tmp_path):
    """Least-squares slope of log RMSE on log spp over 7 rungs of a 16×16 render (~200 sphere
    pixels × 3 channels per rung) against a 1024-spp reference. Over 30 seeds (torch) and 20
    (Mitsuba) it was −0.494 ± 0.021 and −0.500 ± 0.020 (sd), so ±0.08 is about 4σ; the
    reference's own noise flattens it by under 0.01 (E[MSE] = σ²(1/n + 1/1024))."""
    got = _values(_harness(tmp_path).measure(_lambert(), MATERIAL, "lambert"))
    assert got["convergence_slope"] == pytest.approx(-0.5, abs=0.08)
    # 64× the samples: 8× less error in expectation; at least 5× whatever the seed
    assert got["rmse_hdr@spp=64"] < got["rmse_hdr@spp=1"] / 5
    assert got["relmse_hdr@spp=64"] < got["relmse_hdr@spp=1"] / 25
    # MAE and MAPE fall like RMSE (absolute errors: 8× in expectation); PSNR rises by ~18 dB
    assert got["mae_hdr@spp=64"] < got["mae_hdr@spp=1"] / 5
    assert got["mape_hdr@spp=64"] < got["mape_hdr@spp=1"] / 5
    assert got["psnr_hdr@spp=64"] > got["psnr_hdr@spp=1"] + 12
    assert all(got[f"render_time@spp={n}"] > 0 for n in LADDER)
    assert got["convergence_rmse_1spp"] == pytest.approx(got["rmse_hdr@spp=1"], rel=0.3)
    # the harness's own RMSE, which the slope is fitted to, is the rmse_hdr metric's figure
    assert all(got[f"convergence_rmse@spp={n}"] == pytest.approx(got[f"rmse_hdr@spp={n}"], rel=1e-12) for n in LADDER)


def test_the_slope_is_of_the_rmse_whatever_the_metrics(tmp_path):
    """harness.metrics chooses the extra per-rung figures only: with PSNR first (or none),
    the slope and the 1-spp value are still those of the RMSE, as their names say."""
    scene = scenes.sphere_envmap(width=16, height=16)
    build = lambda spp: build_simulator(scene, sampler="cosine", spp=spp, backend="torch")  # noqa: E731
    runs = {}
    for names in ((), ("psnr_hdr", "rmse_hdr")):
        harness = ConvergenceLadder(build, (1, 4, 16), 128, metrics=[registry.get("metrics", n) for n in names],
                                    out_dir=tmp_path / str(len(names)), dataset_fingerprint="test", save_images=False)
        runs[names] = _values(harness.measure(_lambert(), MATERIAL, "lambert"))
    bare, psnr_first = runs[()], runs[("psnr_hdr", "rmse_hdr")]
    assert not any(k.startswith(("psnr_hdr", "rmse_hdr")) for k in bare)
    for key in ("convergence_slope", "convergence_rmse_1spp", "convergence_rmse@spp=4"):
        assert bare[key] == psnr_first[key]
    assert psnr_first["convergence_rmse@spp=16"] == pytest.approx(psnr_first["rmse_hdr@spp=16"], rel=1e-12)
    assert bare["convergence_slope"] < 0 < psnr_first["psnr_hdr@spp=16"] - psnr_first["psnr_hdr@spp=1"]


def test_the_sampler_that_matches_the_representation_converges_faster(tmp_path):
    """A glossy GGX model (α = 0.2) under the sky: GGX sampling with its α against cosine
    sampling, compared by the 1-spp RMSE fitted to all 7 rungs (robust to one unlucky rung).
    Each reference is rendered with its own sampler, so its noise inflates both sides alike
    and a 256-spp reference suffices. Over 16 seeds the ratio was 0.65 ± 0.06 (0.49–0.74;
    0.56–0.70 over 20 more with 1024-spp references, torch and Mitsuba): 0.9 is about 4σ."""
    model = GGX().set_coefficients(kd=0.05, ks=1.0, alpha=0.2, f0=0.5)
    ggx = _harness(tmp_path / "ggx", "ggx", {"alpha": 0.2}, reference_spp=256)
    matched = _values(ggx.measure(model, MATERIAL, "ggx"))
    cosine = _values(_harness(tmp_path / "cos", "cosine", reference_spp=256).measure(model, MATERIAL, "ggx"))
    assert matched["convergence_rmse_1spp"] < 0.9 * cosine["convergence_rmse_1spp"]
    assert matched["rmse_hdr@spp=64"] < cosine["rmse_hdr@spp=64"]


def test_every_render_draws_its_own_random_numbers():
    tags = ["reference", *(f"spp={n}" for n in LADDER), *(f"warm-up/spp={n}" for n in LADDER)]
    seeds = [derive_seed(0, t) for t in tags]
    assert len(set(seeds)) == len(seeds)
    assert all(0 <= s < 2**31 for s in seeds)  # within Mitsuba's 32-bit sampler seeds
    assert derive_seed(1, "reference") != derive_seed(0, "reference")


def test_the_fit_recovers_a_power_law_and_skips_noise_free_rungs():
    slope, at_one = fit_slope([1, 4, 16], [0.3, 0.15, 0.075])
    assert slope == pytest.approx(-0.5) and at_one == pytest.approx(0.3)
    slope, at_one = fit_slope([1, 4, 16], [0.3, 0.0, 0.075])
    assert slope == pytest.approx(-0.5)
    assert all(math.isnan(v) for v in fit_slope([1, 4], [0.0, 0.0]))


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
def test_the_mitsuba_backend_takes_the_derived_seeds(tmp_path):
    got = _values(_harness(tmp_path, backend="mitsuba", ladder=(1, 4, 16), reference_spp=128, width=8)
                  .measure(_lambert(), MATERIAL, "lambert"))
    assert all(math.isfinite(v) for v in got.values())
    assert got["rmse_hdr@spp=16"] < got["rmse_hdr@spp=1"]


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
def test_the_path_traced_scene_converges_too(tmp_path):
    scene = scenes.spheres_on_plane(width=16, height=12)
    harness = ConvergenceLadder(lambda spp: build_simulator(scene, spp=spp), (1, 4, 16), 128,
                                 metrics=_rung_metrics(), out_dir=tmp_path, dataset_fingerprint="test",
                                 save_images=False)
    assert {s.name for s in harness.rungs.values()} == {"path"}
    got = _values(harness.measure(_lambert(), MATERIAL, "lambert"))
    assert got["rmse_hdr@spp=16"] < got["rmse_hdr@spp=1"] and -0.8 < got["convergence_slope"] < -0.2


# --------------------------------------------------------------------------- the runner and the store


def _convergence(**kw) -> object:
    fields = {"backend": "torch", "spp_ladder": (1, 2, 4, 8), "reference_spp": 64, **kw}
    return harness_config(kind="convergence", **fields)


def _cfg(tmp_path, synthetic_cache, harness, scene="sphere_envmap", scene_params=None, **kw):
    return RunConfig(
        representation="lambert", representation_params={}, label="lambert", dataset="synthetic",
        dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, results_dir=tmp_path, limit=1,
        harness=harness, scene=scene,
        scene_params={"width": 12, "height": 12} if scene_params is None else scene_params,
        **kw,
    )


def test_rungs_land_in_the_store_per_sampler_and_in_the_leaderboard(tmp_path, synthetic_cache):
    assert run(_cfg(tmp_path, synthetic_cache, _convergence()))["done"] == 1
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    assert set(df.scene) == {"sphere_envmap"} and set(df.sampler) == {"cosine"} and set(df.harness) == {"convergence"}
    rows = {(r.metric, r.spp): r for r in df.itertuples()}
    for n in (1, 2, 4, 8):
        assert rows[("rmse_hdr", n)].unit == "radiance" and not rows[("rmse_hdr", n)].higher_is_better
        assert rows[("relmse_hdr", n)].unit == "1"
        assert rows[("render_time", n)].unit == "s"
        # the four panels of Sztrajman et al.'s convergence figures: MAE, RMSE, MAPE, PSNR
        assert rows[("mae_hdr", n)].unit == "radiance" and not rows[("mae_hdr", n)].higher_is_better
        assert rows[("mape_hdr", n)].unit == "%" and not rows[("mape_hdr", n)].higher_is_better
        assert rows[("psnr_hdr", n)].unit == "dB" and rows[("psnr_hdr", n)].higher_is_better
        assert rows[("mae_hdr", n)].value <= rows[("rmse_hdr", n)].value + 1e-12
    assert {("convergence_slope", 0), ("convergence_rmse_1spp", 0), ("fit_time", 0)} <= set(rows)
    references = list((tmp_path / "renders" / "sphere_envmap" / "convergence").rglob("reference/lambert/*.exr"))
    assert len(references) == 1
    stamp = references[0].stat().st_mtime_ns

    # another ladder is another cell, but the same model's reference is reused from the cache
    assert run(_cfg(tmp_path, synthetic_cache, _convergence(spp_ladder=(1, 4))))["done"] == 1
    assert references[0].stat().st_mtime_ns == stamp
    # another sampler is told apart in the sampler column
    assert run(_cfg(tmp_path, synthetic_cache, _convergence(sampler="uniform")))["done"] == 1
    samplers_now = set(ResultsStore(tmp_path / "brdfbench.sqlite").frame().sampler)
    assert samplers_now == {"cosine", "uniform"}

    paths = write_reports(tmp_path)
    board = paths[0].read_text()
    plots = [p for p in paths if p.suffix == ".png"]
    assert len(plots) == 1 and plots[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert board.count(f"]({plots[0].name})") == 2  # linked from both samplers' sections
    for sampler in ("cosine", "uniform"):
        assert f"convergence on `sphere_envmap`, sampler `{sampler}`" in board
    assert "| `lambert` |" in board and "| 1 spp |" in board and "slope" in board


def test_sampler_parameters_are_part_of_the_sampler_label():
    assert sampler_label("cosine") == "cosine"
    assert sampler_label("ggx", {"alpha": 0.2}) == "ggx(alpha=0.2)"


@pytest.mark.parametrize("harness, scene, match", [
    (_convergence(spp_ladder=(4, 2)), "sphere_envmap", r"harness.spp_ladder=\[4, 2\] must be strictly increasing"),
    (_convergence(spp_ladder=(8,)), "sphere_envmap", "harness.spp_ladder=.*at least two"),
    (_convergence(spp_ladder=(1, 0)), "sphere_envmap", "harness.spp_ladder=.*positive integers"),
    (_convergence(reference_spp=8), "sphere_envmap", "harness.reference_spp=8 must be an integer above .* 8"),
    (_convergence(), "sphere_directional", "scene='sphere_directional' renders with harness.simulator='closed_form'"),
    (_convergence(), "brdf_space", "harness=convergence needs a rendered scene"),
    (_convergence(metrics=("l1",)), "sphere_envmap", "harness.metrics: 'l1' is measured on 'merl_grid'"),
    (_convergence(spp=16), "sphere_envmap", "harness.spp=16 must be null"),
])
def test_bad_convergence_config_names_the_key_before_any_work(tmp_path, synthetic_cache, harness, scene, match):
    params = {} if scene == "brdf_space" else None
    with pytest.raises(ConfigError, match=match):
        run(_cfg(tmp_path, synthetic_cache, harness, scene, params))
    assert not (tmp_path / "renders").exists() and not (tmp_path / "brdfbench.sqlite").exists()


def test_the_packaged_config_composes_with_sampler_parameters():
    from hydra import compose, initialize_config_module

    from brdfbench.hydra.app import to_run_config

    base = ["harness=convergence", "scene=sphere_envmap", "representation=ggx", "limit=2"]
    with initialize_config_module(config_module="brdfbench_conf", version_base="1.3"):
        ggx = to_run_config(compose("config", overrides=[*base, "harness.sampler=ggx",
                                                         "harness.sampler_params.alpha=0.2"]))
        uniform = to_run_config(compose("config", overrides=[*base, "harness.sampler=uniform"]))
    assert ggx.harness.kind == "convergence" and ggx.harness.metrics == ("rmse_hdr", "mae_hdr", "mape_hdr", "psnr_hdr")
    assert ggx.harness.sampler_params == {"alpha": 0.2} and uniform.harness.sampler_params == {}
    assert tuple(ggx.harness.spp_ladder) == LADDER and ggx.harness.reference_spp == 1024


# --------------------------------------------------------------------------- the leaderboard


def _board_rows() -> pd.DataFrame:
    rows = []
    for rep, sampler, scale in (("ggx", "ggx(alpha=0.2)", 0.3), ("ggx", "cosine", 0.6), ("lambert", "cosine", 0.2)):
        cell = dict(representation=rep, scene="sphere_envmap", sampler=sampler, harness="convergence",
                    higher_is_better=False)
        for n in (1, 4, 16):
            rows += [dict(cell, metric="rmse_hdr", spp=n, value=scale / math.sqrt(n), unit="radiance"),
                     dict(cell, metric="render_time", spp=n, value=0.01 * n, unit="s")]
        rows.append(dict(cell, metric="convergence_slope", value=-0.5, unit="1"))
    rows.append(dict(representation="lambert", scene="brdf_space", sampler="", harness="accuracy", spp=0,
                     metric="l1_log_cos", value=0.1, unit="log", higher_is_better=False))
    df = pd.DataFrame(rows)
    df["material"], df["status"], df["message"], df["timestamp"] = "a", "ok", "", 1.0
    df["dataset"], df["dataset_fingerprint"], df["package_version"], df["git_sha"] = "synthetic", "fp", "0.1", "abc"
    return df


def test_the_leaderboard_has_a_convergence_section_per_sampler_beside_the_others():
    text = markdown.render(_board_rows(), "store.sqlite", plots={"unrelated.png"})
    assert "## Dataset `synthetic`\n" in text and "l1_log_cos" in text  # the BRDF-space section is untouched
    assert "convergence on `sphere_envmap`, sampler `ggx(alpha=0.2)`" in text
    cosine = text.split("sampler `cosine`")[1]
    header = next(line for line in cosine.splitlines() if line.startswith("| representation"))
    assert "| 1 spp | 4 spp | 16 spp | slope |" in header and "render time at 16 spp" in header
    line = next(line for line in cosine.splitlines() if line.startswith("| `ggx`"))
    assert "| 0.6 | 0.3 | 0.15 | -0.5 |" in line
    assert "![" not in text  # no figure was written for this scene


def test_the_figure_has_a_panel_per_error_of_the_papers_plots_and_copes_with_older_rows():
    from brdfbench_leaderboard import plots

    old = _board_rows()
    figs = plots.convergence_figures(old)
    (fig,) = figs.values()
    axes = fig.axes
    titled = {ax.get_ylabel().split(",")[0]: ax for ax in axes if ax.get_xlabel() == "samples per pixel"}
    assert set(titled) == {"RMSE of HDR radiance", "MAE of HDR radiance", "MAPE of HDR radiance (%)",
                           "PSNR of HDR radiance (dB)"}
    assert any(ax.get_xlabel().startswith("render time") and len(ax.lines) == 3 for ax in axes)
    # rows stored before MAE/MAPE/PSNR were measured: those panels say so instead of plotting
    assert not titled["MAE of HDR radiance"].lines and titled["MAE of HDR radiance"].texts
    assert len(titled["RMSE of HDR radiance"].lines) == 3 + 1  # three curves and the −½ guide

    extra = []
    for r in old[old.metric == "rmse_hdr"].to_dict("records"):
        extra += [dict(r, metric="mae_hdr", value=0.8 * r["value"]), dict(r, metric="mape_hdr", value=50 * r["value"], unit="%"),
                  dict(r, metric="psnr_hdr", value=-20 * math.log10(r["value"]), unit="dB", higher_is_better=True)]
    (fig,) = plots.convergence_figures(pd.concat([old, pd.DataFrame(extra)], ignore_index=True)).values()
    titled = {ax.get_ylabel().split(",")[0]: ax for ax in fig.axes if ax.get_xlabel() == "samples per pixel"}
    for name in ("MAE of HDR radiance", "MAPE of HDR radiance (%)", "PSNR of HDR radiance (dB)"):
        assert len(titled[name].lines) == 3 and not titled[name].texts
    mae = titled["MAE of HDR radiance"]
    assert mae.get_xscale() == mae.get_yscale() == "log"
    assert titled["PSNR of HDR radiance (dB)"].get_yscale() == "linear"
    # one colour per curve on every panel
    colours = [tuple(line.get_color() for line in ax.lines[:3]) for ax in
               (titled["MAE of HDR radiance"], titled["PSNR of HDR radiance (dB)"])]
    assert colours[0] == colours[1]
