"""The native MERL lookup (drjit_kernels.merl_cell) returns the reference reader's cells.

It decides most lanes in fp32 and sends those near a cell edge (or ill-conditioned) to an
fp64 branch. These tests pin the three claims that make that exact: the fp32 coordinates'
error stays well below the tolerance, every lane the fp32 path is sure of lies in the
reference's cell (random, adversarial and cell-edge pairs, and a hypothesis property),
and the fp32 path decides almost every lane, so the branch stays rare.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import coords, merl, mitsuba_env
from brdfbench.testing import adversarial_pairs
from brdfbench.testing.kit import reference_material

pytestmark = pytest.mark.skipif(not mitsuba_env.llvm_usable(), reason="drjit does not load LLVM >= 19 here")


@pytest.fixture(scope="module")
def dk():
    with mitsuba_env.mitsuba_variant(mitsuba_env.LLVM_VARIANT):
        from brdfbench.render import drjit_kernels

        yield drjit_kernels


def vec(t: torch.Tensor):
    import mitsuba as mi

    t = t.to(torch.float32)
    return mi.Vector3f(*(mi.Float(np.ascontiguousarray(t[:, c].numpy())) for c in range(3)))


def above(wi: torch.Tensor, wo: torch.Tensor):
    wi, wo = wi.float(), wo.float()
    keep = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    return wi[keep], wo[keep]


def reference_flat(wi: torch.Tensor, wo: torch.Tensor) -> np.ndarray:
    ih, id_, ip = merl.cell_indices(wi, wo)
    return ((ih * merl.RES_THETA_D + id_) * merl.RES_PHI_D + ip).numpy()


def native_flat(dk, wi: torch.Tensor, wo: torch.Tensor) -> np.ndarray:
    return np.asarray(dk.merl_cell(vec(wi), vec(wo)))


def reference_coordinates(wi: torch.Tensor, wo: torch.Tensor) -> tuple[np.ndarray, ...]:
    """The reader's continuous (u_h, u_d, u_p) in fp64, in cells, from its own angles."""
    theta_h, theta_d, phi_d = merl.reader_angles(wi, wo)
    u_h = np.sqrt(np.clip(theta_h.numpy() / (math.pi / 2) * merl.RES_THETA_H**2, 0, None))
    u_d = theta_d.numpy() / (math.pi / 2) * merl.RES_THETA_D
    u_p = merl.fold_phi_diff(phi_d).numpy() / math.pi * merl.RES_PHI_D
    return u_h, u_d, u_p


def assert_reference_cells(dk, wi: torch.Tensor, wo: torch.Tensor, what: str = "") -> np.ndarray:
    """The native cells equal the reader's (brdfbench.merl's, which are bitwise the
    reader's), except where the reader's own coordinate lies within 1e-9 cells of an edge,
    or at a degenerate pair (its θh or θd below 1e-6 rad), where only the φd cell may
    differ: there the reader's cell hangs on the last bits of sin, cos, acos and atan2,
    and drjit's fp64 ones are not the C library's. Returns the mask of those pairs."""
    got, want = native_flat(dk, wi, wo), reference_flat(wi, wo)
    exempt = np.zeros(len(got), dtype=bool)
    for u in reference_coordinates(wi, wo):
        exempt |= np.abs(u - np.round(u)) < 1e-9
    theta_h, theta_d, _ = merl.reader_angles(wi, wo)
    degenerate = ~((theta_h.numpy() >= 1e-6) & (theta_d.numpy() >= 1e-6))
    exempt |= degenerate & (got // merl.RES_PHI_D == want // merl.RES_PHI_D)
    wrong = got != want
    assert not (wrong & ~exempt).any(), f"{what}: {int((wrong & ~exempt).sum())} of {len(got)} pairs in another cell"
    return exempt


def random_pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """ωi uniform in solid angle, ωo cosine-distributed: a renderer's pairs."""
    u = torch.rand(n, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    wi = coords.spherical_to_vector(torch.acos(1 - u[:, 0]), 2 * math.pi * u[:, 1])
    wo = coords.spherical_to_vector(torch.acos(torch.sqrt(1 - u[:, 2])), 2 * math.pi * u[:, 3])
    return above(wi, wo)


def edge_pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Pairs whose θh, θd or φd lies on a cell edge, or within 1e-9 .. 1e-4 (relative) of
    one, on either side; the other angles random."""
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 5, generator=g, dtype=torch.float64)
    theta_h = u[:, 0] * math.pi / 2
    theta_d = u[:, 1] * math.pi / 2
    phi_d = u[:, 2] * 2 * math.pi
    phi_h = u[:, 3] * 2 * math.pi
    which = torch.randint(0, 3, (n,), generator=g)
    k = u[:, 4]
    offset = torch.pow(10.0, -4 - 5 * torch.rand(n, generator=g, dtype=torch.float64))
    offset = offset * torch.where(torch.rand(n, generator=g) < 0.5, -1.0, 1.0).double()
    offset[torch.rand(n, generator=g) < 0.1] = 0.0  # exactly on the edge (before rounding to fp32)
    edge_h = (torch.floor(k * 89) + 1) ** 2 / merl.RES_THETA_H**2 * (math.pi / 2)
    edge_d = (torch.floor(k * 89) + 1) * (math.pi / 180)
    edge_p = torch.floor(k * 360) * (math.pi / 180)
    theta_h = torch.where(which == 0, edge_h * (1 + offset), theta_h)
    theta_d = torch.where(which == 1, edge_d * (1 + offset), theta_d)
    phi_d = torch.where(which == 2, edge_p + offset, phi_d)
    wi, wo = coords.from_half_diff(theta_h, phi_h, theta_d, phi_d)
    return above(coords.normalize(wi), coords.normalize(wo))


def test_fp32_coordinates_err_far_below_the_tolerance(dk):
    """The tolerance is ~10x the fp32 path's worst error; assert at least 5x over 2·10⁶
    renderer-like pairs and every adversarial family."""
    pairs = [random_pairs(2_000_000, seed=1)]
    pairs += [above(*p) for fam, p in adversarial_pairs(400_000, torch.float64, seed=2).items()
              if fam not in ("below_horizon", "identical")]
    for wi, wo in pairs:
        u_h, u_d, u_p, sin2, dz, ok = (np.asarray(x) for x in dk.merl_coordinates(vec(wi), vec(wo)))
        ref_h, ref_d, ref_p = reference_coordinates(wi, wo)
        with np.errstate(invalid="ignore"):  # 0/0 where θd = 0: not well posed, masked below
            sin_d = np.sqrt(sin2 / (sin2 + dz * dz))
        err_p = np.abs(u_p - ref_p)
        err_p = np.minimum(err_p, merl.RES_PHI_D - err_p) * sin_d  # φd wraps at 0 ~ π
        if not ok.any():
            continue  # θh = 0 for every pair (the mirror family): all go to fp64
        worst = max(np.abs(u_h - ref_h)[ok].max(), np.abs(u_d - ref_d)[ok].max(), err_p[ok].max())
        assert worst < dk.MERL_EDGE_TOL / 5, f"fp32 coordinate error {worst:.2e} cells"


@pytest.mark.parametrize("name, make", [
    ("random", lambda: random_pairs(1_000_000, seed=3)),
    ("cell edges", lambda: edge_pairs(400_000, seed=4)),
    ("cell centres", lambda: tuple(d[::3].float() for d in merl.grid_directions(torch.float64))),
])
def test_native_cells_are_the_reference_cells(dk, name, make):
    exempt = assert_reference_cells(dk, *make(), what=name)
    assert exempt.mean() < 0.01 or name == "cell centres"  # centres: φd = 0 is an edge


def test_adversarial_pairs_land_in_the_reference_cells(dk):
    # Every family but ωi = ωo exactly, where φd is rounding noise in the reference too.
    for fam, (wi, wo) in adversarial_pairs(70_000, torch.float64, seed=5).items():
        if fam in ("identical", "below_horizon"):
            continue
        assert_reference_cells(dk, *above(wi, wo), what=fam)


def test_the_fp32_path_decides_almost_every_lane(dk):
    wi, wo = random_pairs(1_000_000, seed=6)
    unsure = np.asarray(dk.merl_cells_fast(vec(wi), vec(wo))[3])
    assert 0 < unsure.mean() < 0.01, f"{unsure.mean():.3%} of lanes take the fp64 branch"
    wi, wo = edge_pairs(100_000, seed=7)
    assert np.asarray(dk.merl_cells_fast(vec(wi), vec(wo))[3]).mean() > 0.5  # the edges do


angle = st.floats(0.0, 1.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(angle, angle, angle, angle), min_size=1, max_size=64),
       st.sampled_from([0.0, 1e-9, -1e-9, 1e-7, -1e-7, 1e-5, -1e-5]), st.integers(0, 2))
def test_cells_match_near_any_edge(dk, fractions, offset, which):
    """Property: θh/θd/φd nudged to any cell edge (or off it by a relative offset) still
    gives the reference's cell."""
    f = torch.tensor(fractions, dtype=torch.float64)
    theta_h, theta_d = f[:, 0] * math.pi / 2, f[:, 1] * math.pi / 2
    phi_h, phi_d = f[:, 2] * 2 * math.pi, f[:, 3] * 2 * math.pi
    if which == 0:
        theta_h = torch.round(torch.sqrt(theta_h / (math.pi / 2)) * 90) ** 2 / 8100 * (math.pi / 2) * (1 + offset)
    elif which == 1:
        theta_d = torch.round(theta_d * 180 / math.pi) * (math.pi / 180) * (1 + offset)
    else:
        phi_d = torch.round(phi_d * 180 / math.pi) * (math.pi / 180) + offset
    wi, wo = coords.from_half_diff(theta_h, phi_h, theta_d.clamp(max=math.pi / 2), phi_d)
    wi, wo = above(coords.normalize(wi), coords.normalize(wo))
    if len(wi) == 0:
        return
    assert_reference_cells(dk, wi, wo, what=f"edge of coordinate {which}, offset {offset}")


def test_half_vector_in_the_xz_plane_behind_the_normal(dk):
    """h with h_y = 0 exactly and h_x < 0 has φh = π: the fp64 branch once took an fp32 π
    there (a select of two Python floats), rotating by 8.7e-8 rad too much and moving φd
    by 4.6e-7 cells into the neighbouring cell (found by the edge property above)."""
    wi = torch.tensor([[-0.15405487, -0.5, 0.85221308]], dtype=torch.float32)
    wo = torch.tensor([[-0.85482579, 0.5, 0.1388267]], dtype=torch.float32)
    assert native_flat(dk, wi, wo)[0] == reference_flat(wi, wo)[0]
    theta_h, theta_d, phi_d = (np.asarray(a) for a in dk.merl_reader_angles64(vec(wi), vec(wo)))
    want = merl.reader_angles(wi, wo)
    for got, ref in zip((theta_h, theta_d, phi_d), want):
        assert abs(float(got[0]) - float(ref[0])) < 1e-14


def test_tables_sit_on_aligned_memory(dk):
    """A packet gather from memory not aligned to the packet silently becomes separate
    gathers: a different, slower kernel, decided by where numpy's allocator put the table."""
    for _ in range(4):
        kernel = dk.MerlTableKernel(reference_material().table.values)
        assert np.from_dlpack(kernel.table).ctypes.data % 64 == 0
        assert kernel.finite


def _kernel_values(kernel, wi, wo) -> np.ndarray:
    got = kernel.eval(vec(wi), vec(wo))
    return np.stack([np.asarray(got[c]) for c in range(3)], axis=1)


@pytest.mark.parametrize("params", [{}, {"downsample": 4}, {"mode": "trilinear"}], ids=["nearest", "downsample4", "trilinear"])
def test_kernel_values_equal_the_torch_lookup(dk, params, fitted):
    """Nearest cells: the very values (fp32 rounding of the table); trilinear: to fp32
    rounding of the weights, including grazing, θh = 0 and invalid neighbours. (Not at
    ωi = ωo, where φd is undefined and its rounding noise picks the φd neighbours.)"""
    model = fitted("merl", **params)
    kernel = dk.kernel_for(model)
    assert kernel is not None
    wi, wo = random_pairs(200_000, seed=8)
    for fam, pair in adversarial_pairs(20_000, torch.float64, seed=9).items():
        if fam not in ("below_horizon", "identical"):
            wi, wo = torch.cat([wi, above(*pair)[0]]), torch.cat([wo, above(*pair)[1]])
    got, want = _kernel_values(kernel, wi, wo), model.eval(wi, wo).numpy()
    assert np.isfinite(got).all()
    if params.get("mode") == "trilinear":  # fp32 coordinates move a weight by up to 3e-5 of a cell
        np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-7)
    else:
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=0)
