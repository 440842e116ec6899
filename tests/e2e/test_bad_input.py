"""Bad input ends in one line naming the file, key or value, exit status 2, nothing half-written."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import safetensors.torch
import torch

from brdfbench import merl
from brdfbench import data
from brdfbench.data import Dataset
from brdfbench.data.merl_folder import merl_folder_dataset
from brdfbench.errors import DataError
from brdfbench.protocols.representation import Material


def one_error_line(out) -> str:
    """The single error line of a failed command (progress lines may precede it)."""
    assert out.returncode == 2, (out.stdout, out.stderr)
    errors = [line for line in out.stderr.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and errors[0].startswith("brdfbench: error: "), out.stderr
    assert "Traceback" not in out.stderr
    return errors[0]


def write_table(path, raw):
    """Bytes of a MERL file with these raw values (merl.write_binary refuses non-finite ones)."""
    path.write_bytes(np.asarray(merl.SHAPE, dtype="<i4").tobytes() + np.asarray(raw, dtype="<f8").tobytes())
    return path


@pytest.fixture
def folder(tmp_path):
    d = tmp_path / "merl"
    d.mkdir()
    write_table(d / "good.binary", np.full((3, *merl.SHAPE), 0.5))
    return d


# --------------------------------------------------------------------------- tables no metric can score


def test_all_invalid_table_is_a_data_error_naming_the_file(folder):
    bad = write_table(folder / "negative.binary", np.full((3, *merl.SHAPE), -1.0))
    ds = merl_folder_dataset(folder)
    ds.load("good")
    with pytest.raises(DataError, match=rf"{bad}: no valid \(non-negative\) cells"):
        ds.load("negative")


def test_absurd_values_are_a_data_error_naming_the_file(folder):
    raw = np.full((3, *merl.SHAPE), 0.5)
    raw[1, 10, 20, 30] = 1e300
    bad = write_table(folder / "huge.binary", raw)
    with pytest.raises(DataError, match=rf"{bad}: BRDF value .*e\+29\d 1/sr, above the plausible maximum"):
        merl_folder_dataset(folder).load("huge")
    raw[1, 10, 20, 30] = data.MAX_VALUE / merl.CHANNEL_SCALES[1] * 0.99  # bright, but plausible: kept
    write_table(folder / "huge.binary", raw)
    merl_folder_dataset(folder).load("huge")


@pytest.mark.parametrize("value", [math.inf, math.nan])
def test_non_finite_cells_in_a_file_are_a_data_error(folder, value):
    raw = np.full((3, *merl.SHAPE), 0.5)
    raw[0, 1, 2, 3] = value
    bad = write_table(folder / "nonfinite.binary", raw)
    with pytest.raises(DataError, match=rf"{bad}: 1 non-finite"):
        merl_folder_dataset(folder).load("nonfinite")


@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_non_finite_cells_from_any_loader_are_a_data_error(value):
    """Tables that do not come from a .binary file (e.g. an evaluated network) are checked too."""
    raw = np.full((3, *merl.SHAPE), 0.5)
    raw[2, 0, 0, 0] = value
    ds = Dataset("fake", ("net",), lambda n: Material(n, merl.MerlTable(raw), source="/data/net.h5"), "fake:1")
    with pytest.raises(DataError, match=r"/data/net\.h5: 1 non-finite \(NaN/Inf\) cells, first at channel 2"):
        ds.load("net")
    unnamed = Dataset("fake", ("net",), lambda n: Material(n, merl.MerlTable(raw)), "fake:1")
    with pytest.raises(DataError, match=r"material 'net': 1 non-finite"):
        unnamed.load("net")


@pytest.mark.parametrize("representation", ["lambert", "merl"])
def test_all_invalid_table_stops_the_run_before_any_plugin_fault(tmp_path, folder, representation, cli):
    """lambert and merl used to record IndexError / 'L1.compute() called before any update' as plugin faults."""
    bad = write_table(folder / "negative.binary", np.full((3, *merl.SHAPE), -1.0))
    (folder / "good.binary").unlink()
    out = cli(f"representation={representation}", "dataset=merl_folder", f"dataset.params.path={folder}",
                    "hydra.mode=RUN", "harness=quick", f"results_dir={tmp_path}/res", cwd=tmp_path)
    line = one_error_line(out)
    assert str(bad) in line and "no valid (non-negative) cells" in line
    assert "IndexError" not in out.stderr and "compute()" not in out.stderr
    assert not (tmp_path / "res" / "leaderboard.md").exists()


# --------------------------------------------------------------------------- merl_folder paths


def test_merl_folder_given_a_file_is_one_line(tmp_path, folder, cli):
    out = cli("dataset=merl_folder", f"dataset.params.path={folder / 'good.binary'}", "hydra.mode=RUN",
                    f"results_dir={tmp_path}/res", cwd=tmp_path)
    line = one_error_line(out)
    assert f"{folder / 'good.binary'}: is a MERL file, not a directory; pass its folder ({folder})" in line
    assert not (tmp_path / "res" / "leaderboard.md").exists()


# --------------------------------------------------------------------------- model files


def test_inspect_of_a_model_naming_another_representation_is_one_line(tmp_path, cli):
    from brdfbench.plugins import registry

    ggx = registry.get("representations", "ggx").create()
    path = tmp_path / "model.safetensors"
    header = {"format": "brdfbench.model/1", "representation": "lambert", "params": {}, "metadata": {}}
    safetensors.torch.save_file(ggx.state_dict(), str(path), metadata={"brdfbench": json.dumps(header)})
    line = one_error_line(cli("inspect", str(path), cwd=tmp_path))
    assert str(path) in line and "'albedo'" in line
    header["params"] = {"bogus": 1}
    safetensors.torch.save_file({"albedo": torch.ones(3)}, str(path), metadata={"brdfbench": json.dumps(header)})
    line = one_error_line(cli("inspect", str(path), cwd=tmp_path))
    assert str(path) in line and "'bogus'" in line and "it takes: no params" in line


@pytest.mark.parametrize("override, named", [
    ("profile=nope", "profile='nope': no such profile config (expected one of first_look, full, literature)"),
    ("dataset=nope", "dataset='nope': no such dataset config (expected one of "),
    ("representation=lambert,lambret", "representation='lambret': no such representation config"),
])
def test_an_unknown_config_choice_is_one_line_naming_the_group_and_its_options(tmp_path, override, named, cli):
    out = cli(override, f"results_dir={tmp_path / 'res'}", cwd=tmp_path)
    assert named in one_error_line(out)
    assert not (tmp_path / "res").exists()


@pytest.mark.parametrize("override", ["workers=0", "workers=-2", "workers=100000", "threads=0", "threads=100000",
                                      "threads=many"])
def test_a_bad_worker_or_thread_count_is_one_line_with_the_range(tmp_path, override, cli):
    out = cli(override, "representation=lambert", f"results_dir={tmp_path / 'res'}", cwd=tmp_path)
    line = one_error_line(out)
    assert line.startswith(f"brdfbench: error: {override.split('=')[0]}=") and "expected auto or a whole number from 1 to" in line
    assert not (tmp_path / "res").exists()
