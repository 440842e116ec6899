"""End-to-end: the `brdfbench` command, its sweep, its reports and its errors."""

from __future__ import annotations

import pickle
import subprocess
import sys

import pytest

from brdfbench.store.sqlite import ResultsStore

QUICK = ["dataset.params.size=small", "harness=quick", "limit=3"]
FIRST_LOOK = ("merl", "lambert", "blinn_phong", "cook_torrance", "ggx", "pca", "nbrdf_brief", "naive_mlp_brief",
              "tripleplane_brief", "triplane_gated_brief")


def test_default_sweep_writes_a_leaderboard_then_skips_done_cells(tmp_path, cli_process, cli):
    """The default sweep (the first look) as a user starts it, in a fresh interpreter: every
    built-in representation, the neural ones on their brief recipes, on three materials (the
    fewest pca's cross-validation takes, two training materials per fold); `harness=quick` on
    the command line leaves the render section out."""
    out = cli_process(*QUICK, f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    board = (tmp_path / "res" / "leaderboard.md").read_text()
    for name in FIRST_LOOK:
        assert f"`{name}`" in board, name
    assert "fit time ↓" in board and "evals/s" in board and "bytes" in board
    assert "the first look's brief training recipes" in board and "profile=full" in board
    assert "## Machine speed" in board  # the calibration product, stored with every cell
    df = ResultsStore(tmp_path / "res" / "brdfbench.sqlite").frame()
    cells = df.groupby(["config_hash", "material"])["metric"].apply(set)
    assert all("calibration_gflops" in metrics for metrics in cells)
    assert out.stdout.count(": 3 done") == len(FIRST_LOOK)
    page = (tmp_path / "res" / "leaderboard.html").read_text(encoding="utf-8")
    assert "Accuracy against cost" in page and "<svg" in page and "Lobes: in-plane slices" in page
    again = cli(*QUICK, f"results_dir={tmp_path}/res", cwd=tmp_path)  # the second run, in this process
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("0 done, 3 already in the store") == len(FIRST_LOOK)


def test_explicit_multirun_sweep(tmp_path, cli):
    out = cli("-m", "representation=lambert,merl_trilinear", *QUICK, f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    board = (tmp_path / "res" / "leaderboard.md").read_text()
    assert "`merl_trilinear`" in board and "`lambert`" in board and "`merl`" not in board


def test_render_sweep_with_the_multirun_flag_among_the_overrides(tmp_path, cli):
    """The issue's command shape: `-m` after other overrides, image metrics per material."""
    out = cli("harness=render", "scene=sphere_envmap", "-m", "representation=merl,lambert",
                    "dataset.params.size=small", "limit=1", "scene.params.width=16", "scene.params.height=16",
                    "scene.params.spp=4", "harness.sampler=ggx", "harness.sampler_params.alpha=0.3",
                    f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    board = (tmp_path / "res" / "leaderboard.md").read_text()
    assert "rendered scene `sphere_envmap`" in board and "psnr_ldr" in board and "flip_ldr" in board
    assert "`merl`" in board and "`lambert`" in board
    exrs = list((tmp_path / "res" / "renders").rglob("*.exr"))
    shown = [p for p in exrs if p.name.endswith(".display.exr")]  # harness.display_spp: for the report's images
    assert len(exrs) - len(shown) == 3 and len(shown) == 3  # reference, merl, lambert


def test_list_prints_one_line_per_plugin(tmp_path, cli):
    out = cli("list", cwd=tmp_path)
    assert out.returncode == 0
    lines = out.stdout.splitlines()
    assert any(line.split()[:2] == ["representations", "lambert"] for line in lines)
    assert any(line.split()[:2] == ["datasets", "synthetic"] for line in lines)


def test_unknown_config_key_names_the_key(tmp_path, cli):
    out = cli("bogus_key=1", f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode != 0
    assert "bogus_key" in out.stderr
    assert not (tmp_path / "res").exists()


def test_unknown_harness_key_names_the_key(tmp_path, cli):
    out = cli("+harness.n_randm=5", *QUICK, f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 2
    assert "harness.n_randm" in out.stderr
    assert not (tmp_path / "res" / "brdfbench.sqlite").exists()


def test_unknown_representation_gets_did_you_mean(tmp_path, cli):
    out = cli("representation.name=lambret", "hydra.mode=RUN", *QUICK, f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 2
    assert "Did you mean 'lambert'" in out.stderr
    assert not (tmp_path / "res" / "leaderboard.md").exists()


def test_unknown_config_option_lists_choices(tmp_path, cli):
    out = cli("representation=lambret", f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode != 0
    assert "lambret" in out.stderr and "lambert" in out.stderr


def test_merl_folder_that_is_not_a_merl_folder(tmp_path, cli):
    (tmp_path / "notmerl").mkdir()
    (tmp_path / "notmerl" / "readme.txt").write_text("hello")
    out = cli("dataset=merl_folder", f"dataset.params.path={tmp_path}/notmerl", "hydra.mode=RUN",
                    f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 2
    assert "notmerl" in out.stderr
    assert not (tmp_path / "res" / "leaderboard.md").exists()


def test_truncated_merl_file_is_named(tmp_path, cli):
    folder = tmp_path / "merl"
    folder.mkdir()
    (folder / "broken.binary").write_bytes(b"\x5a\x00\x00\x00" * 3 + b"\x00" * 100)
    out = cli("dataset=merl_folder", f"dataset.params.path={folder}", "hydra.mode=RUN",
                    f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 2
    assert "broken.binary" in out.stderr and "truncated" in out.stderr
    assert not (tmp_path / "res" / "leaderboard.md").exists()


def test_inspect_refuses_a_pickle(tmp_path, cli):
    path = tmp_path / "model.safetensors"
    path.write_bytes(pickle.dumps({"weights": [1, 2, 3]}))
    out = cli("inspect", str(path), cwd=tmp_path)
    assert out.returncode == 2
    assert str(path) in out.stderr and "pickle" in out.stderr


def test_report_without_store_is_an_error(tmp_path, cli):
    out = cli("report", "--results", str(tmp_path / "nothing"), cwd=tmp_path)
    assert out.returncode == 2
    assert "no results store" in out.stderr


@pytest.mark.slow
def test_default_benchmark_full_size(tmp_path, cli_process):
    out = cli_process(f"results_dir={tmp_path}/res", cwd=tmp_path)
    assert out.returncode == 0, out.stderr


def test_inspect_shows_params_and_fit_metadata(tmp_path, cli, fitted):
    from brdfbench import modelio

    model = fitted("ggx")
    path = modelio.save(model, "ggx", tmp_path / "ggx.safetensors")
    out = cli("inspect", str(path), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "representation 'ggx'" in out.stdout and "FLOP/eval" in out.stdout
    assert f"fit_loss: {model.fit_loss}" in out.stdout


def test_version_prints_the_brdfbench_version(tmp_path, cli):
    from brdfbench import __version__

    out = cli("--version", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"brdfbench {__version__}"


def test_help_lists_subcommands_config_groups_and_their_options(tmp_path, cli):
    from importlib import resources

    out = cli("--help", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    for command in ("list", "report", "check", "inspect", "convert"):
        assert f"\n    {command} " in out.stdout, command
    conf = resources.files("brdfbench_conf")
    for group in ("representation", "dataset", "harness", "scene"):
        assert f"{group}=OPTION" in out.stdout
        for option in (r.name[:-5] for r in (conf / group).iterdir() if r.name.endswith(".yaml")):
            assert f"\n    {option} " in out.stdout, (group, option)
    assert "brdfbench representation=lambert" in out.stdout and "--hydra-help" in out.stdout
    assert "@package" not in out.stdout  # a Hydra directive is not a config's description
    assert "    naive_mlp_equal_flops  naive_mlp at" in out.stdout  # a long name keeps its gap
    assert not (tmp_path / "results").exists()


def test_hydra_help_stays_reachable(tmp_path, cli):
    out = cli("--hydra-help", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "Hydra" in out.stdout and "--multirun" in out.stdout


def test_list_into_a_closed_pipe_ends_without_a_traceback(tmp_path):
    """`brdfbench list | head -n 2`: the reader leaves early; here it leaves before the first line."""
    proc = subprocess.Popen([sys.executable, "-m", "brdfbench.cli", "list"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()
    stderr = proc.stderr.read()
    proc.stderr.close()
    assert proc.wait(timeout=600) == 141  # as a tool killed by SIGPIPE
    assert "Traceback" not in stderr and "BrokenPipeError" not in stderr, stderr


@pytest.mark.shared_data
def test_cli_fits_nbrdf_on_the_release(tmp_path, cli, nbrdf_release_dir):
    """`brdfbench representation=nbrdf dataset=nbrdf_release`, cut down: two materials, a short recipe."""
    args = ["representation=nbrdf", "dataset=nbrdf_release", "limit=2", "harness=quick", f"results_dir={tmp_path}/res",
            "representation.params.epochs=2", "representation.params.n_samples=50000"]
    out = cli(*args, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    board = (tmp_path / "res" / "leaderboard.md").read_text()
    assert "## Dataset `nbrdf_release`" in board and "`nbrdf`" in board
    assert "favours `nbrdf`" in board and "materials per fit" in board
    df = ResultsStore(tmp_path / "res" / "brdfbench.sqlite").frame()
    assert set(df[df.metric == "fit_batch"].value) == {2.0}


def test_merge_combines_results_folders_into_one_leaderboard(tmp_path, cli):
    """Two folders written apart (as two nodes would) merge into one store and leaderboard;
    merging again adds nothing; a missing source fails before anything is written."""
    for rep, folder in (("lambert", "node1"), ("merl", "node2")):
        out = cli(f"representation={rep}", *QUICK[:2], "limit=2", f"results_dir={tmp_path / folder}",
                        cwd=tmp_path)
        assert out.returncode == 0, out.stderr
    out = cli("merge", str(tmp_path / "node1"), str(tmp_path / "node2"), "--into", str(tmp_path / "all"),
                    cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "2 cells merged, 0 already in" in out.stdout
    board = (tmp_path / "all" / "leaderboard.md").read_text()
    assert "`lambert`" in board and "`merl`" in board
    df = ResultsStore(tmp_path / "all" / "brdfbench.sqlite").frame()
    assert df.groupby(["representation", "material", "metric"]).size().max() == 1 and len(df.material.unique()) == 2
    again = cli("merge", str(tmp_path / "node1"), "--into", str(tmp_path / "all"), cwd=tmp_path)
    assert again.returncode == 0 and "0 cells merged, 2 already in" in again.stdout
    assert len(ResultsStore(tmp_path / "all" / "brdfbench.sqlite").frame()) == len(df)
    missing = cli("merge", str(tmp_path / "node1"), str(tmp_path / "gone"), "--into", str(tmp_path / "new"),
                        cwd=tmp_path)
    assert missing.returncode == 2 and f"{tmp_path / 'gone'}/brdfbench.sqlite: no results store here" in missing.stderr
    assert not (tmp_path / "new").exists() and not (tmp_path / "gone").exists()
    itself = cli("merge", str(tmp_path / "node1"), "--into", str(tmp_path / "node1"), cwd=tmp_path)
    assert itself.returncode == 2 and "cannot be merged into itself" in itself.stderr
