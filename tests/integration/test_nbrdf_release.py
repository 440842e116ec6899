"""NBRDF h5 reader, network evaluation and the nbrdf_release dataset."""

from __future__ import annotations

import math
import os
import shutil

import h5py
import numpy as np
import pytest
import torch

from brdfbench import coords, merl
from brdfbench.data import nbrdf_release
from brdfbench.data.nbrdf_h5 import nbrdf_table
from brdfbench.data.nbrdf_release import find_release_dir, nbrdf_release_dataset
from brdfbench.errors import ConfigError, DataError
from brdfbench.nbrdf.keras_h5 import LAYOUT, read_nbrdf_h5
from brdfbench.nbrdf.network import MAX_LOG_VALUE, forward, rusinkiewicz_input

SHAPES = {name: shape for name, (_, shape) in LAYOUT.items()}


def random_weights(seed: int = 0, scale: float = 0.3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {k: (rng.standard_normal(s) * scale).astype(np.float32) for k, s in SHAPES.items()}


def write_h5(path, weights: dict[str, np.ndarray], skip: str | None = None, override: dict | None = None) -> None:
    """A Keras-2.2-style weights file; `skip` leaves one weight out, `override` replaces arrays."""
    override = override or {}
    with h5py.File(path, "w") as f:
        f.attrs["layer_names"] = np.array([b"dense_1", b"dense_2", b"dense_3", b"lambda_1"])
        for name, (key, _) in LAYOUT.items():
            if name == skip:
                continue
            f.create_dataset(key, data=override.get(name, weights[name]))
        f.create_group("lambda_1")


def reference_forward(w: dict[str, np.ndarray], x: np.ndarray) -> np.ndarray:
    w = {k: v.astype(np.float64) for k, v in w.items()}
    h = np.maximum(x @ w["W1"] + w["b1"], 0)
    h = np.maximum(h @ w["W2"] + w["b2"], 0)
    return np.maximum(np.exp(h @ w["W3"] + w["b3"]) - 1, 0)


# --------------------------------------------------------------------------- the reader


def test_read_roundtrip(tmp_path):
    w = random_weights()
    p = tmp_path / "mat.h5"
    write_h5(p, w)
    (tmp_path / "mat.json").write_text("this is not json and must never be read")
    got = read_nbrdf_h5(p)
    assert set(got) == set(SHAPES)
    for k in SHAPES:
        assert got[k].dtype == np.float32 and got[k].shape == SHAPES[k]
        np.testing.assert_array_equal(got[k], w[k])


@pytest.mark.parametrize("missing", ["W1", "b3"])
def test_missing_dataset(tmp_path, missing):
    p = tmp_path / "broken.h5"
    write_h5(p, random_weights(), skip=missing)
    with pytest.raises(DataError) as exc:
        read_nbrdf_h5(p)
    msg = str(exc.value)
    assert "broken.h5" in msg and LAYOUT[missing][0] in msg and "missing" in msg


def test_wrong_shape(tmp_path):
    p = tmp_path / "shape.h5"
    write_h5(p, random_weights(), override={"W2": np.zeros((21, 20), np.float32)})
    with pytest.raises(DataError) as exc:
        read_nbrdf_h5(p)
    msg = str(exc.value)
    assert "shape.h5" in msg and "dense_2/dense_2/kernel:0" in msg
    assert "(21, 21)" in msg and "(21, 20)" in msg


def test_non_finite_weights(tmp_path):
    w = random_weights()
    b1 = w["b1"].copy()
    b1[3] = np.nan
    p = tmp_path / "nan.h5"
    write_h5(p, w, override={"b1": b1})
    with pytest.raises(DataError, match=r"nan\.h5.*dense_1/dense_1/bias:0.*non-finite"):
        read_nbrdf_h5(p)


def test_non_float_dataset(tmp_path):
    p = tmp_path / "int.h5"
    write_h5(p, random_weights(), override={"b3": np.array([b"a", b"b", b"c"])})
    with pytest.raises(DataError, match=r"int\.h5.*dense_3/dense_3/bias:0.*dtype"):
        read_nbrdf_h5(p)


def test_group_instead_of_dataset(tmp_path):
    p = tmp_path / "group.h5"
    write_h5(p, random_weights(), skip="b2")
    with h5py.File(p, "a") as f:
        f.create_group("dense_2/dense_2/bias:0")
    with pytest.raises(DataError, match=r"group\.h5.*dense_2/dense_2/bias:0.*Group"):
        read_nbrdf_h5(p)


def test_external_link_refused(tmp_path):
    other = tmp_path / "other.h5"
    write_h5(other, random_weights())
    p = tmp_path / "linked.h5"
    write_h5(p, random_weights(), skip="W1")
    with h5py.File(p, "a") as f:
        f["dense_1/dense_1/kernel:0"] = h5py.ExternalLink(str(other), "dense_1/dense_1/kernel:0")
    with pytest.raises(DataError, match=r"linked\.h5.*dense_1/dense_1/kernel:0.*ExternalLink"):
        read_nbrdf_h5(p)


@pytest.mark.parametrize("extra, named", [
    ({"dense_4/dense_4/kernel:0": (3, 3), "dense_4/dense_4/bias:0": (3,)}, "layer 'dense_4' is beyond the 3 dense"),
    ({"dense_2/dense_2/scale:0": (21,)}, "'dense_2/dense_2/scale:0'"),
    ({"lambda_1/weights:0": (4,)}, "'lambda_1/weights:0'"),
    ({"optimizer_weights/m:0": (4,)}, "'optimizer_weights/m:0'"),
], ids=["extra-layer", "extra-weight", "weights-in-the-lambda", "other-group"])
def test_entries_beyond_the_layout_are_refused(tmp_path, extra, named):
    """Weights the 6-21-21-3 layout does not have (an extra layer most of all) are refused,
    not silently dropped from the network read."""
    p = tmp_path / "deeper.h5"
    write_h5(p, random_weights())
    with h5py.File(p, "a") as f:
        for key, shape in extra.items():
            f.create_dataset(key, data=np.zeros(shape, np.float32))
    with pytest.raises(DataError) as exc:
        read_nbrdf_h5(p)
    msg = str(exc.value)
    assert "deeper.h5" in msg and named in msg and "unexpected entry" in msg


def test_a_link_beyond_the_layout_is_refused(tmp_path):
    p = tmp_path / "alias.h5"
    write_h5(p, random_weights())
    with h5py.File(p, "a") as f:
        f["dense_1/alias"] = h5py.SoftLink("/dense_1/dense_1/kernel:0")
    with pytest.raises(DataError, match=r"alias\.h5: unexpected entry 'dense_1/alias'"):
        read_nbrdf_h5(p)


def test_a_deeper_network_reads_with_its_hidden_widths(tmp_path):
    from brdfbench.nbrdf.keras_h5 import layout

    hidden = (21, 21, 21)
    p = tmp_path / "deep.h5"
    rng = np.random.default_rng(5)
    with h5py.File(p, "w") as f:
        for key, shape in layout(hidden).values():
            f.create_dataset(key, data=rng.standard_normal(shape).astype(np.float32))
    assert len(read_nbrdf_h5(p, hidden=hidden)) == 8
    with pytest.raises(DataError, match=r"deep\.h5.*dense_3/dense_3/kernel:0.*wrong shape"):
        read_nbrdf_h5(p)


def test_not_hdf5(tmp_path):
    p = tmp_path / "fake.h5"
    p.write_bytes(b"definitely not an HDF5 file" * 10)
    with pytest.raises(DataError, match=r"fake\.h5.*HDF5"):
        read_nbrdf_h5(p)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(DataError, match=r"nope\.h5"):
        read_nbrdf_h5(tmp_path / "nope.h5")
    with pytest.raises(DataError, match="directory"):
        read_nbrdf_h5(tmp_path)


# --------------------------------------------------------------------------- the network


def test_forward_hand_computed():
    w = {k: np.zeros(s, np.float32) for k, s in SHAPES.items()}
    w["W1"][0, 0] = 2.0  # h1[0] = 2 x0
    w["W1"][1, 1] = -1.0  # h1[1] = relu(-x1) = 0 for x1 > 0
    w["W2"][0, 0] = 0.5  # h2[0] = h1[0] / 2
    w["W2"][1, 1] = 7.0
    w["W3"][0] = [1.0, 0.0, -1.0]
    w["W3"][1] = [5.0, 5.0, 5.0]
    w["b3"][:] = [0.0, math.log(2.0), 0.0]
    x = torch.tensor([[1.0, 3.0, 0, 0, 0, 0], [0.0, 0, 0, 0, 0, 0]], dtype=torch.float64)
    y = forward(w, x)
    expected = torch.tensor([[math.e - 1, 1.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
    torch.testing.assert_close(y, expected, rtol=1e-6, atol=1e-6)  # ln 2 is stored in float32


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_forward_matches_numpy(dtype):
    w = random_weights(seed=1)
    x = np.random.default_rng(2).uniform(-1, 1, size=(64, 6))
    y = forward(w, torch.tensor(x, dtype=dtype))
    assert y.dtype == dtype and y.shape == (64, 3)
    ref = reference_forward(w, x)
    assert (ref > 0).any() and (ref == 0).any()  # both branches of the final clamp exercised
    tol = 1e-5 if dtype == torch.float32 else 1e-12
    np.testing.assert_allclose(y.numpy(), ref, rtol=tol, atol=tol)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_overflow_guard(dtype):
    w = random_weights()
    w["b3"] = np.array([1e4, 1e30, -1e4], np.float32)
    x = torch.rand(10, 6, dtype=dtype)
    y = forward(w, x)
    assert torch.isfinite(y).all()
    torch.testing.assert_close(y[:, 0], torch.full((10,), math.expm1(MAX_LOG_VALUE), dtype=dtype))
    assert (y[:, 2] == 0).all()


def test_input_layout():
    th, ph, td, pd = 0.3, 0.7, 0.4, 4.0  # φd > π: must not be folded
    t = lambda v: torch.tensor([v], dtype=torch.float64)  # noqa: E731
    wi, wo = coords.from_half_diff(t(th), t(ph), t(td), t(pd))
    x = rusinkiewicz_input(wi, wo)
    expected = [math.sin(th), 0.0, math.cos(th), math.sin(td) * math.cos(pd), math.sin(td) * math.sin(pd), math.cos(td)]
    assert x.shape == (1, 6) and x.dtype == torch.float64
    np.testing.assert_allclose(x[0].numpy(), expected, atol=1e-12)
    assert rusinkiewicz_input(wi.float(), wo.float()).dtype == torch.float32


def test_table_from_synthetic_weights():
    w = random_weights(seed=3, scale=0.2)
    table = nbrdf_table(w)
    assert table.raw.shape == (3, *merl.SHAPE)
    wi, wo = merl.grid_directions()
    above = coords.above_horizon(wi, wo).numpy().reshape(merl.SHAPE)
    assert not above.all() and above.any()
    np.testing.assert_array_equal(table.valid, above)
    assert (table.raw[:, ~above] == merl.INVALID_RAW).all()
    # Table order: cell (i, j, k) holds the network at that cell's centre.
    idx = np.random.default_rng(4).integers(0, merl.N_CELLS, 200)
    idx = idx[above.reshape(-1)[idx]]
    direct = forward(w, rusinkiewicz_input(wi[idx], wo[idx])).numpy()
    flat = table.values.reshape(3, -1)[:, idx].T
    np.testing.assert_allclose(flat, direct, rtol=1e-4, atol=1e-6)


# --------------------------------------------------------------------------- the dataset (fake release)


@pytest.fixture
def fake_release(tmp_path):
    root = tmp_path / "neural-brdf"
    (root / "merl").mkdir(parents=True)
    for i, name in enumerate(["zeta", "alpha"]):
        write_h5(root / "merl" / f"{name}.h5", random_weights(seed=i, scale=0.2))
        (root / "merl" / f"{name}.json").write_text("{not json")
    (root / "nielsen").mkdir()
    return root


def test_dataset_from_explicit_path(fake_release):
    ds = nbrdf_release_dataset(str(fake_release))
    assert ds.materials == ("alpha", "zeta")
    assert ds.categories == {"alpha": "merl", "zeta": "merl"}
    m = ds.load("alpha")
    assert m.name == "alpha" and m.category == "merl" and m.source.endswith("alpha.h5")
    assert m.table.raw.shape == (3, *merl.SHAPE)
    assert nbrdf_release_dataset(str(fake_release), limit=1).materials == ("alpha",)
    assert nbrdf_release_dataset(str(fake_release)).fingerprint == ds.fingerprint


def test_dataset_fingerprint_changes(fake_release):
    before = nbrdf_release_dataset(str(fake_release)).fingerprint
    write_h5(fake_release / "merl" / "beta.h5", random_weights(seed=9))
    assert nbrdf_release_dataset(str(fake_release)).fingerprint != before


def test_dataset_fingerprint_sees_a_network_replaced_by_another_of_the_same_size(fake_release):
    """Every published network is 18736 bytes: the fingerprint must follow the content."""
    before = nbrdf_release_dataset(str(fake_release)).fingerprint
    alpha, zeta = fake_release / "merl" / "alpha.h5", fake_release / "merl" / "zeta.h5"
    size, mtime = zeta.stat().st_size, zeta.stat().st_mtime_ns
    zeta.write_bytes(alpha.read_bytes())
    os.utime(zeta, ns=(mtime, mtime))
    assert zeta.stat().st_size == size
    assert nbrdf_release_dataset(str(fake_release)).fingerprint != before


@pytest.mark.shared_data
def test_published_network_swapped_for_another_is_new_data(release, tmp_path):
    root = tmp_path / "release"
    (root / "merl").mkdir(parents=True)
    for name in ("alum-bronze", "white-paint"):
        shutil.copy(release / "merl" / f"{name}.h5", root / "merl" / f"{name}.h5")
    before = nbrdf_release_dataset(str(root)).fingerprint
    shutil.copy(release / "merl" / "black-obsidian.h5", root / "merl" / "white-paint.h5")
    assert nbrdf_release_dataset(str(root)).fingerprint != before


def test_dataset_errors(fake_release, tmp_path):
    with pytest.raises(ConfigError, match="subset"):
        nbrdf_release_dataset(str(fake_release), subset="anisotropic")
    with pytest.raises(DataError, match="no .h5 files"):
        nbrdf_release_dataset(str(fake_release), subset="nielsen")
    with pytest.raises(DataError, match="rgl-isotropic"):
        nbrdf_release_dataset(str(fake_release), subset="rgl-isotropic")
    with pytest.raises(DataError, match="missing-dir"):
        nbrdf_release_dataset(str(tmp_path / "missing-dir"))


def test_env_var(fake_release, monkeypatch, tmp_path):
    monkeypatch.setenv("BRDFBENCH_NBRDF_DIR", str(fake_release))
    assert find_release_dir() == fake_release
    assert nbrdf_release_dataset().materials == ("alpha", "zeta")
    monkeypatch.setenv("BRDFBENCH_NBRDF_DIR", str(tmp_path / "nowhere"))
    assert find_release_dir() is None
    with pytest.raises(DataError, match="BRDFBENCH_NBRDF_DIR"):
        nbrdf_release_dataset()


def test_search_upward(fake_release, monkeypatch, tmp_path):
    monkeypatch.delenv("BRDFBENCH_NBRDF_DIR", raising=False)
    # Pretend both the working directory and the package live where there is no release ...
    isolated = tmp_path / "isolated" / "repo"
    (isolated / "pkg").mkdir(parents=True)
    monkeypatch.chdir(isolated)
    monkeypatch.setattr(nbrdf_release, "__file__", str(isolated / "pkg" / "nbrdf_release.py"))
    if find_release_dir() is not None:  # a release above tmp_path (e.g. /shared) would be found, rightly
        pytest.skip("a shared/data/neural-brdf exists above the temporary directory")
    with pytest.raises(DataError, match="BRDFBENCH_NBRDF_DIR"):
        nbrdf_release_dataset()
    # ... then put one beside the "repository", as the project layout does.
    sibling = tmp_path / "isolated" / "shared" / "data"
    sibling.mkdir(parents=True)
    fake_release.rename(sibling / "neural-brdf")
    assert find_release_dir() == sibling / "neural-brdf"
    assert nbrdf_release_dataset().materials == ("alpha", "zeta")


# --------------------------------------------------------------------------- the real release


@pytest.fixture(scope="module")
def release(nbrdf_release_dir):
    return nbrdf_release_dir


@pytest.mark.shared_data
def test_release_subsets(release):
    counts = {s: len(nbrdf_release_dataset(str(release), subset=s)) for s in ("merl", "nielsen", "rgl-isotropic")}
    assert counts == {"merl": 100, "nielsen": 8, "rgl-isotropic": 51}


@pytest.mark.shared_data
@pytest.mark.parametrize("name", ["alum-bronze", "white-paint"])
def test_release_material(release, name):
    ds = nbrdf_release_dataset(str(release))
    assert name in ds.materials
    m = ds.load(name)
    assert m.category == "merl" and m.source.endswith(f"{name}.h5")
    t = m.table
    assert t.raw.shape == (3, 90, 90, 180)
    assert np.isfinite(t.raw).all()
    wi, wo = merl.grid_directions()
    above = coords.above_horizon(wi, wo).numpy().reshape(merl.SHAPE)
    np.testing.assert_array_equal(t.valid, above)
    assert (t.raw[:, ~above] == merl.INVALID_RAW).all()
    v = t.values[:, t.valid]
    assert (v >= 0).all()
    med = np.median(v, axis=1)
    assert ((med > 1e-3) & (med < 10)).all(), med
    assert v.max() < 1e5  # a few thousand at most for the brightest MERL specular peaks


@pytest.mark.shared_data
def test_release_other_subsets_load(release):
    for subset in ("nielsen", "rgl-isotropic"):
        ds = nbrdf_release_dataset(str(release), subset=subset, limit=1)
        assert len(ds) == 1
        m = ds.load(ds.materials[0])
        assert m.category == subset
        assert np.isfinite(m.table.raw).all() and (m.table.values[:, m.table.valid] >= 0).all()


# --------------------------------------------------------------------------- the grid-output cache


def _cache_files(cache_dir):
    return sorted((cache_dir / "nbrdf_release").glob("*/*.npy"))


def test_cached_load_is_the_evaluated_table_bit_for_bit(fake_release, tmp_path, monkeypatch):
    """The first load evaluates the network and keeps its outputs; later loads (every job of a
    sweep) read them back and build the very table the evaluation gives."""
    monkeypatch.setenv("BRDFBENCH_CACHE", str(tmp_path / "cache"))
    first = nbrdf_release_dataset(str(fake_release)).load("alpha")
    files = _cache_files(tmp_path / "cache")
    assert len(files) == 1 and files[0].with_name(files[0].name + ".sha256").exists()
    calls = []
    monkeypatch.setattr("brdfbench.data.nbrdf_release.grid_outputs", lambda w: calls.append(w))
    again = nbrdf_release_dataset(str(fake_release)).load("alpha")
    assert calls == []  # read back, not evaluated
    direct = nbrdf_table(read_nbrdf_h5(fake_release / "merl" / "alpha.h5"))
    assert again.table.raw.tobytes() == first.table.raw.tobytes() == direct.raw.tobytes()


def test_cache_is_keyed_by_the_weights(fake_release, tmp_path, monkeypatch):
    """A network replaced by another (same file size) is evaluated anew, never served the old outputs."""
    monkeypatch.setenv("BRDFBENCH_CACHE", str(tmp_path / "cache"))
    nbrdf_release_dataset(str(fake_release)).load("zeta")
    alpha, zeta = fake_release / "merl" / "alpha.h5", fake_release / "merl" / "zeta.h5"
    zeta.write_bytes(alpha.read_bytes())
    swapped = nbrdf_release_dataset(str(fake_release)).load("zeta")
    assert swapped.table.raw.tobytes() == nbrdf_table(read_nbrdf_h5(alpha)).raw.tobytes()


@pytest.mark.parametrize("damage", ["append", "truncate", "other_array"])
def test_damaged_cache_file_is_recomputed_with_a_warning(fake_release, tmp_path, monkeypatch, caplog, damage):
    monkeypatch.setenv("BRDFBENCH_CACHE", str(tmp_path / "cache"))
    nbrdf_release_dataset(str(fake_release)).load("alpha")
    (path,) = _cache_files(tmp_path / "cache")
    if damage == "append":
        with open(path, "ab") as f:
            f.write(b"garbage")
    elif damage == "truncate":
        path.write_bytes(path.read_bytes()[:1000])
    else:  # a valid .npy of the right shape, other values: only the content record tells
        np.save(path, np.zeros(np.load(path).shape, dtype=np.float32))
    with caplog.at_level("WARNING"):
        again = nbrdf_release_dataset(str(fake_release)).load("alpha")
    assert "recomputing" in caplog.text and str(path) in caplog.text
    assert again.table.raw.tobytes() == nbrdf_table(read_nbrdf_h5(fake_release / "merl" / "alpha.h5")).raw.tobytes()
    caplog.clear()
    with caplog.at_level("WARNING"):  # rewritten: the next load is clean
        nbrdf_release_dataset(str(fake_release)).load("alpha")
    assert "recomputing" not in caplog.text


def test_unwritable_cache_only_costs_the_evaluation(fake_release, tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder would go")
    monkeypatch.setenv("BRDFBENCH_CACHE", str(blocker))
    with caplog.at_level("WARNING"):
        ds = nbrdf_release_dataset(str(fake_release))
        a, z = ds.load("alpha"), ds.load("zeta")
    assert caplog.text.count("cannot write the cache") == 1  # said once, not per material
    assert a.table.raw.tobytes() == nbrdf_table(read_nbrdf_h5(fake_release / "merl" / "alpha.h5")).raw.tobytes()
    assert z.table.raw.shape == (3, *merl.SHAPE)
