"""The merl_folder dataset: every MERL .binary file in a folder."""

from __future__ import annotations

import os

import numpy as np
import pytest

from brdfbench import merl
from brdfbench.data.merl_folder import merl_folder_dataset
from brdfbench.errors import DataError


@pytest.fixture(scope="module")
def table():
    return merl.MerlTable(np.full((3, 90, 90, 180), 0.5))


@pytest.fixture
def folder(tmp_path, table):
    d = tmp_path / "merl"
    d.mkdir()
    merl.write_binary(d / "zinc.binary", table)
    merl.write_binary(d / "brass.binary", table)
    (d / "notes.txt").write_text("not a material")
    return d


def test_lists_and_loads(folder, table):
    ds = merl_folder_dataset(str(folder))
    assert ds.materials == ("brass", "zinc")
    assert ds.categories == {"brass": "merl", "zinc": "merl"}
    for m in ds:
        assert m.category == "merl"
        assert m.source == str(folder / f"{m.name}.binary")
        np.testing.assert_array_equal(m.table.raw, table.raw)
        assert m.table.valid.all()


def test_nonexistent(tmp_path):
    with pytest.raises(DataError, match=r"no-such-folder.*does not exist"):
        merl_folder_dataset(str(tmp_path / "no-such-folder"))


def test_file_not_dir(tmp_path):
    f = tmp_path / "one.binary"
    f.write_bytes(b"x")
    with pytest.raises(DataError, match=r"one\.binary.*not a directory"):
        merl_folder_dataset(str(f))


def test_empty_dir(tmp_path):
    d = tmp_path / "empty"
    d.mkdir()
    (d / "readme.txt").write_text("nothing here")
    with pytest.raises(DataError, match=r"empty.*is not a MERL folder: no \.binary files"):
        merl_folder_dataset(str(d))


def test_truncated_file_raises_on_load(folder):
    bad = folder / "broken.binary"
    bad.write_bytes((folder / "zinc.binary").read_bytes()[:1000])
    ds = merl_folder_dataset(str(folder))
    assert ds.materials == ("brass", "broken", "zinc")
    ds.load("brass")  # the others still load
    with pytest.raises(DataError, match=r"broken\.binary.*truncated"):
        ds.load("broken")


def test_recursive(folder, table):
    sub = folder / "metals"
    sub.mkdir()
    merl.write_binary(sub / "chrome.binary", table)
    assert merl_folder_dataset(str(folder)).materials == ("brass", "zinc")
    ds = merl_folder_dataset(str(folder), recursive=True)
    assert ds.materials == ("brass", "metals/chrome", "zinc")
    assert ds.load("metals/chrome").source == str(sub / "chrome.binary")


def test_fingerprint(folder, table):
    fp = merl_folder_dataset(str(folder)).fingerprint
    assert merl_folder_dataset(str(folder)).fingerprint == fp
    st = (folder / "zinc.binary").stat()
    os.utime(folder / "zinc.binary", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    fp2 = merl_folder_dataset(str(folder)).fingerprint
    assert fp2 != fp
    merl.write_binary(folder / "copper.binary", table)
    assert merl_folder_dataset(str(folder)).fingerprint not in (fp, fp2)
