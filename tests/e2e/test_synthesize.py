"""Constrained synthesis: samples of one category from a saved generator, by rejection, with
the acceptance rate and the time per accepted sample; reproducible for a seed; bad input is
one line and exit 2, a shortfall exit 1, and nothing is written unless all were found."""

from __future__ import annotations

import pytest
import torch

from brdfbench import modelio
from brdfbench.data.categories import categories
from brdfbench.errors import ConfigError
from brdfbench.plugins import registry
from brdfbench.synthesis import batch_seed, constrained_samples
from brdfbench.testing import adversarial_pairs
from brdfbench.testing.generators import training_data

CATEGORY = "mid-specular"  # about a quarter of this PCA's draws (measured when the test was written)


@pytest.fixture(scope="module")
def generator():
    return registry.get("generators", "pca_brdf").create().fit(training_data(), seed=0)


@pytest.fixture(scope="module")
def saved(generator, tmp_path_factory):
    return modelio.save_generator(generator, "pca_brdf", tmp_path_factory.mktemp("gen") / "pca.safetensors")


def test_every_accepted_sample_is_in_the_category_and_the_rate_is_counted(generator):
    seen = []
    draw = constrained_samples(generator, CATEGORY, 2, batch=4, max_draws=64, on_batch=lambda d: seen.append(d.drawn))
    assert draw.complete and draw.accepted == 2 and draw.representation == "merl"
    assert all(CATEGORY in categories(s) for s in draw.samples)
    assert 2 <= draw.drawn <= 64 and draw.acceptance_rate == pytest.approx(2 / draw.drawn)
    assert seen and seen[-1] == draw.drawn and draw.seconds_per_accepted == pytest.approx(draw.seconds / 2)


def test_a_seed_gives_the_same_samples_and_batches_do_not_repeat(generator):
    a = constrained_samples(generator, CATEGORY, 1, seed=5, batch=4, max_draws=64)
    b = constrained_samples(generator, CATEGORY, 1, seed=5, batch=4, max_draws=64)
    wi, wo = adversarial_pairs(512, torch.float64, seed=0)["uniform"]
    assert a.drawn == b.drawn and torch.equal(a.samples[0].eval(wi, wo), b.samples[0].eval(wi, wo))
    assert len({batch_seed(5, k) for k in range(100)}) == 100 and batch_seed(5, 0) != batch_seed(6, 0)


def test_bad_arguments_are_named(generator):
    with pytest.raises(ConfigError, match=r"category='mid-specualr' is not a material category; did you mean 'mid-specular'"):
        constrained_samples(generator, "mid-specualr", 1)
    with pytest.raises(ConfigError, match=r"n=0 must be an integer ≥ 1"):
        constrained_samples(generator, CATEGORY, 0)
    with pytest.raises(ConfigError, match=r"max_draws=1 is below n=2"):
        constrained_samples(generator, CATEGORY, 2, max_draws=1)


def test_the_command_writes_the_samples_and_says_what_they_cost(saved, tmp_path, cli):
    out = tmp_path / "mid"
    res = cli("synthesize", str(saved), "--category", CATEGORY, "-n", "2", "--batch", "4", "--out", str(out),
              cwd=tmp_path)
    assert res.returncode == 0, res.stdout + res.stderr
    files = sorted(out.glob("*.safetensors"))
    assert [f.name for f in files] == [f"{CATEGORY}-000.safetensors", f"{CATEGORY}-001.safetensors"]
    for f in files:
        name, model = modelio.load(f)
        assert name == "merl" and CATEGORY in categories(model)
    assert "s per accepted sample" in res.stdout and "accepted 2 of" in res.stdout
    assert f"synthesize: 2/2 {CATEGORY} after" in res.stdout
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".mid-")]  # no temporary folder left


@pytest.mark.parametrize("args, words", [
    (["--category", "shiny"], "category='shiny' is not a material category"),
    (["--category", CATEGORY, "-n", "0"], "n=0 must be an integer ≥ 1"),
])
def test_bad_input_is_one_line_and_exit_2(saved, tmp_path, cli, args, words):
    res = cli("synthesize", str(saved), *args, "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2 and words in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert not (tmp_path / "o").exists()


def test_an_existing_folder_or_a_file_that_is_no_generator_is_refused(saved, tmp_path, cli):
    (tmp_path / "taken").mkdir()
    res = cli("synthesize", str(saved), "--category", CATEGORY, "--out", str(tmp_path / "taken"), cwd=tmp_path)
    assert res.returncode == 2 and "exists; give a new folder" in res.stderr
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"not a model")
    res = cli("synthesize", str(junk), "--category", CATEGORY, "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2 and str(junk) in res.stderr and "\n" not in res.stderr.strip()


def test_a_shortfall_writes_nothing_and_exits_1(saved, tmp_path, cli):
    res = cli("synthesize", str(saved), "--category", "diffuse", "-n", "3", "--batch", "2", "--max-draws", "4",
              "--out", str(tmp_path / "none"), cwd=tmp_path)
    assert res.returncode == 1, res.stdout + res.stderr
    assert "not the 3 diffuse samples asked; nothing written (raise --max-draws, now 4)" in res.stderr
    assert not (tmp_path / "none").exists()
