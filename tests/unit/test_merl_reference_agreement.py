"""The MERL lookup agrees with the reference reader's arithmetic (issue 17).

`merl_reference.py` follows BRDFRead.cpp step by step in float64. The reader takes angles:
`merl.angle_cell_indices` / `MerlTable.lookup_angles` must give its cells bitwise, and
`merl.cell_indices` / `lookup_nearest` at the two vectors it builds from the angles too,
on adversarial sets where the reader's cell is decided by rounding: ωi = ωo, exact
specular pairs given as angles, θo = 0, in-plane pairs with φo = φi + 180°, equal polar
angles, and pairs on θh, θd and φd cell edges. Unit vectors made another way (torch's
sin and cos) round differently from the reader's own: there a lookup may land in another
cell, but only where the reader's coordinate is within a tolerance of an edge that its
conditioning sets (1e-9 cells for well-conditioned pairs, unbounded at degenerate ones).
"""

from __future__ import annotations

import importlib.util
import math
import platform
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import coords, merl, mitsuba_env

_spec = importlib.util.spec_from_file_location("merl_reference", Path(__file__).with_name("merl_reference.py"))
ref = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ref)

MAX_T = math.radians(89.99)
EDGE_TOL = 1e-9  # cells
DEGENERATE = 1e-6  # rad: θh or θd below it leaves φh or φd to rounding
SETS = ("identical", "specular_angles", "theta_o_zero", "in_plane", "equal_polar", "theta_h_edge", "theta_d_edge", "phi_d_edge")


# --------------------------------------------------------------------------- the sets


def _edge_set(rng, n, which):
    """Pairs whose θh, θd or φd is exactly a cell edge before rounding, as spherical angles."""
    m = 2 * n
    th = rng.uniform(0, math.pi / 2, m)
    td = rng.uniform(0, math.pi / 2, m)
    pd = rng.uniform(0, 2 * math.pi, m)
    if which == "theta_h_edge":
        th = (rng.integers(1, 90, m) / 90.0) ** 2 * (math.pi / 2)
    elif which == "theta_d_edge":
        td = rng.integers(1, 90, m) * (math.pi / 180)
    else:
        pd = rng.integers(0, 360, m) * (math.pi / 180)  # 0 and 180° are the fold
    t = lambda x: torch.from_numpy(x)  # noqa: E731
    wi, wo = (w.numpy() for w in coords.from_half_diff(t(th), t(rng.uniform(-math.pi, math.pi, m)), t(td), t(pd)))
    keep = (wi[:, 2] > 1e-4) & (wo[:, 2] > 1e-4)
    angles = [np.arctan2(np.hypot(w[keep, 0], w[keep, 1]), w[keep, 2]) for w in (wi, wo)]
    azimuths = [np.arctan2(w[keep, 1], w[keep, 0]) for w in (wi, wo)]
    return np.stack([angles[0], azimuths[0], angles[1], azimuths[1]], 1)[:n]


def adversarial_sets(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """{set: (n, 4) float64 (θi, φi, θo, φo)} for the sets of issue 17 (polar angles up to 89.99°)."""
    rng = np.random.default_rng(seed)
    u = lambda a, b: rng.uniform(a, b, n)  # noqa: E731
    polar = lambda: np.arccos(rng.uniform(math.cos(MAX_T), 1.0, n))  # noqa: E731
    out = {}
    t, p = polar(), u(-math.pi, math.pi)
    t[: n // 50] = 0.0
    out["identical"] = np.stack([t, p, t, p], 1)
    t, p = polar(), u(-math.pi, math.pi)
    po = np.where(p <= 0, p + math.pi, p - math.pi)
    po[: n // 2] = p[: n // 2] + math.pi
    out["specular_angles"] = np.stack([t, p, t, po], 1)
    po = u(-math.pi, math.pi)
    po[: n // 4] = 0.0
    out["theta_o_zero"] = np.stack([polar(), u(-math.pi, math.pi), np.zeros(n), po], 1)
    # φo = φi + 180°: half in degrees (φi whole degrees, a quarter of them 0) as a lobe plot gives them.
    pi_deg = rng.integers(-180, 180, n).astype(float)
    pi_deg[: n // 4] = 0.0
    deg = np.stack([np.radians(u(0, 89.99)), np.radians(pi_deg), np.radians(u(0, 89.99)), np.radians(pi_deg + 180.0)], 1)
    p = u(-math.pi, math.pi)
    out["in_plane"] = np.where((np.arange(n) < n // 2)[:, None], deg, np.stack([polar(), p, polar(), p + math.pi], 1))
    t = polar()
    out["equal_polar"] = np.stack([t, u(-math.pi, math.pi), t, u(-math.pi, math.pi)], 1)
    for name in ("theta_h_edge", "theta_d_edge", "phi_d_edge"):
        out[name] = _edge_set(rng, n, name)
    return out


@pytest.fixture(scope="module")
def sets() -> dict[str, np.ndarray]:
    return adversarial_sets(2500, seed=17)


@pytest.fixture(scope="module")
def table() -> merl.MerlTable:
    return merl.MerlTable(np.random.default_rng(0).random((3, *merl.SHAPE)))


# --------------------------------------------------------------------------- the oracle's view


def oracle(angles: np.ndarray):
    """The reader at each row of (θi, φi, θo, φo): cells (N, 3), the coordinates it truncates
    (N, 3) and its (θh, θd) (N, 2)."""
    cells, coordinates, thetas = [], [], []
    for row in angles.tolist():
        th, _, td, pd = ref.std_coords_to_half_diff_coords(*row)
        cells.append(ref.indices(th, td, pd))
        coordinates.append(ref.cell_coordinates(th, td, pd))
        thetas.append((th, td))
    return np.array(cells).reshape(-1, 3), np.array(coordinates).reshape(-1, 3), np.array(thetas).reshape(-1, 2)


def reader_vectors(angles: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """The reader's own two vectors (un-normalised, from the C library's sin and cos)."""
    def vec(cols):
        return torch.tensor([ref.reader_vector(t, p) for t, p in angles[:, cols].tolist()], dtype=torch.float64).reshape(-1, 3)
    return vec([0, 1]), vec([2, 3])


def torch_unit_vectors(angles: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit vectors made another way: torch's sin and cos, then normalised."""
    a = torch.from_numpy(angles)
    return (coords.normalize(coords.spherical_to_vector(a[:, k], a[:, k + 1])) for k in (0, 2))


def cells(t) -> np.ndarray:
    return np.stack([np.asarray(c) for c in t], 1)


def tolerance(coordinates: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """How far (cells) each of the reader's coordinates can move when its input vectors
    move by a few ulps (u = 1e-15), to first order: h turns by u/cos θd; θh by that plus
    what acos makes of a z near 1 (u/sin θh, at most sqrt(2u)); φh by both over sin θh;
    the difference vector's z by θh's share, its x, y by φh's too; θd and φd by those over
    sin θd (θd again at most sqrt(2·) of it). At least EDGE_TOL; unbounded where an angle is
    undefined (θd = π/2 for all three; θh or θd below DEGENERATE for φd, where the
    reader's acos no longer measures how small the vector's x, y are)."""
    u = 1e-15
    th, td = thetas[:, 0], thetas[:, 1]
    sin_h = np.where(th < DEGENERATE, 0.0, np.sin(th))
    sin_d = np.where(td < DEGENERATE, 0.0, np.sin(td))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        turn_h = u / np.cos(td)
        d_theta_h = turn_h + np.minimum(u / sin_h, math.sqrt(2 * u))
        d_phi_h = (turn_h + u) / sin_h
        d_z = 2 * u + d_theta_h + turn_h
        d_xy = u + d_theta_h + d_phi_h
        u_h = coordinates[:, 0]
        d_h = np.sqrt(u_h * u_h + d_theta_h * (merl.RES_THETA_H**2 / (math.pi / 2))) - u_h
        d_d = (180 / math.pi) * np.minimum(d_z / sin_d, np.sqrt(2 * d_z))
        d_p = (180 / math.pi) * d_xy / sin_d
    return EDGE_TOL + 16 * np.stack([d_h, d_d, d_p], 1)


def cell_distance(coordinates: np.ndarray, got: np.ndarray) -> np.ndarray:
    """Distance (cells) from the reader's coordinates to the cells `got`: 0 inside; θh and θd
    cells 0 and 89 reach to the clamped ends; φd wraps with period 180."""
    lo, hi = got.astype(float), got + 1.0
    lo[:, :2] = np.where(got[:, :2] == 0, -np.inf, lo[:, :2])
    hi[:, :2] = np.where(got[:, :2] == 89, np.inf, hi[:, :2])
    d = np.maximum(np.maximum(lo - coordinates, coordinates - hi), 0.0)
    x = coordinates[:, 2] % 180
    k = got[:, 2]
    d[:, 2] = np.minimum.reduce([np.maximum(np.maximum(k - x + s, x - s - k - 1), 0) for s in (-180, 0, 180)])
    return d


def assert_within_tolerance(got: np.ndarray, angles: np.ndarray, what: str) -> int:
    """Every cell `got` is the reader's, or within the tolerance of its coordinates; returns
    the number of other cells."""
    want, coordinates, thetas = oracle(angles)
    wrong = (got != want).any(1)
    if wrong.any():
        d = cell_distance(coordinates[wrong], got[wrong])
        ok = ~(d > tolerance(coordinates[wrong], thetas[wrong]))  # NaN tolerance: anything goes
        bad = np.flatnonzero(wrong)[~ok.all(1)]
        assert bad.size == 0, f"{what}: {bad.size} pairs out of tolerance, first {angles[bad[0]].tolist()}: {got[bad[0]]} vs {want[bad[0]]}"
    return int(wrong.sum())


# --------------------------------------------------------------------------- the issue's cases


EXAMPLE_DEG = (36.389462, 0.0, 74.920303, 180.0)


def test_the_issue_example_folds_minus_pi_into_cell_0():
    """(36.389462°, 0, 74.920303°, 180°): the reader's φd is atan2's −π (not +π), which its
    fold moves up by π into cell 0. Every entry point now says (41, 55, 0)."""
    a = np.radians([EXAMPLE_DEG])
    _, _, _, phi_d = ref.std_coords_to_half_diff_coords(*a[0])
    assert phi_d < 0 and abs(phi_d + math.pi) < 1e-15
    assert ref.indices_from_angles(*a[0]) == (41, 55, 0)
    assert cells(merl.angle_cell_indices(*a.T)).tolist() == [[41, 55, 0]]
    assert cells(merl.cell_indices(*reader_vectors(a))).tolist() == [[41, 55, 0]]
    assert cells(merl.cell_indices(*torch_unit_vectors(a))).tolist() == [[41, 55, 0]]
    assert merl.reader_angles_spherical(*a.T)[2].item() == phi_d


def test_in_plane_slice_with_theta_i_below_theta_o_is_cell_0():
    """φi = 0, φo = 180° and 0 < θi < θo: the reader's φd cell is always 0 (sin 180° > 0
    leaves the residue on one side); the lookup agrees on every pair of a dense slice, and
    at θi = 0 (ωi the normal), where the reader puts them in 179, too."""
    t = np.radians(np.arange(0.0, 89.99, 0.37))
    ti, to = (x.reshape(-1) for x in np.meshgrid(t, t, indexing="ij"))
    keep = ti < to
    a = np.stack([ti[keep], np.zeros(keep.sum()), to[keep], np.full(keep.sum(), math.pi)], 1)
    want = oracle(a)[0]
    assert np.array_equal(cells(merl.angle_cell_indices(*a.T)), want)
    assert np.array_equal(want[:, 2] == 0, a[:, 0] > 0)
    keep = (0 < ti) & (ti < to)
    a = np.stack([ti[keep], np.zeros(keep.sum()), to[keep], np.full(keep.sum(), math.pi)], 1)
    want = oracle(a)[0]
    assert (want[:, 2] == 0).all()
    assert np.array_equal(cells(merl.angle_cell_indices(*a.T)), want)
    assert np.array_equal(cells(merl.cell_indices(*reader_vectors(a))), want)


# Pairs where a half vector from normalised copies of the vectors (the former oracle)
# lands in another cell than the reader, with the cells of the reader built with gcc 12
# -O2 on x86-64 against glibc (float.hex angles θi, φi, θo, φo; the reader's cell).
COMPILED_READER_PINS = [
    (("0x1.0740f475ee100p+0", "-0x1.902cbcd330a28p-2", "0x1.0740f475ee100p+0", "-0x1.902cbcd330a28p-2"), (72, 0, 179)),
    (("0x1.580244037f962p+0", "0x1.5a4fd0883013ep+1", "0x1.580244037f962p+0", "0x1.7637c2e63972bp+2"), (0, 76, 65)),
    (("0x1.8d3e7f33c687bp+0", "0x1.0bbbbcee0e21cp+0", "0x0.0p+0", "0x0.0p+0"), (63, 44, 179)),
    (("0x1.3d46e602cc153p+0", "-0x1.1df46a2529d39p-1", "0x1.36652b0ee0a34p+0", "0x1.4aa29abaf85cap+1"), (8, 70, 179)),
    (("0x1.58ff8f233d985p+0", "0x1.6d25fb035a100p-4", "0x1.58ff8f233d985p+0", "-0x1.834c58c72f103p+1"), (17, 77, 90)),
    (("0x1.b1b7181d5eed0p-1", "-0x1.2e8ea2719ed20p-1", "0x1.af510a5ead8c7p-1", "-0x1.3755716b89098p-1"), (66, 0, 69)),
    (("0x1.693ce62bb253ap+0", "-0x1.ca197e6fcc451p+0", "0x1.75621cea8786cp-4", "0x1.2f46ab0857e5ap+0"), (58, 43, 178)),
    (("0x1.15cf7d225fa1fp+0", "-0x1.8843601ff665ap-2", "0x1.0dca1c977aa6fp+0", "0x1.47604ed55e429p+1"), (30, 60, 95)),
]


def _normalised_copies_oracle(row):
    """The former oracle's one wrong step: h from the normalised vectors, not the reader's own."""
    vi, vo = (ref.normalize(ref.reader_vector(*row[k:k + 2])) for k in (0, 2))
    half = ref.normalize(tuple((a + b) / 2.0 for a, b in zip(vi, vo)))
    theta_h, phi_h = ref.c_acos(half[2]), math.atan2(half[1], half[0])
    diff = ref.rotate_vector(ref.rotate_vector(vi, ref.NORMAL, -phi_h), ref.BINORMAL, -theta_h)
    return ref.indices(theta_h, ref.c_acos(diff[2]), math.atan2(diff[1], diff[0]))


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="pins of a glibc build")
def test_oracle_and_lookup_match_the_compiled_reader_pins(table):
    flat = table.raw.reshape(-1)
    for hexes, want in COMPILED_READER_PINS:
        row = tuple(float.fromhex(h) for h in hexes)
        assert ref.indices_from_angles(*row) == want
        assert _normalised_copies_oracle(row) != want
        a = np.array([row])
        assert cells(merl.angle_cell_indices(*a.T)).tolist() == [list(want)]
        assert cells(merl.cell_indices(*reader_vectors(a))).tolist() == [list(want)]
        got = table.lookup_angles(*a.T).numpy()[0]
        assert np.array_equal(got.view(np.uint64), np.array(ref.lookup_brdf_val(flat, *row)).view(np.uint64))


def test_normalised_copies_differ_from_the_reader_on_the_sets(sets):
    """The former oracle's half vector is off often enough to matter (about 1 % of these sets)."""
    rows = np.concatenate([sets[k][:500] for k in SETS])
    want = oracle(rows)[0]
    old = np.array([_normalised_copies_oracle(r) for r in rows.tolist()])
    assert 0.002 < (old != want).any(1).mean() < 0.2


# --------------------------------------------------------------------------- the adversarial sets


@pytest.mark.parametrize("name", SETS)
def test_adversarial_set_lands_in_the_readers_cells(sets, table, name):
    """Angle entry point and the reader's own vectors: every cell and value the reader's
    (0 of 2500 in another cell). Unit vectors from torch round differently from the
    reader's vectors, and these pairs sit on an edge or a degenerate point, where the
    reader's side is a coin its rounding flips: many land in the other cell (up to a
    fifth of a set), each within the tolerance."""
    a = sets[name]
    want = oracle(a)[0]
    assert np.array_equal(cells(merl.angle_cell_indices(*a.T)), want)
    wi, wo = reader_vectors(a)
    assert np.array_equal(cells(merl.cell_indices(wi, wo)), want)
    flat = table.raw.reshape(-1)
    expect = np.array([ref.lookup_brdf_val(flat, *row) for row in a.tolist()])
    for got in (table.lookup_angles(*torch.from_numpy(a).T), table.lookup(wi, wo)):
        assert np.array_equal(got.numpy().view(np.uint64), expect.view(np.uint64))
    assert_within_tolerance(cells(merl.cell_indices(*torch_unit_vectors(a))), a, name)


# --------------------------------------------------------------------------- degenerate pairs


def test_degenerate_pairs_follow_the_documented_rule(table):
    """θh = 0 exactly (h = +z: a mirror pair given as vectors): φh = 0, so θd and φd are ωi's
    own polar angle and azimuth (ωi normalised, as the reader rotates it), φd folded; the
    normal with itself is cell (0, 0, 0); ωi = ωo has θd cell 0 and the reader's φd,
    whatever rounding made it; ωo = −ωi is NaN everywhere, cell (0, 0, 0). Every value is
    the reader's, bitwise."""
    rng = np.random.default_rng(3)
    n = 1500
    t, p = np.arccos(rng.uniform(math.cos(MAX_T), 1.0, n)), rng.uniform(-math.pi, math.pi, n)
    wi = torch.tensor([ref.reader_vector(a, b) for a, b in zip(t.tolist(), p.tolist())], dtype=torch.float64)
    flat = table.raw.reshape(-1)

    def check(vi, vo):
        got = cells(merl.cell_indices(vi, vo))
        want = np.array([ref.indices_from_vectors(a, b) for a, b in zip(vi.tolist(), vo.tolist())])
        assert np.array_equal(got, want)
        values = np.array([ref.lookup_from_vectors(flat, a, b) for a, b in zip(vi.tolist(), vo.tolist())])
        assert np.array_equal(table.lookup(vi, vo).numpy().view(np.uint64), values.view(np.uint64))
        return got

    mirror = wi * torch.tensor([-1.0, -1.0, 1.0], dtype=torch.float64)
    got = check(wi, mirror)
    unit = np.array([ref.normalize(v) for v in wi.tolist()])
    theta = torch.from_numpy(np.arccos(unit[:, 2]))
    phi = torch.from_numpy(np.arctan2(unit[:, 1], unit[:, 0]))
    assert (got[:, 0] == 0).all()
    assert np.array_equal(got[:, 1], merl.theta_diff_index(theta).numpy())
    assert np.array_equal(got[:, 2], merl.phi_diff_index(phi).numpy())
    normal = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    assert check(normal, normal).tolist() == [[0, 0, 0]]
    same = check(wi, wi.clone())
    assert (same[:, 1] == 0).all() and len(np.unique(same[:, 2])) > 10
    assert check(wi, -wi).tolist() == [[0, 0, 0]] * n
    assert all(torch.isnan(x).all() for x in merl.reader_angles(wi[:5], -wi[:5]))


def test_values_at_degenerate_angles_are_the_readers(table, sets):
    """Given as angles, exact specular pairs and ωi = ωo are degenerate only up to rounding:
    φh or φd is rounding noise, spread over many cells, and the lookup returns the reader's."""
    flat = table.raw.reshape(-1)
    for name in ("specular_angles", "identical"):
        a = sets[name][:1000]
        want, _, thetas = oracle(a)
        assert (~(np.minimum(thetas[:, 0], thetas[:, 1]) >= DEGENERATE)).mean() > 0.9  # NaN: acos(1 + ulp)
        assert len(np.unique(want[:, 2])) > 10
        expect = np.array([ref.lookup_brdf_val(flat, *row) for row in a.tolist()])
        got = table.lookup_angles(*torch.from_numpy(a).T).numpy()
        assert np.array_equal(got.view(np.uint64), expect.view(np.uint64))


# --------------------------------------------------------------------------- another library


def _nudged(f, rng):
    """f with every result moved by up to 3 ulps at random: another library's last bits."""
    def g(*args):
        r = f(*args)
        k = rng.integers(-3, 4, np.shape(r))
        for _ in range(3):
            r = np.where(k > 0, np.nextafter(r, np.inf), np.where(k < 0, np.nextafter(r, -np.inf), r))
            k = k - np.sign(k)
        return r
    return g


def test_another_librarys_last_bits_change_no_cell(sets, monkeypatch):
    """With numpy's sin, cos, acos and atan2 replaced by ones a few ulps off, the cells are
    still the reader's: every lookup whose cell such bits could move is recomputed with the
    C library's functions. Random pairs and pairs 1e-14 .. 1e-6 cells off an edge probe
    where that recomputation starts."""
    rng = np.random.default_rng(5)
    n = 4000
    t, p = np.arccos(rng.uniform(0, 1, (2, n))), rng.uniform(-math.pi, math.pi, (2, n))
    rows = [np.stack([t[0], p[0], t[1], p[1]], 1)]
    for name in ("theta_h_edge", "theta_d_edge", "phi_d_edge"):
        a = sets[name][:1500].copy()
        a[:, 2] += 10.0 ** rng.uniform(-16, -8, len(a)) * rng.choice([-1.0, 1.0], len(a))
        rows.append(a)
    rows += [sets[k][:800] for k in SETS]
    a = np.concatenate(rows)
    want = oracle(a)[0]
    monkeypatch.setattr(merl, "_FAST", tuple(_nudged(f, rng) for f in merl._FAST))
    assert np.array_equal(cells(merl.angle_cell_indices(*a.T)), want)
    assert np.array_equal(cells(merl.cell_indices(*reader_vectors(a))), want)


def test_the_c_library_is_called_for_few_random_lookups(monkeypatch):
    """The exact recomputation is for lookups near an edge or a degenerate pair: none of
    10⁵ random pairs (cosine-weighted, as a harness draws them) needs it."""
    calls = []
    monkeypatch.setattr(merl, "_LIBM", tuple((lambda f: lambda *x: calls.append(np.size(x[0])) or f(*x))(f) for f in merl._LIBM))
    g = torch.Generator().manual_seed(2)
    u = torch.rand(100_000, 4, generator=g, dtype=torch.float64)
    wi = coords.spherical_to_vector(torch.acos(torch.sqrt(u[:, 0])), 2 * math.pi * u[:, 1])
    wo = coords.spherical_to_vector(torch.acos(torch.sqrt(u[:, 2])), 2 * math.pi * u[:, 3])
    merl.cell_indices(wi, wo)
    assert sum(calls) <= 4 * 10  # at most ten lanes (four functions each)


# --------------------------------------------------------------------------- properties


theta = st.one_of(st.sampled_from([0.0, MAX_T, math.pi / 4]), st.floats(0.0, MAX_T))
phi = st.one_of(st.sampled_from([0.0, math.pi, -math.pi, math.pi / 2]), st.floats(-math.pi, math.pi))
RELATIONS = ("free", "identical", "specular", "in_plane", "same_side", "equal_polar", "theta_o_zero")


@st.composite
def angle_pairs(draw):
    ti, pi_, to, po = draw(theta), draw(phi), draw(theta), draw(phi)
    relation = draw(st.sampled_from(RELATIONS))
    if relation == "identical":
        to, po = ti, pi_
    elif relation == "specular":
        to, po = ti, pi_ + math.pi
    elif relation == "in_plane":
        po = pi_ + math.pi
    elif relation == "same_side":
        po = pi_
    elif relation == "equal_polar":
        to = ti
    elif relation == "theta_o_zero":
        to = 0.0
    return ti, pi_, to, po


@settings(max_examples=150, deadline=None)
@given(st.lists(angle_pairs(), min_size=1, max_size=24))
def test_property_any_angle_pair_lands_in_the_readers_cell(rows):
    """For any angle pair: the angle entry point and the reader's own vectors give the
    reader's cell exactly; unit vectors from torch give it or a cell within the tolerance."""
    a = np.array(rows, dtype=np.float64)
    want = oracle(a)[0]
    assert np.array_equal(cells(merl.angle_cell_indices(*a.T)), want)
    assert np.array_equal(cells(merl.cell_indices(*reader_vectors(a))), want)
    assert_within_tolerance(cells(merl.cell_indices(*torch_unit_vectors(a))), a, "torch unit vectors")


component = st.one_of(st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.5]), st.floats(-1.0, 1.0))
vector = st.tuples(component, component, component)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(vector, vector), min_size=1, max_size=24))
def test_property_any_vector_pair_is_the_readers_arithmetic(pairs):
    """For any two vectors (unit or not, zero, opposite, below the horizon), the vector
    lookup is the reader's arithmetic from its two vectors on, cell for cell."""
    wi = torch.tensor([p[0] for p in pairs], dtype=torch.float64)
    wo = torch.tensor([p[1] for p in pairs], dtype=torch.float64)
    want = np.array([ref.indices_from_vectors(a, b) for a, b in pairs])
    assert np.array_equal(cells(merl.cell_indices(wi, wo)), want)


# --------------------------------------------------------------------------- the drjit kernel


@pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")
def test_the_drjit_kernel_on_the_sets(sets):
    """The kernel's cells (fp32 directions, as a renderer passes them) against the reader's
    at those very vectors: the same, except within 1e-9 cells of an edge or at a degenerate
    pair, where drjit's fp64 sin, cos, acos and atan2 (not the C library's) may round the
    reader's coin the other way. Sets whose pairs stay off an edge once rounded to fp32
    keep ≤ 0.1 % of those; ωi = ωo, θo = 0 and in-plane pairs sit exactly on one."""
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        import mitsuba as mi

        from brdfbench.render import drjit_kernels as dk

        for name in SETS:
            wi, wo = (w.float() for w in reader_vectors(sets[name]))
            vec = [mi.Vector3f(*(mi.Float(np.ascontiguousarray(w[:, c].numpy())) for c in range(3))) for w in (wi, wo)]
            got = np.asarray(dk.merl_cell(*vec)).astype(np.int64)
            angles = [ref.half_diff_from_vectors(a, b) for a, b in zip(wi.double().tolist(), wo.double().tolist())]
            want = np.array([ref.flat_index(*ref.indices(th, td, pd)) for th, _, td, pd in angles])
            u = np.array([ref.cell_coordinates(th, td, pd) for th, _, td, pd in angles])
            edge = (np.abs(u - np.round(u)) < EDGE_TOL).any(1)
            degenerate = np.array([not (th >= DEGENERATE and td >= DEGENERATE) for th, _, td, _ in angles])
            wrong = got != want
            assert not (wrong & ~edge & ~degenerate).any(), name
            if name not in ("identical", "theta_o_zero", "in_plane"):
                assert wrong.mean() <= 0.001, (name, wrong.mean())
