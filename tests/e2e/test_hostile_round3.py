"""Hostile input, round three: each case is one line naming the file, key or value, a
non-zero exit (2 for bad input, 1 for a finished sweep with failed cells) and nothing
half-written. Read-only and full results folders are real tmpfs mounts (skipped where this
process cannot mount)."""

from __future__ import annotations

import contextlib
import json
import logging
import sqlite3
import subprocess
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest
import safetensors.torch
import torch

from brdfbench import modelio
from brdfbench.plugins import registry
from brdfbench.testing.kit import reference_material

from test_bad_input import one_error_line  # tests/e2e is on sys.path (pytest prepend import mode)

SMALL = ["dataset.params.size=small", "harness=quick", "progress=none"]


@contextlib.contextmanager
def tmpfs(path: Path, size: str, read_only: bool = False):
    """A small tmpfs at `path` for the test's life; skips where mounting is not allowed."""
    path.mkdir(parents=True)
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}" + (",ro" if read_only else ""), "tmpfs",
                               str(path)], capture_output=True, text=True)
    except FileNotFoundError:
        pytest.skip("no mount command here")
    if done.returncode:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip()})")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


# -- 1. an explicitly empty selection ------------------------------------------------------------


def test_an_empty_material_selection_is_an_error(tmp_path, cli):
    res = tmp_path / "res"
    line = one_error_line(cli("representation=merl", *SMALL, "materials=[]", f"results_dir={res}", cwd=tmp_path))
    assert "materials=[]" in line and "empty" in line
    assert not res.exists()


# -- 2. a damaged store ----------------------------------------------------------------------------


@pytest.fixture
def damaged_store(tmp_path, cli):
    res = tmp_path / "res"
    out = cli("-m", "representation=lambert,ggx", *SMALL, "limit=2", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    store = res / "brdfbench.sqlite"
    pages = store.stat().st_size // 4096
    assert pages >= 6
    with open(store, "r+b") as fh:  # page 6 overwritten with (seeded) random bytes
        fh.seek(5 * 4096)
        fh.write(np.random.default_rng(0).bytes(4096))
    return res


def test_a_damaged_store_stops_a_run_with_one_line_and_exit_2(tmp_path, cli, damaged_store):
    out = cli("representation=lambert", *SMALL, "limit=1", f"results_dir={damaged_store}", cwd=tmp_path)
    line = one_error_line(out)
    assert str(damaged_store / "brdfbench.sqlite") in line and "damaged" in line


def test_report_of_a_damaged_store_is_one_line_and_exit_2(tmp_path, cli, damaged_store):
    line = one_error_line(cli("report", "--results", str(damaged_store), cwd=tmp_path))
    assert str(damaged_store / "brdfbench.sqlite") in line and "damaged" in line


# -- 3. read-only and full results folders ----------------------------------------------------------


def test_a_read_only_results_folder_is_one_line(tmp_path, cli):
    with tmpfs(tmp_path / "ro", "2m", read_only=True) as ro:
        res = ro / "results"
        line = one_error_line(cli("representation=lambert", *SMALL, "limit=1", f"results_dir={res}", cwd=tmp_path))
        assert f"results_dir={res}" in line and "Read-only file system" in line
        assert not res.exists()


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, cli):
    with tmpfs(tmp_path / "full", "2m") as full:
        with contextlib.suppress(OSError):
            (full / "filler").write_bytes(b"\0" * (4 << 20))
        res = full / "results"
        line = one_error_line(cli("representation=lambert", *SMALL, "limit=1", f"results_dir={res}", cwd=tmp_path))
        assert f"results_dir={res}" in line and "No space left on device" in line
        assert not res.exists()


# -- 4. the disk filling during a run -------------------------------------------------------------


def test_a_disk_filling_mid_run_exits_2_and_keeps_store_and_artifacts_consistent(tmp_path, cli):
    with tmpfs(tmp_path / "small", "300k") as small:
        res = small / "results"
        out = cli("representation=lambert", *SMALL, "limit=8", f"results_dir={res}", cwd=tmp_path)
        line = one_error_line(out)
        assert "full" in line or "No space left" in line
        stored: set[str] = set()
        if (res / "brdfbench.sqlite").exists():
            with contextlib.closing(sqlite3.connect(res / "brdfbench.sqlite")) as con:
                stored = {m for (m,) in con.execute("SELECT DISTINCT material FROM results")}
        assert len(stored) < 8  # it did fill up
        indexed = {p.name.removesuffix(".json") for p in (res / "artifacts").rglob("*.json")
                   if not p.name.endswith(".lobes.json")} if (res / "artifacts").exists() else set()
        assert indexed <= stored, f"artifacts of cells the store does not hold: {sorted(indexed - stored)}"
        lobes = {p.name.removesuffix(".lobes.json") for p in (res / "artifacts").rglob("*.lobes.json")} \
            if (res / "artifacts").exists() else set()
        assert lobes <= stored


# -- 5. a model file with broken tensors -----------------------------------------------------------


@pytest.fixture(scope="module")
def lambert_file(tmp_path_factory):
    from brdfbench_representations.lambert import Lambert

    path = tmp_path_factory.mktemp("lambert") / "lambert.safetensors"
    modelio.save(Lambert().fit(reference_material()), "lambert", path)
    return path


def _rewritten(src: Path, dest: Path, **tensors) -> Path:
    with safetensors.safe_open(str(src), framework="pt") as f:
        header = f.metadata()
    safetensors.torch.save_file(tensors, str(dest), metadata=header)
    return dest


@pytest.mark.parametrize("albedo, says", [
    (torch.tensor([float("nan"), 0.5, 0.5], dtype=torch.float64), "non-finite"),
    (torch.tensor([-0.2, 0.5, 0.5], dtype=torch.float64), "negative"),
    (torch.full((1000, 3), 0.5, dtype=torch.float64), "shape (1000, 3)"),
], ids=["nan", "negative", "shape"])
def test_inspect_refuses_a_broken_lambert_file(tmp_path, cli, lambert_file, albedo, says):
    path = _rewritten(lambert_file, tmp_path / "broken.safetensors", albedo=albedo)
    line = one_error_line(cli("inspect", str(path), cwd=tmp_path))
    assert str(path) in line and "'albedo'" in line and says in line


# -- 7. Hydra-level typos ----------------------------------------------------------------------------


@pytest.mark.parametrize("args, says", [
    (["representation=lambrt"], "did you mean representation=lambert?"),
    (["dataset=synthtic"], "did you mean dataset=synthetic?"),
    (["generator=hyperdifusion"], "did you mean generator=hyperdiffusion?"),
    (["limt=1"], "limt: the config has no key 'limt'; did you mean limit?"),
    (["dataset.params.sise=small"], "dataset.params has no key 'sise'; did you mean dataset.params.size?"),
    (["reprot"], "did you mean report?"),
    (["limit=[1"], "cannot read the override 'limit=[1'"),
])
def test_a_hydra_level_typo_is_one_line_with_a_suggestion(tmp_path, cli, args, says):
    line = one_error_line(cli(*args, f"results_dir={tmp_path / 'res'}", cwd=tmp_path))
    assert says in line, line
    assert not (tmp_path / "res").exists()


# -- 8. a pickled .pt file -----------------------------------------------------------------------------


class _Payload:
    def __reduce__(self):
        return (Path.touch, (Path("/nonexistent/should-never-exist"),))


def test_a_pickled_pt_is_refused_in_one_line_without_torchs_advice(tmp_path, cli):
    src = tmp_path / "evil.pt"
    torch.save({"fc1.weight": torch.zeros(21, 6), "x": _Payload()}, src)
    line = one_error_line(cli("convert", str(src), str(tmp_path / "out.safetensors"), cwd=tmp_path))
    assert str(src) in line and "nothing in it ran" in line and "accepted:" in line
    assert "weights_only" not in line and "will likely succeed" not in line
    assert not (tmp_path / "out.safetensors").exists()


# -- 9. errors that name their file ------------------------------------------------------------------


def _header_file(path: Path, header: dict, tensors: dict | None = None) -> Path:
    safetensors.torch.save_file(tensors or {"w": torch.zeros(3)}, str(path), metadata={"brdfbench": json.dumps(header)})
    return path


@pytest.mark.parametrize("header, says", [
    ({"format": modelio._FORMAT, "representation": "nbrdf", "params": {"hidden": "abc"}, "metadata": {}}, "hidden='abc'"),
    ({"format": "brdfbench.generator/1", "generator": "pca_brdf", "params": {"k": -1}, "metadata": {}}, "k"),
    ({"format": "brdfbench.generator/1", "representation": "lambert", "params": {}, "metadata": {}}, "generator"),
], ids=["hidden-abc", "generator-k-1", "generator-header-on-a-representation"])
def test_a_model_files_bad_values_name_the_file(tmp_path, cli, header, says):
    path = _header_file(tmp_path / "model.safetensors", header)
    line = one_error_line(cli("inspect", str(path), cwd=tmp_path))
    assert str(path) in line and says in line, line


# -- 10. a store path that is a directory ------------------------------------------------------------


def test_report_on_a_store_that_is_a_directory_says_so(tmp_path, cli):
    (tmp_path / "res" / "brdfbench.sqlite").mkdir(parents=True)
    line = one_error_line(cli("report", "--results", str(tmp_path / "res"), cwd=tmp_path))
    assert "is a directory" in line and "no results store here" not in line


# -- 11. MERL folders, broken entry points, errors printed once ----------------------------------


def test_a_folder_named_like_a_merl_file_is_named(tmp_path, caplog, synthetic_cache):
    from brdfbench.data.merl_folder import merl_folder_dataset

    folder = tmp_path / "merl"
    (folder / "odd.binary").mkdir(parents=True)
    source = next(Path(synthetic_cache).rglob("*.binary"))
    (folder / source.name).write_bytes(source.read_bytes())
    with caplog.at_level(logging.WARNING):
        ds = merl_folder_dataset(folder)
    assert list(ds.materials) == [source.stem]
    assert any(str(folder / "odd.binary") in r.getMessage() and "folder" in r.getMessage() for r in caplog.records)


def test_list_names_a_broken_entry_point_and_lists_the_rest(tmp_path, cli, monkeypatch):
    real = registry._entry_points

    def with_broken(group):
        eps = dict(real(group))
        if group == "representations":
            eps["broken_thing"] = EntryPoint("broken_thing", "no_such_module_anywhere:SPEC", "brdfbench.representations")
        return eps

    monkeypatch.setattr(registry, "_entry_points", with_broken)
    registry.get.cache_clear()
    try:
        out = cli("list", "representations", cwd=tmp_path)
    finally:
        registry.get.cache_clear()
    assert out.returncode == 1
    assert "lambert" in out.stdout and "nbrdf" in out.stdout
    errors = out.stderr.strip().splitlines()
    assert len(errors) == 1 and "broken_thing" in errors[0] and "no_such_module_anywhere" in errors[0]


def test_a_data_error_in_a_run_is_printed_once(tmp_path, cli, synthetic_cache):
    folder = tmp_path / "merl"
    folder.mkdir()
    (folder / "bad.binary").write_bytes(b"\x01" * 1000)
    out = cli("representation=lambert", "dataset=merl_folder", f"dataset.params.path={folder}", "harness=quick",
              f"results_dir={tmp_path / 'res'}", cwd=tmp_path)
    line = one_error_line(out)
    assert str(folder / "bad.binary") in line


# -- 12. a plugin that cannot run on so few materials -------------------------------------------------


def test_a_smoke_run_with_a_small_limit_turns_a_plugin_that_cannot_run_into_failure_rows(tmp_path, cli):
    res = tmp_path / "res"
    out = cli("-m", "representation=lambert,pca", *SMALL, "limit=2", f"results_dir={res}", cwd=tmp_path)
    assert out.returncode == 1, out.stderr
    with contextlib.closing(sqlite3.connect(res / "brdfbench.sqlite")) as con:
        rows = con.execute("SELECT c.label, r.status, r.message FROM results r JOIN configs c USING (config_hash)").fetchall()
    assert {(label, status) for label, status, _ in rows} == {("lambert", "ok"), ("pca", "failed")}
    assert all("needs at least 2 training materials" in m for label, status, m in rows if label == "pca")
    assert (res / "leaderboard.html").exists()


# -- 13. values found at validation ------------------------------------------------------------------


@pytest.mark.parametrize("args, says", [
    (["generator.params.guidance=-1e30"], "guidance=-1e+30 must be a real number in [0, 100]"),
    (["generator.params.guidance=3"], "no effect without a condition"),
])
def test_hyperdiffusion_guidance_out_of_range_or_without_a_condition_is_refused(tmp_path, cli, args, says):
    res = tmp_path / "res"
    line = one_error_line(cli("harness=generation", "generator=hyperdiffusion", "dataset.params.size=small", *args,
                              f"results_dir={res}", cwd=tmp_path))
    assert says in line
    assert not res.exists()


def test_a_missing_init_network_is_found_when_the_sweep_is_validated(tmp_path, cli):
    res = tmp_path / "res"
    missing = tmp_path / "nope.h5"
    out = cli("-m", "representation=nbrdf", f"representation.params.init={missing}", "seed=0,1", *SMALL, "limit=1",
              f"results_dir={res}", cwd=tmp_path)
    line = one_error_line(out)  # both jobs, one reason: said once
    assert f"init: {missing}: no such network file" in line
    assert not res.exists()
