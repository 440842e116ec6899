"""The merl_folder dataset: every MERL .binary file in a folder."""

from __future__ import annotations

import errno
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
    assert merl_folder_dataset(str(folder)).fingerprint == fp  # same bytes: same data
    merl.write_binary(folder / "copper.binary", table)
    assert merl_folder_dataset(str(folder)).fingerprint != fp


def test_fingerprint_sees_a_file_replaced_by_another_of_the_same_size(folder):
    """Content, not size: another material's table in zinc.binary is new data."""
    fp = merl_folder_dataset(str(folder)).fingerprint
    st = (folder / "zinc.binary").stat()
    merl.write_binary(folder / "zinc.binary", merl.MerlTable(np.full((3, 90, 90, 180), 0.25)))
    os.utime(folder / "zinc.binary", ns=(st.st_atime_ns, st.st_mtime_ns))  # even with the old mtime
    assert (folder / "zinc.binary").stat().st_size == st.st_size
    assert merl_folder_dataset(str(folder)).fingerprint != fp


def test_digests_are_cached_by_size_and_mtime(folder, monkeypatch, tmp_path):
    from brdfbench.data import content_hash

    monkeypatch.setenv("BRDFBENCH_CACHE", str(tmp_path / "cache"))
    old = 1_000_000_000 * 10**9  # settled long ago
    for f in folder.glob("*.binary"):
        os.utime(f, ns=(old, old))
    fp = merl_folder_dataset(str(folder)).fingerprint
    assert (tmp_path / "cache" / content_hash.CACHE_NAME).is_file()

    def boom(path):
        raise AssertionError(f"re-hashed {path}")

    monkeypatch.setattr(content_hash, "sha256_file", boom)
    assert merl_folder_dataset(str(folder)).fingerprint == fp
    os.utime(folder / "zinc.binary", ns=(old, old + 1))  # a changed mtime is hashed again
    with pytest.raises(AssertionError, match="re-hashed .*zinc"):
        merl_folder_dataset(str(folder))


def _denying_scandir(monkeypatch, denied):
    real = os.scandir

    def scandir(path="."):
        if os.fspath(path) == os.fspath(denied):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)


def test_unlistable_folder_is_permission_denied_not_empty(folder, monkeypatch):
    _denying_scandir(monkeypatch, folder)
    with pytest.raises(DataError, match=rf"{folder}: cannot list MERL folder \(permission denied\)") as err:
        merl_folder_dataset(str(folder))
    assert "no .binary files" not in str(err.value)


def test_unlistable_subfolder_is_named(folder, monkeypatch, table):
    sub = folder / "metals"
    sub.mkdir()
    merl.write_binary(sub / "chrome.binary", table)
    _denying_scandir(monkeypatch, sub)
    with pytest.raises(DataError, match=rf"{sub}: cannot list MERL folder \(permission denied\)"):
        merl_folder_dataset(str(folder), recursive=True)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root lists any folder: chmod does not deny")
def test_chmod_000_folder_is_permission_denied(folder):
    folder.chmod(0)
    try:
        with pytest.raises(DataError, match=r"permission denied"):
            merl_folder_dataset(str(folder))
    finally:
        folder.chmod(0o755)


def test_unreachable_folder_is_not_reported_missing(tmp_path, monkeypatch):
    """A folder below one without search permission: os.stat fails with EACCES."""
    real = os.stat

    def stat(path, *args, **kwargs):
        if os.fspath(path) == str(tmp_path):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat)
    with pytest.raises(DataError, match=r"cannot reach MERL folder \(permission denied\)"):
        merl_folder_dataset(str(tmp_path))


def test_missing_folder_and_file_messages_say_what_to_pass(tmp_path):
    with pytest.raises(DataError, match=r"does not exist; pass the folder holding your MERL \.binary files"):
        merl_folder_dataset(str(tmp_path / "nowhere"))
    with pytest.raises(DataError, match=r"does not exist"):
        merl_folder_dataset(str(tmp_path / "nowhere" / "deeper"))
    f = tmp_path / "chrome.binary"
    f.write_bytes(b"x")
    with pytest.raises(DataError, match=rf"{f}: is a MERL file, not a directory; pass its folder \({tmp_path}\)"):
        merl_folder_dataset(str(f))
    notes = tmp_path / "notes.txt"
    notes.write_text("x")
    with pytest.raises(DataError, match=rf"{notes}: is a file, not a directory; pass the folder holding"):
        merl_folder_dataset(str(notes))
    with pytest.raises(DataError, match="no folder given"):
        merl_folder_dataset("")
