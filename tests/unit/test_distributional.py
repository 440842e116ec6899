"""Distributional metrics (MMD, COV, 1-NNA) and the BRDF-space distance matrices they use:
against a slow reference written from Zhou et al.'s equations 3–5, the validity properties
the issue lists, bootstrap intervals, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import merl
from brdfbench.distances import brdf as brdf_distances
from brdfbench_metrics import distributional as D

# --------------------------------------------------------------------------- the slow reference


def slow_mmd(d_rs) -> float:
    """Eq. 3: (1/|R|) Σ_r min_s d(r, s)."""
    return sum(min(row) for row in d_rs.tolist()) / len(d_rs)


def slow_cov(d_rs) -> float:
    """Eq. 4: |{argmin_r d(r, s) : s ∈ S}| / |R|, the first r of equal distances."""
    nr, ns = d_rs.shape
    chosen = set()
    for s in range(ns):
        best, arg = math.inf, None
        for r in range(nr):
            if d_rs[r, s] < best:
                best, arg = d_rs[r, s], r
        chosen.add(arg)
    return len(chosen) / nr


def slow_one_nna(d_rr, d_ss, d_rs) -> float:
    """Eq. 5: each member of R ∪ S (R first) labelled by its nearest neighbour in the union
    without itself, the first of equal distances in that order."""
    nr, ns = d_rs.shape
    members = [("r", i) for i in range(nr)] + [("s", j) for j in range(ns)]

    def dist(a, b):
        (sa, i), (sb, j) = a, b
        if sa == sb == "r":
            return d_rr[i, j]
        if sa == sb == "s":
            return d_ss[i, j]
        return d_rs[i, j] if sa == "r" else d_rs[j, i]

    correct = 0
    for a in members:
        best, label = math.inf, None
        for b in members:
            if b is a:
                continue
            if dist(a, b) < best:
                best, label = dist(a, b), b[0]
        correct += label == a[0]
    return correct / len(members)


def euclidean(x, y):
    return np.sqrt(((x[:, None, :] - y[None, :, :]) ** 2).sum(-1))


def matrices(r, s):
    return euclidean(r, r), euclidean(s, s), euclidean(r, s)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 9), st.integers(1, 9), st.integers(0, 2**31 - 1), st.booleans())
def test_fast_metrics_equal_the_slow_reference(nr, ns, seed, coarse):
    """Coarse (integer) points make ties common: the tie rule must be the reference's too."""
    rng = np.random.default_rng(seed)
    r, s = rng.normal(size=(nr, 2)), rng.normal(size=(ns, 2))
    if coarse:
        r, s = np.round(r), np.round(s)
    rr, ss, rs = matrices(r, s)
    assert D.mmd(rs) == pytest.approx(slow_mmd(rs), abs=1e-15)
    assert D.cov(rs) == slow_cov(rs)
    if nr + ns >= 2:
        assert D.one_nna(rr, ss, rs) == slow_one_nna(rr, ss, rs)


# --------------------------------------------------------------------------- validity

#: 1-NNA of two samples of one distribution: its spread is about 0.5/sqrt(|R| + |S|) = 0.018
#: at 400 + 400 points, so a 0.08 band is 4.5 standard deviations: α ≈ 1e-5, two-sided.
NNA_BAND = 0.08


def test_one_distribution_gives_one_nna_near_half():
    rng = np.random.default_rng(1)
    r, s = rng.normal(size=(400, 3)), rng.normal(size=(400, 3))
    assert abs(D.one_nna(*matrices(r, s)) - 0.5) < NNA_BAND


def test_disjoint_distributions_give_one_nna_near_one():
    rng = np.random.default_rng(2)
    r, s = rng.normal(size=(200, 3)), rng.normal(size=(200, 3)) + 20.0
    assert D.one_nna(*matrices(r, s)) == 1.0


def test_a_set_covers_itself():
    rng = np.random.default_rng(3)
    r = rng.normal(size=(50, 4))
    assert D.cov(euclidean(r, r)) == 1.0


def test_mmd_is_zero_when_the_samples_contain_the_reference():
    rng = np.random.default_rng(4)
    r = rng.normal(size=(30, 4))
    s = np.concatenate([rng.normal(size=(20, 4)), r])[rng.permutation(50)]
    assert D.mmd(euclidean(r, s)) == 0.0


def test_collapsed_samples_cover_one_reference_member():
    rng = np.random.default_rng(5)
    r = rng.normal(size=(40, 2))
    s = np.repeat(r[:1] + 1e-3, 25, axis=0)
    assert D.cov(euclidean(r, s)) == 1 / 40
    assert D.one_nna(*matrices(r, s)) > 0.9  # every sample's neighbour is another sample


def test_declared_directions():
    assert D.DECLARED["mmd"][1] is False and D.DECLARED["cov"][1] is True and D.DECLARED["1nna"][1] is False


# --------------------------------------------------------------------------- bootstrap


def test_reference_bootstrap_is_seeded_and_brackets_the_value():
    rng = np.random.default_rng(6)
    r, s = rng.normal(size=(60, 2)), rng.normal(size=(60, 2)) * 1.3
    rs = euclidean(r, s)
    for metric, value in (("mmd", D.mmd(rs)), ("cov", D.cov(rs))):
        got = D.reference_bootstrap(metric, rs, n_boot=500, seed=0)
        assert got == D.reference_bootstrap(metric, rs, n_boot=500, seed=0)
        assert got.value == value and got.lo < value < got.hi and got.level == 0.95
        assert got.method == "reference bootstrap (500 resamples)"


def test_reference_bootstrap_covers_the_mean_over_fresh_reference_draws():
    """MMD against a fixed sample set, over 200 fresh reference draws: the share of draws
    whose interval covers the mean over all draws is near 95 % (binomial, n = 200: below
    85 % has probability < 1e-5 for a correct 95 % interval)."""
    rng = np.random.default_rng(8)
    s = rng.normal(size=(40, 2))
    figures, intervals = [], []
    for k in range(200):
        r = rng.normal(size=(40, 2))
        rs = euclidean(r, s)
        figures.append(D.mmd(rs))
        intervals.append(D.reference_bootstrap("mmd", rs, n_boot=300, seed=k))
    truth = float(np.mean(figures))
    covered = np.mean([i.lo <= truth <= i.hi for i in intervals])
    assert covered > 0.85, covered


def test_draw_interval_is_a_t_interval():
    got = D.draw_interval([1.0, 2.0, 3.0])
    # mean 2, sd 1, sem 1/sqrt(3), t(0.975, 2) = 4.3027
    assert got.value == 2.0 and got.hi - 2.0 == pytest.approx(4.302653 / math.sqrt(3), rel=1e-5)
    assert got.method == "t over 3 sample draws"


def test_one_nna_has_no_reference_bootstrap():
    with pytest.raises(ValueError, match="not a mean over the reference members"):
        D.reference_bootstrap("1nna", np.zeros((2, 2)))


# --------------------------------------------------------------------------- bad input


def test_bad_matrices_are_named():
    with pytest.raises(ValueError, match="non-finite distance at \\(0, 1\\)"):
        D.mmd(np.array([[0.0, np.nan]]))
    with pytest.raises(ValueError, match="empty"):
        D.cov(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="2-D"):
        D.mmd(np.zeros(3))
    with pytest.raises(ValueError, match="d_ss has shape"):
        D.one_nna(np.zeros((2, 2)), np.zeros((3, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="unknown distributional metric 'fid'"):
        D.reference_bootstrap("fid", np.zeros((2, 2)))
    with pytest.raises(ValueError, match="n_boot"):
        D.reference_bootstrap("mmd", np.zeros((2, 2)), n_boot=0)
    with pytest.raises(ValueError, match="at least 2 draws"):
        D.draw_interval([0.5])
    with pytest.raises(ValueError, match="not finite"):
        D.draw_interval([0.5, np.inf])


# --------------------------------------------------------------------------- BRDF distances


def _tables(n: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        v = rng.lognormal(-1.0, 1.5, size=(3, *merl.SHAPE)).astype(np.float64)
        v[:, ~merl.grid_above_horizon().numpy().reshape(merl.SHAPE)] = -1.0
        out.append(v)
    return out


def _slow_distance(x: np.ndarray, y: np.ndarray, kind: str, cells: np.ndarray) -> float:
    cos = merl.grid_directions(torch.float64)[0][:, 2].numpy()[cells]
    f, g = x.reshape(3, -1)[:, cells], y.reshape(3, -1)[:, cells]
    if kind == "l1_log":
        f, g = np.log1p(f), np.log1p(g)
    elif kind == "l1_log_cos":
        f, g = np.log1p(f * cos), np.log1p(g * cos)
    return float(np.abs(f - g).mean())


@pytest.mark.parametrize("kind", brdf_distances.KINDS)
def test_distance_matrix_equals_the_direct_mean_over_common_valid_cells(kind):
    a, b = _tables(2, 0), _tables(3, 1)
    b[1][:, 5, 5, :] = -1.0  # a cell one table lacks is left out of every pair
    cells = brdf_distances.common_valid_cells(a, b)
    assert 5 * 90 * 180 + 5 * 180 not in set(cells.tolist())
    d = brdf_distances.distance_matrix(a, b, kind, chunk_cells=400_000)
    for i in range(2):
        for j in range(3):
            assert d[i, j] == pytest.approx(_slow_distance(a[i], b[j], kind, cells), rel=1e-6)


def test_distance_matrix_is_symmetric_with_a_zero_diagonal_and_chunking_does_not_matter():
    a = _tables(3, 2)
    cells = brdf_distances.common_valid_cells(a)[::97]
    d = brdf_distances.distance_matrix(a, kind="l1_log", cells=cells, chunk_cells=1000)
    assert np.allclose(d, d.T, rtol=1e-6) and (np.diag(d) == 0).all() and (d[~np.eye(3, dtype=bool)] > 0).all()
    coarse = brdf_distances.distance_matrix(a, kind="l1_log", cells=cells, chunk_cells=10**6)
    assert np.allclose(d, coarse, rtol=1e-6)


def test_distance_matrix_bad_input():
    good = _tables(1, 3)
    with pytest.raises(ValueError, match="set b, member 0: expected MERL values of shape"):
        brdf_distances.distance_matrix(good, [np.zeros((3, 4))], "l1")
    with pytest.raises(ValueError, match="unknown BRDF distance 'l2'"):
        brdf_distances.distance_matrix(good, good, "l2")
    with pytest.raises(ValueError, match="members in both sets"):
        brdf_distances.distance_matrix(good, [], "l1")
    dead = np.full((3, *merl.SHAPE), -1.0)
    with pytest.raises(ValueError, match="no MERL cell is valid"):
        brdf_distances.distance_matrix(good, [dead], "l1")


def test_a_memory_mapped_merl_file_reads_as_its_table(tmp_path):
    tables = _tables(2, 4)
    path = tmp_path / "m.binary"
    merl.write_binary(path, merl.MerlTable.from_values(tables[1]))
    cells = brdf_distances.common_valid_cells(tables)[::50]
    as_file = brdf_distances.distance_matrix(tables[:1], [brdf_distances.MerlFileCells(path)], "l1_log_cos", cells=cells)
    as_array = brdf_distances.distance_matrix(tables[:1], tables[1:], "l1_log_cos", cells=cells)
    assert as_file[0, 0] == pytest.approx(as_array[0, 0], rel=1e-12)


def test_a_representation_evaluated_at_the_cell_centres_is_its_table():
    from brdfbench.plugins import registry
    from brdfbench.data.synthetic import synthetic_dataset

    material = next(iter(synthetic_dataset("small", seed=0)))
    model = registry.get("representations", "merl").load()().fit(material)
    cells = brdf_distances.common_valid_cells([material.table])[::200]
    d = brdf_distances.distance_matrix([material.table], [brdf_distances.RepresentationCells(model)], "l1",
                                       cells=cells)
    assert d[0, 0] < 1e-6 * float(np.abs(material.table.values.reshape(3, -1)[:, cells]).mean())


class _Broken:
    def grid_cells(self, cells):
        v = np.ones((3, len(cells)))
        v[0, 0] = np.nan
        return v


def test_a_source_with_non_finite_values_is_named():
    with pytest.raises(ValueError, match="set b, member 0: non-finite values"):
        brdf_distances.distance_matrix(_tables(1, 5), [_Broken()], "l1", cells=np.arange(10) + 200_000)


@pytest.mark.parametrize("n, m", [(1, 1), (3, 5), (4, 4), (7, 2), (9, 9)])
def test_the_l1_kernel_equals_numpy(n, m):
    """Every tile shape of the compiled kernel (full tiles of four and the rest), both forms."""
    rng = np.random.default_rng(n * 10 + m)
    xa, xb = rng.random((n, 2500)), rng.random((m, 2500))
    out = np.zeros((n, m))
    brdf_distances.l1_sums(xa, xb, out)
    assert np.allclose(out, np.abs(xa[:, None, :] - xb[None, :, :]).sum(-1), rtol=1e-12)
    sym = np.zeros((n, n))
    brdf_distances.l1_sums(xa, xa, sym, symmetric=True)
    want = np.triu(np.abs(xa[:, None, :] - xa[None, :, :]).sum(-1), 1)
    assert np.allclose(sym, want, rtol=1e-12) and (np.tril(sym) == 0).all()


def test_the_kernel_leaves_torchs_openmp_alone():
    """numba's OpenMP layer shares torch's OpenMP runtime and resets its thread count, after
    which torch's reductions in the process sum in another order (it changed a figure of a
    later in-process run in its last bit): the kernel runs on numba's own thread pool."""
    import numba

    brdf_distances.l1_sums(np.ones((2, 8)), np.ones((2, 8)), np.zeros((2, 2)), symmetric=True)
    assert numba.threading_layer() == "workqueue"


class _Counting:
    """A table as a cell source that counts the cells it is asked for."""

    def __init__(self, values):
        self.flat, self.read = values.reshape(3, -1), 0

    def grid_cells(self, cells):
        self.read += len(cells)
        return self.flat[:, cells].copy()


def test_each_member_is_read_once_per_cell():
    """The common valid cells come from the values read for the distances, not from a pass of their own."""
    tables = _tables(2, 6)
    tables[0][:, 3, 4, :] = -1.0  # cells one member lacks
    members = [_Counting(t) for t in tables]
    d = brdf_distances.distance_matrix(members, kind="l1", chunk_cells=300_000)
    above = int(merl.grid_above_horizon().sum())
    assert [m.read for m in members] == [above, above]
    want = _slow_distance(tables[0], tables[1], "l1", brdf_distances.common_valid_cells(tables))
    assert d[0, 1] == pytest.approx(want, rel=1e-6)
