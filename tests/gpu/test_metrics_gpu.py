"""The set metrics on a GPU: the BRDF distance matrices (torch on the device) against the
CPU's numba kernel, for tables and for representations evaluated where they live; the
image distance matrices and SSIM against the CPU; InceptionV3's features (FID) against the
CPU's; and the generation harness's samples built from parameters on the GPU. Each check
is small: the whole file takes seconds on an H200."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.nbrdf import layouts
from brdfbench.nbrdf import network as net
from brdfbench.distances import brdf as BD
from brdfbench_metrics import fid as FD
from brdfbench.distances import image as ID
from brdfbench.distances import image_functional as IF

#: The torch path sums in another order than numba: fp64 rounding, about 1e-14.
REL = 1e-12


def _rel(got: np.ndarray, want: np.ndarray) -> float:
    zero = want == 0
    assert (got[zero] == 0).all()
    return float((np.abs(got - want)[~zero] / np.abs(want[~zero])).max())


def _tables(n: int, seed: int, dtype) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        v = rng.lognormal(-1.0, 1.5, size=(3, *merl.SHAPE))
        v[:, ~merl.grid_above_horizon().numpy().reshape(merl.SHAPE)] = -1.0
        out.append(v.astype(dtype))
    return out


@pytest.fixture(scope="module")
def tables():
    a, b = _tables(4, 0, np.float64), _tables(3, 1, np.float32)
    a[1][:, 5, 5, :] = -1.0  # cells one member lacks
    b[2][0, 40, 10, :3] = np.nan
    return a, b


@pytest.mark.parametrize("kind", BD.KINDS)
def test_gpu_distance_matrix_of_tables_agrees_with_numba(tables, gpu, kind):
    a, b = tables
    want = BD.distance_matrix(a, b, kind)
    assert _rel(BD.distance_matrix(a, b, kind, device=gpu), want) <= REL
    sym = BD.distance_matrix(a + b, None, kind, device=gpu)
    assert _rel(sym, BD.distance_matrix(a + b, None, kind)) <= REL
    assert (np.diag(sym) == 0).all() and (sym == sym.T).all()
    on_gpu = [torch.from_numpy(t).to(gpu) for t in a]  # tables already on the device
    assert _rel(BD.distance_matrix(on_gpu, b, kind, device=gpu), want) <= REL


def _networks(n: int, seed: int):
    from brdfbench_representations.nbrdf import NBRDF

    g = torch.Generator().manual_seed(seed)
    out = []
    for _ in range(n):
        weights = net.glorot_init((21, 21), g)
        out.append(NBRDF.from_network(net.Network(weights={k: 0.5 * v for k, v in weights.items()})))
    return out


def test_gpu_distance_matrix_of_representations_agrees_with_numba(tables, gpu):
    """Representations evaluate on their own device: networks moved to the GPU there, the
    CPU's on the CPU; their fp64 values differ by rounding only."""
    a, _ = tables
    cpu = _networks(3, 7)
    dev = [m.to(gpu) for m in _networks(3, 7)]
    for kind in BD.KINDS:
        want = BD.distance_matrix([BD.RepresentationCells(m) for m in cpu] + a[:2], None, kind)
        got = BD.distance_matrix([BD.RepresentationCells(m) for m in dev] + a[:2], None, kind, device=gpu)
        assert _rel(got, want) <= REL, kind


@pytest.fixture(scope="module")
def images():
    g = torch.Generator().manual_seed(0)
    base = torch.rand(1, 64, 64, 3, generator=g, dtype=torch.float64)
    a = base * torch.rand(20, 1, 1, 3, generator=g, dtype=torch.float64) * 2
    b = torch.rand(15, 64, 64, 3, generator=g, dtype=torch.float64) * 1.5
    return a.float(), b.float()


@pytest.mark.parametrize("space", ID.SPACES)
@pytest.mark.parametrize("kind", ID.KINDS)
def test_gpu_image_distance_matrices_agree_with_the_cpu(images, gpu, kind, space):
    a, b = images
    for other in (b, None):
        want = ID.image_distance_matrix(a, other, kind, space=space)
        got = ID.image_distance_matrix(a, other, kind, space=space, device=gpu)
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
        if other is None:
            assert (got == got.T).all()


@pytest.mark.parametrize("space", IF.SPACES)
def test_gpu_ssim_and_psnr_agree_with_the_cpu(images, gpu, space):
    a, b = images
    want, want_map = IF.ssim(a[:15], b, space=space, return_map=True, reduction="none")
    got, got_map = IF.ssim(a[:15], b, space=space, return_map=True, reduction="none", device=gpu)
    assert got.device.type == "cpu"  # values come back on pred's device
    torch.testing.assert_close(got, want, rtol=1e-6, atol=1e-9)
    torch.testing.assert_close(got_map, want_map, rtol=1e-6, atol=1e-9)
    on_gpu = IF.ssim(a[:15].to(gpu), b.to(gpu), space=space, reduction="none")  # images already there
    assert on_gpu.device.type == "cuda"
    torch.testing.assert_close(on_gpu.cpu(), want, rtol=1e-6, atol=1e-9)
    torch.testing.assert_close(IF.psnr(a[:15], b, space=space, device=gpu), IF.psnr(a[:15], b, space=space),
                               rtol=1e-6, atol=1e-9)


def test_gpu_inception_features_agree_with_the_cpu(images, gpu):
    """The network runs in fp32 on both devices (TF32 off on the GPU) from the very same
    input bits; cuDNN's convolutions sum in other orders than the CPU's, so features differ
    by fp32 rounding carried through 90-odd layers: held to 1e-3 of the largest feature
    (measured about 1e-5 on an H200), FID to 1e-3 relative."""
    try:
        FD.load_inception()
    except FD.FidUnavailable as exc:
        pytest.skip(str(exc))
    a, b = images
    a, b = a[:6], b[:6]
    want = FD.inception_features(a, threads=None)
    got = FD.inception_features(a, device=gpu)
    assert np.abs(got - want).max() <= 1e-3 * np.abs(want).max()
    assert FD.fid(a, b, device=gpu, threads=None) == pytest.approx(FD.fid(a, b, threads=None), rel=1e-3)


def test_samples_built_on_the_gpu_are_evaluated_there_and_rendered_on_the_cpu(gpu):
    from brdfbench_generators.harness import grid_values, on_cpu, placed
    from brdfbench_generators.samples import WeightSamples

    g = torch.Generator().manual_seed(3)
    rows = np.stack([layouts.flatten({k: 0.5 * v for k, v in net.glorot_init((21, 21), g).items()})
                     for _ in range(2)])
    on_device, on_host = WeightSamples(torch.from_numpy(rows).to(gpu)), WeightSamples(torch.from_numpy(rows))
    built = placed(on_device[0], on_device.array.device)
    assert built.device.type == "cuda"
    want = grid_values(on_host[0])
    np.testing.assert_allclose(grid_values(built), want, rtol=1e-6, atol=1e-12)
    moved = on_cpu(built)
    assert moved.device.type == "cpu"
    wi, wo = merl.grid_directions(torch.float64)
    torch.testing.assert_close(moved.eval(wi[:1000], wo[:1000]), on_host[0].eval(wi[:1000], wo[:1000]),
                               rtol=1e-12, atol=1e-15)
