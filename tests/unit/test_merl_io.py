"""MERL `.binary` I/O, validation and lookup against the reference reader (BRDFRead.cpp).

`merl_reference.py` is a scalar float64 port of the reader's lookup; `lookup_nearest` must
return bitwise the same values, cell edges and degenerate pairs included: the lookup runs
the reader's own operations, so even where the reader's cell is decided by rounding noise
(φd on the 0 ≡ π fold for pairs in one plane with the normal, φd on the 90° edge for pairs
with equal polar angles, φd at ωi = ωo, angles exactly on a cell edge) it is the same
noise. The adversarial sets and the property test are in test_merl_reference_agreement.py.
"""

from __future__ import annotations

import importlib.util
import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from brdfbench import coords, merl
from brdfbench.errors import DataError

_spec = importlib.util.spec_from_file_location("merl_reference", Path(__file__).with_name("merl_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)

RNG_SEED = 0
HALF_PI = math.pi / 2


@pytest.fixture(scope="module")
def raw() -> np.ndarray:
    return np.random.default_rng(RNG_SEED).random((3, *merl.SHAPE))


@pytest.fixture(scope="module")
def table(raw) -> merl.MerlTable:
    return merl.MerlTable(raw)


@pytest.fixture(scope="module")
def file_bytes(raw) -> bytes:
    """A valid file, built by hand from the format (not by write_binary)."""
    return np.asarray([90, 90, 180], dtype="<i4").tobytes() + raw.astype("<f8").tobytes()


def as_vectors(pairs):
    vi = torch.tensor([p[0] for p in pairs], dtype=torch.float64)
    vo = torch.tensor([p[1] for p in pairs], dtype=torch.float64)
    return vi, vo


def reference_values(raw, pairs) -> np.ndarray:
    flat = raw.reshape(-1)
    return np.array([ref.lookup_from_vectors(flat, a, b) for a, b in pairs], dtype=np.float64)


def reference_indices(pairs) -> np.ndarray:
    return np.array([ref.indices_from_vectors(a, b) for a, b in pairs])


def our_indices(pairs) -> np.ndarray:
    return np.stack([i.numpy() for i in merl.cell_indices(*as_vectors(pairs))], axis=1)


def assert_bitwise_same(table, raw, pairs):
    got = merl.lookup_nearest(table.values, *as_vectors(pairs)).numpy()
    want = reference_values(raw, pairs)
    assert got.dtype == np.float64 and got.shape == (len(pairs), 3)
    same = (got.view(np.uint64) == want.view(np.uint64)).all(axis=1)
    if not same.all():
        k = int(np.flatnonzero(~same)[0])
        a, b = pairs[k]
        pytest.fail(
            f"{int((~same).sum())}/{len(pairs)} differ; first ωi={a} ωo={b}: "
            f"ours {our_indices([pairs[k]])[0]}, reference {reference_indices([pairs[k]])[0]} "
            f"(reference angles {ref.half_diff_from_vectors(a, b)})"
        )


def unit_pairs_from_angles(th, ph, td, pd):
    """Direction pairs from Rusinkiewicz angles (via coords), normalised as the reader does."""
    wi, wo = coords.from_half_diff(*(torch.as_tensor(np.asarray(x, dtype=np.float64)) for x in (th, ph, td, pd)))
    keep = coords.above_horizon(wi, wo)
    return [(ref.normalize(tuple(a)), ref.normalize(tuple(b))) for a, b in zip(wi[keep].tolist(), wo[keep].tolist())]


def random_pairs(rng, n, max_theta=HALF_PI):
    """Pairs built the reader's way, its two vectors from spherical angles (cosine-uniform polar angles)."""
    ti = np.arccos(rng.uniform(math.cos(max_theta), 1.0, n))
    to = np.arccos(rng.uniform(math.cos(max_theta), 1.0, n))
    pi_, po = rng.uniform(-math.pi, math.pi, (2, n))
    pairs = [
        (ref.reader_vector(float(a), float(b)), ref.reader_vector(float(c), float(d)))
        for a, b, c, d in zip(ti, pi_, to, po)
    ]
    return [(a, b) for a, b in pairs if a[2] > 0 and b[2] > 0]


# --------------------------------------------------------------------------- lookup vs the reference


def test_nearest_matches_reference_random(table, raw):
    rng = np.random.default_rng(1)
    pairs = random_pairs(rng, 6000)
    assert len(pairs) > 5900
    assert_bitwise_same(table, raw, pairs)
    # The MerlTable method and the reader's angle-based entry point agree too.
    vi, vo = as_vectors(pairs[:500])
    assert torch.equal(table.lookup(vi, vo), merl.lookup_nearest(table.values, vi, vo))
    assert torch.equal(table.lookup(vi, vo, mode="nearest"), merl.lookup_nearest(table.values, vi, vo))


def test_nearest_matches_reference_angle_entry_point(table, raw):
    """lookup_brdf_val(θi, φi, θo, φo), the reader's own signature: `lookup_angles` at the
    angles, and `lookup` at the two vectors the reader builds from them, bitwise."""
    rng = np.random.default_rng(2)
    n = 1000
    ti, to = rng.uniform(0, math.radians(89.99), (2, n))
    pi_, po = rng.uniform(-math.pi, math.pi, (2, n))
    flat = raw.reshape(-1)
    want = np.array([ref.lookup_brdf_val(flat, *map(float, x)) for x in zip(ti, pi_, to, po)])
    got = table.lookup_angles(*(torch.from_numpy(x) for x in (ti, pi_, to, po))).numpy()
    assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
    assert np.array_equal(merl.lookup_nearest_angles(table.values, ti, pi_, to, po).numpy(), got)
    pairs = [(ref.reader_vector(float(a), float(b)), ref.reader_vector(float(c), float(d))) for a, b, c, d in zip(ti, pi_, to, po)]
    got = table.lookup(*as_vectors(pairs)).numpy()
    assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
    # Angles broadcast; the trilinear mode interpolates at the reader's vectors.
    one = table.lookup_angles(0.3, torch.tensor([0.1, 0.2]), 0.4, 2.0)
    assert one.shape == (2, 3) and torch.equal(one[0], table.lookup_angles(0.3, 0.1, 0.4, 2.0)[0])
    tri = table.lookup_angles(ti[:50], pi_[:50], to[:50], po[:50], mode="trilinear")
    assert torch.equal(tri, table.lookup(*as_vectors(pairs[:50]), mode="trilinear"))
    with pytest.raises(ValueError, match="bogus"):
        table.lookup_angles(0.1, 0.2, 0.3, 0.4, mode="bogus")


def test_nearest_matches_reference_specular_and_grazing(table, raw):
    rng = np.random.default_rng(3)
    n = 2000
    # Near-specular pairs: θh small, where the square-root warp is steepest.
    th = (10.0 ** rng.uniform(-6, 0, n)) * HALF_PI / 4
    pairs = unit_pairs_from_angles(th, rng.uniform(-math.pi, math.pi, n), rng.uniform(0.01, 1.4, n), rng.uniform(0, 2 * math.pi, n))
    assert_bitwise_same(table, raw, pairs)
    # Grazing: one direction at 89.99°, the other anywhere or also grazing (89°..89.99°).
    g = math.radians(89.99)
    one = [(ref.reader_vector(g, float(a)), ref.reader_vector(float(t), float(b))) for a, b, t in zip(*rng.uniform(-math.pi, math.pi, (2, n)), rng.uniform(0, g, n))]
    both = [(ref.reader_vector(g, float(a)), ref.reader_vector(float(t), float(b))) for a, b, t in zip(*rng.uniform(-math.pi, math.pi, (2, n)), rng.uniform(math.radians(89.0), g, n))]
    assert_bitwise_same(table, raw, one + both + [(b, a) for a, b in one + both])


def test_equal_polar_angles_sit_on_a_cell_edge(table, raw):
    """θi = θo puts φd at exactly ±π/2, the edge between φd cells 89 and 90: the reader's
    side is decided by rounding, and the lookup's is the same (here at grazing 89.99°,
    and at 30°)."""
    rng = np.random.default_rng(11)
    for theta in (math.radians(89.99), math.radians(30.0)):
        pairs = [(ref.reader_vector(theta, float(a)), ref.reader_vector(theta, float(b))) for a, b in rng.uniform(-math.pi, math.pi, (1000, 2))]
        pairs = [(a, b) for a, b in pairs if abs(a[0] - b[0]) + abs(a[1] - b[1]) > 1e-3]
        ours, theirs = our_indices(pairs), reference_indices(pairs)
        assert np.array_equal(ours, theirs)
        assert np.isin(theirs[:, 2], [89, 90]).all() and len(np.unique(theirs[:, 2])) == 2
        assert_bitwise_same(table, raw, pairs)


def test_nearest_matches_reference_theta_h_zero(table, raw):
    """ωo = ωi mirrored about the normal: h is exactly the normal in both, θh index 0."""
    rng = np.random.default_rng(4)
    n = 2000
    wi = [ref.reader_vector(float(t), float(p)) for t, p in zip(rng.uniform(0, math.radians(89.99), n), rng.uniform(-math.pi, math.pi, n))]
    wi += [(0.0, 0.0, 1.0)]
    pairs = [(a, (-a[0], -a[1], a[2])) for a in wi]
    assert (our_indices(pairs)[:, 0] == 0).all()
    assert_bitwise_same(table, raw, pairs)


def test_nearest_matches_reference_near_cell_edges(table, raw):
    """Angles 1e-10 .. 1e-4 rad either side of θh, θd and φd cell edges, φd = 0 ≡ π fold included."""
    rng = np.random.default_rng(5)
    n = 300
    pairs = []
    for delta in (1e-10, 1e-7, 1e-4):
        for sign in (-1.0, 1.0):
            # φd near 0, π and 2π (the reciprocity fold) and near other cell edges.
            for base in (0.0, math.pi, 2 * math.pi, math.radians(37.0), math.pi + math.radians(122.0)):
                pd = np.full(n, base + sign * delta)
                pairs += unit_pairs_from_angles(rng.uniform(0.01, 1.4, n), rng.uniform(-math.pi, math.pi, n), rng.uniform(0.01, 1.4, n), pd)
            # θd near a cell edge (k degrees).
            k = rng.integers(1, 90, n)
            pairs += unit_pairs_from_angles(rng.uniform(0.01, 0.6, n), rng.uniform(-math.pi, math.pi, n), np.radians(k) + sign * delta, rng.uniform(0.1, 3.0, n))
            # θh near a cell edge ((k/90)² · π/2).
            k = rng.integers(1, 60, n)
            pairs += unit_pairs_from_angles((k / 90.0) ** 2 * HALF_PI + sign * delta, rng.uniform(-math.pi, math.pi, n), rng.uniform(0.01, 0.6, n), rng.uniform(0.1, 3.0, n))
    assert len(pairs) > 8000
    assert_bitwise_same(table, raw, pairs)


def test_identical_directions(table, raw):
    """ωi = ωo: the reader's θd is acos of (1 ± rounding) — 0, a few 1e-8 or NaN (cast to
    cell 0) — and its φd is the atan2 of rounding residues: undefined, but the lookup
    reproduces it, so the cells and values are bitwise the reader's."""
    rng = np.random.default_rng(6)
    wi = [ref.reader_vector(float(t), float(p)) for t, p in zip(rng.uniform(0, math.radians(89.99), 2000), rng.uniform(-math.pi, math.pi, 2000))]
    wi += [(0.0, 0.0, 1.0), ref.reader_vector(math.radians(89.99), 0.3)]
    pairs = [(a, a) for a in wi]
    ours, theirs = our_indices(pairs), reference_indices(pairs)
    assert np.array_equal(ours, theirs)
    assert (ours[:, 1] == 0).all() and len(np.unique(ours[:, 2])) > 20  # φd: all over the row
    assert_bitwise_same(table, raw, pairs)


def test_in_plane_pairs_fold_ambiguity(table, raw):
    """Pairs in one plane with the normal have φd = 0 ≡ π: the reader puts them in cell 0
    or 179 by the sign of a rounding residue (or of a zero), and the lookup follows it."""
    rng = np.random.default_rng(7)
    n = 1500
    t1, t2 = rng.uniform(-math.radians(89.9), math.radians(89.9), (2, n))
    keep = np.abs(np.abs(t1) - np.abs(t2)) > 1e-3  # not θd ≈ 0 nor θh ≈ 0
    pairs = []
    for a, b in zip(t1[keep], t2[keep]):
        for phi in (0.0, 0.7):  # exactly in the xz-plane, and a rotated plane
            c, s = math.cos(phi), math.sin(phi)
            pairs.append(((math.sin(a) * c, math.sin(a) * s, math.cos(a)), (math.sin(b) * c, math.sin(b) * s, math.cos(b))))
    ours, theirs = our_indices(pairs), reference_indices(pairs)
    assert np.array_equal(ours, theirs)
    assert np.isin(ours[:, 2], [0, 179]).all() and len(np.unique(ours[:, 2])) == 2
    assert_bitwise_same(table, raw, pairs)


def test_index_functions_at_cell_edges():
    """Index functions vs the reader's at exact cell edges and 1–2 ulps either side."""

    def around(edges):
        e = np.asarray(edges, dtype=np.float64)
        down, up = np.nextafter(e, -np.inf), np.nextafter(e, np.inf)
        return np.concatenate([e, down, up, np.nextafter(down, -np.inf), np.nextafter(up, np.inf)])

    th = around((np.arange(0, 91) / 90.0) ** 2 * HALF_PI)
    th = np.concatenate([th[th >= 0], [0.0, -0.0, -1e-300, math.pi]])
    got = merl.theta_half_index(torch.from_numpy(th)).numpy()
    assert np.array_equal(got, [ref.theta_half_index(float(x)) for x in th])

    td = around(np.concatenate([np.arange(0, 91) / 90.0 * HALF_PI, np.radians(np.arange(0.0, 91.0))]))
    td = np.concatenate([td[td >= 0], [math.pi]])
    got = merl.theta_diff_index(torch.from_numpy(td)).numpy()
    assert np.array_equal(got, [ref.theta_diff_index(float(x)) for x in td])

    # The reader's own φd, atan2's [−π, π] (−π folds to cell 0, +π clamps to 179), and
    # coords.to_half_diff's [0, 2π), where the same angle is φd − 2π above π.
    pd = around(np.concatenate([np.arange(-180, 181) / 180.0 * math.pi, np.radians(np.arange(-180.0, 181.0))]))
    pd = pd[(pd >= -math.pi) & (pd <= math.pi)]
    got = merl.phi_diff_index(torch.from_numpy(pd)).numpy()
    assert np.array_equal(got, [ref.phi_diff_index(float(x)) for x in pd])
    assert merl.phi_diff_index(torch.tensor([-math.pi, math.pi, -0.0, 0.0], dtype=torch.float64)).tolist() == [0, 179, 0, 0]
    pd = around(np.concatenate([np.arange(0, 361) / 180.0 * math.pi, np.radians(np.arange(0.0, 361.0))]))
    pd = pd[(pd >= 0) & (pd < 2 * math.pi)]
    got = merl.phi_diff_index(torch.from_numpy(pd)).numpy()
    want = [ref.phi_diff_index(float(x) if x <= math.pi else float(x) - 2 * math.pi) for x in pd]
    assert np.array_equal(got, want)
    # NaN (the reader's angles for ωo = −ωi) is cast to cell 0, as C's (int) then clamps it.
    nan = torch.tensor([math.nan])
    assert [int(f(nan)) for f in (merl.theta_half_index, merl.theta_diff_index, merl.phi_diff_index)] == [0, 0, 0]


# --------------------------------------------------------------------------- the grid and trilinear


@pytest.fixture(scope="module")
def grid():
    return merl.grid_directions(torch.float64)


def test_grid_centres_look_up_their_own_cell(table, grid):
    wi, wo = grid
    assert wi.shape == (merl.N_CELLS, 3)
    ih, id_, ip = merl.cell_indices(wi, wo)
    flat = (ih * merl.RES_THETA_D + id_) * merl.RES_PHI_D + ip
    assert torch.equal(flat, torch.arange(merl.N_CELLS))
    got = merl.lookup_nearest(table.values, wi, wo).numpy()
    assert np.array_equal(got, table.values.reshape(3, -1).T)


def test_grid_centres_match_reference(raw, table, grid):
    wi, wo = grid
    rng = np.random.default_rng(8)
    pick = rng.choice(merl.N_CELLS, 3000, replace=False)
    pick = pick[coords.above_horizon(wi[pick], wo[pick]).numpy()]
    pairs = [(tuple(a), tuple(b)) for a, b in zip(wi[pick].tolist(), wo[pick].tolist())]
    theirs = reference_indices(pairs)
    flat = (theirs[:, 0] * 90 + theirs[:, 1]) * 180 + theirs[:, 2]
    assert np.array_equal(flat, pick)


def test_trilinear_at_centres_equals_cell(table, grid):
    wi, wo = grid
    got = merl.lookup_trilinear(table.values, wi, wo).numpy()
    want = table.values.reshape(3, -1).T
    # Equal up to the round trip of the centre angles through directions, worst (~1e-9 of
    # the value range) in the first θh cell at θd = 89.5°, where φd is ill-conditioned.
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-8 * table.values.max())
    assert torch.equal(table.lookup(wi[:1000], wo[:1000], "trilinear"), merl.lookup_trilinear(table.values, wi[:1000], wo[:1000]))


def test_trilinear_is_continuous(table):
    """Across nearest-cell edges (θh, θd, φd, the φd = 0 ≡ π fold) and the clamped first
    θh half-cell, trilinear moves by ≪ 1e-5 of the value range when the angles move by
    2e-9 rad, while nearest jumps at the edges. (Not at θh → 0 in direction space: there
    φd turns with φh, so a table whose first θh row varies with φd — unlike a measured
    isotropic BRDF — is discontinuous whatever the interpolation.)"""
    rng = np.random.default_rng(9)
    n = 400
    d = 1e-9
    u = lambda a, b: rng.uniform(a, b, n)  # noqa: E731
    full = lambda x: np.full(n, float(x))  # noqa: E731
    theta_h_edge = (rng.integers(3, 60, n) / 90.0) ** 2 * HALF_PI
    theta_d_edge = np.radians(rng.integers(2, 80, n).astype(float))
    phi_d_edge = np.radians(rng.integers(1, 179, n).astype(float))
    centre0 = (0.5 / 90.0) ** 2 * HALF_PI
    # name: ((θh, θd, φd) on one side, crosses a nearest-cell edge?); the other side below
    cases = {
        "theta_h": ((theta_h_edge - d, u(0.05, 0.5), u(0.2, 3.0)), True),
        "theta_d": ((u(0.05, 1.2), theta_d_edge - d, u(0.2, 3.0)), True),
        "phi_d": ((u(0.05, 0.6), u(0.05, 0.6), phi_d_edge - d), True),
        "phi_d_fold_pi": ((u(0.05, 0.6), u(0.05, 0.6), full(math.pi - d)), True),
        "phi_d_fold_0": ((u(0.05, 0.6), u(0.05, 0.6), full(2 * math.pi - d)), True),
        "theta_h_first_centre": ((full(centre0 - d), u(0.05, 0.6), u(0.2, 3.0)), False),
    }
    scale = table.values.max()
    for name, (a, crosses) in cases.items():
        th, td, pd = a
        moved = {"theta_h": (th + 2 * d, td, pd), "theta_d": (th, td + 2 * d, pd), "phi_d": (th, td, pd + 2 * d),
                 "phi_d_fold_pi": (th, td, pd + 2 * d), "phi_d_fold_0": (th, td, full(d)),
                 "theta_h_first_centre": (th + 2 * d, td, pd)}[name]
        ph = u(-math.pi, math.pi)
        w0 = coords.from_half_diff(*(torch.as_tensor(x) for x in (th, ph, td, pd)))
        w1 = coords.from_half_diff(*(torch.as_tensor(x) for x in (moved[0], ph, moved[1], moved[2])))
        tri = (merl.lookup_trilinear(table.values, *w0) - merl.lookup_trilinear(table.values, *w1)).abs().max().item()
        assert tri <= 1e-5 * scale, (name, tri)
        near = (merl.lookup_nearest(table.values, *w0) - merl.lookup_nearest(table.values, *w1)).abs().max().item()
        if crosses:
            assert near > 1e-2 * scale, name  # the edge was really crossed


def test_trilinear_skips_invalid_cells(raw):
    """Invalid (negative) cells get zero weight: on a table that is constant where valid,
    trilinear returns that constant wherever any corner is valid, and −1 where none is."""
    rng = np.random.default_rng(10)
    const = np.full((3, *merl.SHAPE), 0.5)
    invalid = rng.random(merl.SHAPE) < 0.4
    const[:, invalid] = merl.INVALID_RAW
    t = merl.MerlTable(const)
    assert not t.valid[invalid].any() and t.valid[~invalid].all()
    pairs = random_pairs(rng, 20_000)
    vi, vo = as_vectors(pairs)
    tri = merl.lookup_trilinear(t.values, vi, vo).numpy()
    expect = 0.5 * np.asarray(merl.CHANNEL_SCALES)
    ok = (tri >= 0).all(axis=1)
    assert ok.mean() > 0.95
    np.testing.assert_allclose(tri[ok], np.broadcast_to(expect, tri[ok].shape), rtol=1e-12)
    # Nearest returns the invalid cell's (negative) value, as the reader does.
    near = merl.lookup_nearest(t.values, vi, vo).numpy()
    ih, id_, ip = merl.cell_indices(vi, vo)
    hit_invalid = invalid[ih.numpy(), id_.numpy(), ip.numpy()]
    assert hit_invalid.any()
    assert (near[hit_invalid] < 0).all() and (near[~hit_invalid] > 0).all()
    # All-invalid table: no valid corner anywhere.
    none = merl.MerlTable(np.full((3, *merl.SHAPE), merl.INVALID_RAW))
    assert (merl.lookup_trilinear(none.values, vi[:100], vo[:100]) == -1.0).all()


def test_trilinear_between_valid_and_invalid_cell():
    """Halfway between φd cells 10 and 11: the average when both are valid, cell 10 alone
    when cell 11 is invalid."""
    raw = np.zeros((3, *merl.SHAPE))
    raw[:, 40, 40, 10] = 3.0
    raw[:, 40, 40, 11] = 5.0
    th = torch.tensor([((40.5) / 90.0) ** 2 * HALF_PI], dtype=torch.float64)
    td = torch.tensor([40.5 / 90.0 * HALF_PI], dtype=torch.float64)
    pd = torch.tensor([11.0 / 180.0 * math.pi], dtype=torch.float64)
    wi, wo = coords.from_half_diff(th, torch.zeros_like(th), td, pd)
    scales = np.asarray(merl.CHANNEL_SCALES)
    np.testing.assert_allclose(merl.MerlTable(raw).lookup(wi, wo, "trilinear").numpy()[0], 4.0 * scales, rtol=1e-9)
    raw[:, 40, 40, 11] = merl.INVALID_RAW
    np.testing.assert_allclose(merl.MerlTable(raw).lookup(wi, wo, "trilinear").numpy()[0], 3.0 * scales, rtol=1e-9)


def test_unknown_lookup_mode(table):
    wi = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    with pytest.raises(ValueError, match="bogus"):
        table.lookup(wi, wi, mode="bogus")


# --------------------------------------------------------------------------- the table and the file


def test_table_shape_is_checked():
    with pytest.raises(ValueError, match="shape"):
        merl.MerlTable(np.zeros((3, 90, 90, 360)))
    with pytest.raises(ValueError, match="shape"):
        merl.MerlTable(np.zeros((90, 90, 180)))


def test_values_and_validity(raw):
    r = raw.copy()
    r[1, 2, 3, 4] = merl.INVALID_RAW
    t = merl.MerlTable(r)
    np.testing.assert_array_equal(t.values, r * np.asarray(merl.CHANNEL_SCALES).reshape(3, 1, 1, 1))
    assert t.values[1, 2, 3, 4] < 0
    assert not t.valid[2, 3, 4] and t.valid.sum() == merl.N_CELLS - 1
    assert merl.FILE_BYTES == 12 + 3 * 90 * 90 * 180 * 8


def test_write_read_round_trip_is_byte_exact(tmp_path, raw, file_bytes):
    r = raw.copy()
    # Values that a lossy path would disturb: invalid marks, −0, subnormals, extremes.
    r[0, 0, 0, :6] = [merl.INVALID_RAW, -0.0, 5e-324, 1.7e308, -1e-300, math.pi]
    t = merl.MerlTable(r)
    a, b = tmp_path / "a.binary", tmp_path / "b.binary"
    merl.write_binary(a, t)
    merl.write_binary(b, t)
    data = a.read_bytes()
    assert data == b.read_bytes()
    assert len(data) == merl.FILE_BYTES
    assert data[:12] == np.asarray([90, 90, 180], dtype="<i4").tobytes()
    assert data[12:] == r.astype("<f8").tobytes()  # float64 little-endian, channel-major
    back = merl.read_binary(a)
    assert back.raw.dtype == np.float64 and back.raw.shape == (3, *merl.SHAPE)
    assert back.raw.tobytes() == r.tobytes()
    back.raw[0, 0, 0, 0] = 7.0  # an independent, writable copy
    # A file made by hand from the format reads to the same table, and writes back the same bytes.
    c = tmp_path / "c.binary"
    c.write_bytes(file_bytes)
    t2 = merl.read_binary(str(c))
    assert t2.raw.tobytes() == raw.tobytes()
    merl.write_binary(tmp_path / "d.binary", t2)
    assert (tmp_path / "d.binary").read_bytes() == file_bytes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.binary", "b.binary", "c.binary", "d.binary"]


def _bad_file(tmp_path, name, data: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(data)
    return p


def _assert_data_error(path, *words):
    with pytest.raises(DataError) as info:
        merl.read_binary(path)
    msg = str(info.value)
    assert str(path) in msg, msg
    for w in words:
        assert w in msg.lower(), msg
    return msg


@pytest.mark.parametrize(
    "name, cut, words",
    [
        ("half", merl.FILE_BYTES // 2, ("truncated",)),
        ("minus-one-value", merl.FILE_BYTES - 8, ("truncated",)),
        ("minus-one-byte", merl.FILE_BYTES - 1, ("truncated",)),
        ("header-only", 12, ("truncated",)),
        ("short-header", 5, ("truncated", "header")),
        ("empty", 0, ("truncated", "header")),
    ],
)
def test_truncated_file(tmp_path, file_bytes, name, cut, words):
    _assert_data_error(_bad_file(tmp_path, f"{name}.binary", file_bytes[:cut]), *words)


@pytest.mark.parametrize("extra", [b"\x00", b"\x00" * 8, b"\x00" * merl.FILE_BYTES])
def test_oversized_file(tmp_path, file_bytes, extra):
    _assert_data_error(_bad_file(tmp_path, "big.binary", file_bytes + extra), "oversized")


@pytest.mark.parametrize("dims", [(90, 90, 360), (180, 90, 90), (0, 0, 0), (-90, 90, 180), (90, 90, 181)])
def test_wrong_header_dims(tmp_path, file_bytes, dims):
    data = np.asarray(dims, dtype="<i4").tobytes() + file_bytes[12:]
    msg = _assert_data_error(_bad_file(tmp_path, "dims.binary", data), "header")
    assert str(tuple(dims)) in msg


def test_big_endian_header_is_rejected(tmp_path, file_bytes):
    data = np.asarray([90, 90, 180], dtype=">i4").tobytes() + file_bytes[12:]
    _assert_data_error(_bad_file(tmp_path, "be.binary", data), "header")


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", [(0, 0, 0, 0), (1, 45, 12, 99), (2, 89, 89, 179)])
def test_non_finite_cell(tmp_path, raw, bad, where):
    r = raw.copy()
    r[where] = bad
    data = np.asarray([90, 90, 180], dtype="<i4").tobytes() + r.astype("<f8").tobytes()
    msg = _assert_data_error(_bad_file(tmp_path, "nan.binary", data), "non-finite")
    assert str(tuple(int(i) for i in where[1:])) in msg


def test_missing_path(tmp_path):
    _assert_data_error(tmp_path / "nope" / "missing.binary", "cannot read")
    _assert_data_error(tmp_path / "missing.binary", "cannot read")


def test_directory_instead_of_file(tmp_path):
    d = tmp_path / "dir.binary"
    d.mkdir()
    _assert_data_error(d, "directory")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads unreadable files")
def test_unreadable_file(tmp_path, file_bytes):
    p = _bad_file(tmp_path, "locked.binary", file_bytes[:100])
    p.chmod(0)
    try:
        _assert_data_error(p, "cannot read")
    finally:
        p.chmod(0o644)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_failed_write_leaves_no_file(tmp_path, raw, bad):
    r = raw.copy()
    r[2, 3, 4, 5] = bad
    target = tmp_path / "out.binary"
    with pytest.raises(ValueError) as info:
        merl.write_binary(target, merl.MerlTable(r))
    assert str(target) in str(info.value)
    assert list(tmp_path.iterdir()) == []
    # An existing file is left untouched by a failed write.
    merl.write_binary(target, merl.MerlTable(raw))
    before = target.read_bytes()
    with pytest.raises(ValueError):
        merl.write_binary(target, merl.MerlTable(r))
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.binary"]


def test_interrupted_write_leaves_no_partial_file(tmp_path, raw, monkeypatch):
    """A failure after the temporary file is written (here: the final rename) removes it
    and leaves the target path as it was."""
    target = tmp_path / "out.binary"

    def fail(src, dst):
        assert Path(src).stat().st_size == merl.FILE_BYTES
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(merl.os, "replace", fail)
    with pytest.raises(OSError):
        merl.write_binary(target, merl.MerlTable(raw))
    assert list(tmp_path.iterdir()) == []
