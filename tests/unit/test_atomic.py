"""brdfbench.atomic.replacing: atomic replacement, with the permissions of a plain open()."""

from __future__ import annotations

import os
import stat

import pytest

from brdfbench.atomic import replacing


@pytest.fixture
def umask():
    """Set the process umask for one test, then restore it."""
    saved = os.umask(0o022)
    yield os.umask
    os.umask(saved)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_written_file_gets_the_mode_a_plain_open_gives(tmp_path, umask, mask):
    umask(mask)
    with open(tmp_path / "plain.txt", "w") as f:
        f.write("x")
    with replacing(tmp_path / "atomic.txt") as tmp:
        tmp.write_text("x")
    assert mode(tmp_path / "atomic.txt") == mode(tmp_path / "plain.txt") == 0o666 & ~mask


def test_writers_built_on_it_get_that_mode(tmp_path, umask):
    import numpy as np
    import torch

    from brdfbench import merl, modelio
    from brdfbench_representations.lambert import Lambert

    umask(0o022)
    merl.write_binary(tmp_path / "t.binary", merl.MerlTable(np.zeros((3, *merl.SHAPE))))
    modelio.save(Lambert(), "lambert", tmp_path / "m.safetensors")
    assert mode(tmp_path / "t.binary") == mode(tmp_path / "m.safetensors") == 0o644
    assert torch.equal(modelio.load(tmp_path / "m.safetensors")[1].albedo, Lambert().albedo)


def test_replaces_atomically_and_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with replacing(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer failed")
    assert target.read_text() == "old"
    with replacing(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_temporary_names_are_unique(tmp_path):
    with replacing(tmp_path / "a") as first, replacing(tmp_path / "a") as second:
        assert first != second and first.exists() and second.exists()
        first.write_text("1")
        second.write_text("2")
    assert (tmp_path / "a").read_text() == "1"  # the outer context finishes last
