"""The device paths of the set metrics, run on the CPU where CI checks them: the BRDF
distance matrices' torch path (what a GPU runs) against the numba kernel, the image
distance matrices' device block sizes against the CPU's, `device="cpu"` as the default
everywhere, and the generation harness's handling of the job's device and of samples
that live off the CPU. The same paths on a real GPU: tests/gpu/test_metrics_gpu.py."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.device import CPU, Placed
from brdfbench.distances import brdf as BD
from brdfbench_metrics import image as IM
from brdfbench.distances import image as ID
from brdfbench.distances import image_functional as IF

#: The torch path sums in another order than the numba kernel (fp64 both): measured about
#: 1e-14 relative on full-grid tables; the brief holds it to 1e-12.
REL = 1e-12


def _tables(n: int, seed: int, dtype=np.float64) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        v = rng.lognormal(-1.0, 1.5, size=(3, *merl.SHAPE))
        v[:, ~merl.grid_above_horizon().numpy().reshape(merl.SHAPE)] = -1.0
        out.append(v.astype(dtype))
    return out


def _close(got: np.ndarray, want: np.ndarray, rel: float = REL) -> float:
    """Largest relative difference (entries that are 0 in `want` must be 0 in `got`)."""
    assert got.shape == want.shape and got.dtype == np.float64
    zero = want == 0
    assert (got[zero] == 0).all()
    worst = float((np.abs(got - want)[~zero] / np.abs(want[~zero])).max()) if (~zero).any() else 0.0
    assert worst <= rel, worst
    return worst


@pytest.fixture(scope="module")
def sets():
    a, b = _tables(3, 0), _tables(2, 1, np.float32)
    a[1][:, 5, 5, :] = -1.0  # cells one member lacks: left out of every pair
    a[2][1, 20, 3, :7] = np.nan
    b[0][2, 40, 10, :] = np.inf
    return a, b


# --------------------------------------------------------------------------- BRDF distances


@pytest.mark.parametrize("kind", BD.KINDS)
def test_the_torch_path_agrees_with_numba_over_the_full_grid(sets, kind):
    a, b = sets
    _close(BD.distance_matrix(a, b, kind, backend="torch"), BD.distance_matrix(a, b, kind))
    sym = BD.distance_matrix(a + b, None, kind, backend="torch")
    _close(sym, BD.distance_matrix(a + b, None, kind))
    assert (np.diag(sym) == 0).all() and (sym == sym.T).all()


def test_chunks_column_blocks_and_groups_do_not_change_the_torch_sums(sets, monkeypatch):
    a, b = sets
    want = BD.distance_matrix(a, b, "l1_log_cos")
    monkeypatch.setattr(BD, "COLUMN_BLOCK_BYTES", 1)  # the narrowest column blocks (256 values)
    monkeypatch.setattr(BD, "SUMS_BYTES", 1)  # one block's sums per call
    calls = []
    got = BD.distance_matrix(a, b, "l1_log_cos", backend="torch", chunk_cells=300_000,
                             progress=lambda d, n: calls.append((d, n)))
    _close(got, want)
    above = int(merl.grid_above_horizon().sum())
    assert calls[-1] == (above, above) and len(calls) == -(-above // 300_000)


def test_the_torch_chunk_follows_the_memory_budget(sets, monkeypatch):
    """Chunks hold about DEVICE_BYTES / (members · 3 · BYTES_PER_VALUE) cells: device memory
    stays at the budget whatever the number of members."""
    a, b = sets
    monkeypatch.setattr(BD, "DEVICE_BYTES", 5 * 3 * BD.BYTES_PER_VALUE * 100_000)
    calls = []
    BD.distance_matrix(a, b, "l1", backend="torch", progress=lambda d, n: calls.append(d))
    assert calls[0] == 100_000


def test_chosen_cells_on_the_torch_path(sets):
    a, b = _tables(2, 3), _tables(2, 4)
    cells = BD.common_valid_cells(a, b)[::37]
    for kind in BD.KINDS:
        _close(BD.distance_matrix(a, b, kind, cells=cells, backend="torch"),
               BD.distance_matrix(a, b, kind, cells=cells))


def test_representation_tensor_and_file_members_on_the_torch_path(tmp_path):
    from brdfbench.plugins import registry
    from brdfbench.data.synthetic import generate_material
    from brdfbench.protocols.representation import Material

    materials = [Material(name, table, category) for name, category, table in
                 (generate_material(i, seed=0) for i in range(3))]
    tables = [m.table for m in materials]
    merl_rep = registry.get("representations", "merl").load()
    lambert = registry.get("representations", "lambert").load()
    members = [BD.RepresentationCells(merl_rep().fit(materials[0])),
               BD.RepresentationCells(lambert().fit(materials[1])),
               torch.from_numpy(tables[2].values.copy())]
    path = tmp_path / "m.binary"
    merl.write_binary(path, tables[1])
    others = [tables[0], BD.MerlFileCells(path)]
    for kind in BD.KINDS:
        _close(BD.distance_matrix(members, others, kind, backend="torch"), BD.distance_matrix(members, others, kind))


def test_the_torch_path_checks_as_the_numba_path():
    class Broken:
        def grid_cells(self, cells):
            v = np.ones((3, len(cells)))
            v[0, 0] = np.nan
            return v

    class Short:
        def grid_cells(self, cells):
            return np.ones((3, len(cells) - 1))

    good = _tables(1, 5)
    with pytest.raises(ValueError, match="set b, member 0: non-finite values"):
        BD.distance_matrix(good, [Broken()], "l1", cells=np.arange(10) + 200_000, backend="torch")
    with pytest.raises(ValueError, match="set b, member 0: a chunk of 10 cells came back with shape"):
        BD.distance_matrix(good, [Short()], "l1", cells=np.arange(10) + 200_000, backend="torch")
    with pytest.raises(ValueError, match="no MERL cell is valid"):
        BD.distance_matrix(good, [np.full((3, *merl.SHAPE), -1.0)], "l1", backend="torch")
    with pytest.raises(ValueError, match="unknown backend 'cupy'"):
        BD.distance_matrix(good, good, "l1", backend="cupy")
    with pytest.raises(ValueError, match="backend='numba' runs on the CPU"):
        BD.distance_matrix(good, good, "l1", backend="numba", device="cuda:0")
    with pytest.raises(ValueError, match="set a, member 0: expected MERL values of shape"):
        BD.distance_matrix([torch.zeros(3, 4)], good, "l1", backend="torch")


def test_the_cpu_device_is_the_numba_path(sets, monkeypatch):
    a, b = sets
    want = BD.distance_matrix(a, b, "l1_log")
    assert (BD.distance_matrix(a, b, "l1_log", device="cpu") == want).all()
    assert (BD.distance_matrix(a, b, "l1_log", device=torch.device("cpu"), backend="numba") == want).all()
    monkeypatch.setattr(BD, "_torch_matrix", lambda *args: pytest.fail("the CPU took the torch path"))
    BD.distance_matrix(a, b, "l1", device="cpu")


# --------------------------------------------------------------------------- image distances


@pytest.fixture(scope="module")
def images():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(7, 24, 20, 3, generator=g, dtype=torch.float64) * 1.5
    b = torch.rand(5, 24, 20, 3, generator=g, dtype=torch.float64) * 1.5
    return a, b


@pytest.mark.parametrize("space", ID.SPACES)
@pytest.mark.parametrize("kind", ID.KINDS)
def test_the_image_device_path_agrees_with_the_cpu(images, monkeypatch, kind, space):
    a, b = images
    want = ID.image_distance_matrix(a, b, kind, space=space)
    want_sym = ID.image_distance_matrix(a, None, kind, space=space)
    assert (ID.image_distance_matrix(a, b, kind, space=space, device="cpu") == want).all()
    monkeypatch.setattr(ID, "_DEVICE_PATH_ON_CPU", True)
    np.testing.assert_allclose(ID.image_distance_matrix(a, b, kind, space=space), want, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ID.image_distance_matrix(a, None, kind, space=space), want_sym, rtol=1e-12,
                               atol=1e-15)


@pytest.mark.parametrize("fn", [IF.mse, IF.rmse, IF.psnr, IF.ssim])
def test_image_functions_take_a_device(images, fn):
    a, b = images
    for space in IF.SPACES:
        want = fn(a[:5], b, space=space, reduction="none")
        got = fn(a[:5], b, space=space, reduction="none", device="cpu")
        assert got.device == a.device and torch.equal(got, want)
    value, smap = IF.ssim(a[0], b[0], space="ldr", return_map=True, device=torch.device("cpu"))
    assert value.ndim == 0 and smap.shape == (24, 20)


def test_streaming_metrics_take_a_device(images):
    a, b = images
    plain, placed = IM.SSIMLDR(), IM.SSIMLDR(device="cpu")
    plain.update(a[:5], b)
    placed.update(a[:5], b)
    assert placed.device == CPU and placed.compute() == plain.compute()
    flip = IM.FLIPLDR(device="cpu")  # numpy: FLIP computes on the CPU whatever device it is given
    flip.update(a[0].float(), b[0].float())
    assert 0 < flip.compute() < 1


# --------------------------------------------------------------------------- FID


def test_fid_features_on_the_cpu_device_are_the_default():
    from brdfbench_metrics import fid as FD

    try:
        model = FD.load_inception()
    except FD.FidUnavailable as exc:
        pytest.skip(str(exc))
    assert FD.load_inception(device="cpu") is model  # one CPU network, whatever asks for it
    x = torch.rand(2, 16, 16, 3, generator=torch.Generator().manual_seed(0))
    assert np.array_equal(FD.inception_features(x, device="cpu"), FD.inception_features(x))


def test_fid_turns_tf32_off_on_a_gpu_and_restores_it():
    """cuDNN's flags are process state: set for the network's passes on a CUDA device (fp32
    without TF32, deterministic algorithms), restored after, and left alone on the CPU."""
    from brdfbench_metrics import fid as FD

    cudnn = torch.backends.cudnn
    before = (cudnn.allow_tf32, cudnn.deterministic, cudnn.benchmark)
    with FD._exact_fp32(torch.device("cpu")):
        assert (cudnn.allow_tf32, cudnn.deterministic, cudnn.benchmark) == before
    with FD._exact_fp32(torch.device("cuda", 0)):  # only flags: no CUDA needed to set them
        assert not cudnn.allow_tf32 and cudnn.deterministic and not cudnn.benchmark and cudnn.enabled
    assert (cudnn.allow_tf32, cudnn.deterministic, cudnn.benchmark) == before


# --------------------------------------------------------------------------- the generation harness


class _Moving(Placed):
    """A representation whose `to` records where it was sent (the "meta" device stands for a
    GPU on a machine without one)."""

    devices = frozenset({"cpu", "meta"})

    def __init__(self):
        self.moves = []

    def _move(self, device):
        self.moves.append(device.type)

    def eval(self, wi, wo):
        return torch.ones(wi.shape[0], 3, dtype=wi.dtype, device=wi.device)


def test_the_generation_harness_uses_the_jobs_device():
    from brdfbench.harness import HarnessContext
    from brdfbench_generators.harness import GenerationConfig, GenerationHarness

    assert GenerationHarness.uses_device
    context = dict(scene=None, metric_specs=[], seed=0, results_dir=None, dataset_fingerprint="", representation="",
                   representation_params={}, scene_name="", scene_params={})
    assert GenerationHarness(GenerationConfig(), HarnessContext(**context)).device == CPU
    on = GenerationHarness(GenerationConfig(), HarnessContext(**context, device=torch.device("meta")))
    assert on.device == torch.device("meta")


def test_samples_off_the_cpu_are_placed_evaluated_and_rendered_on_the_cpu():
    from brdfbench_generators.harness import grid_values, on_cpu, placed

    m = _Moving()
    assert placed(m, CPU) is m and m.moves == []  # a set on the CPU: nothing moves
    assert placed(m, torch.device("meta")).device.type == "meta"  # built from device parameters: placed there
    assert on_cpu(m).device == CPU and m.moves == ["meta", "cpu"]
    assert on_cpu(m) is m and m.moves == ["meta", "cpu"]
    v = grid_values(_Moving(), chunk=1 << 20)
    assert v.shape == (3, *merl.SHAPE) and v.dtype == np.float32 and (v == 1).all()


def test_grid_values_on_the_cpu_are_the_models_own():
    from brdfbench.plugins import registry
    from brdfbench.data.synthetic import generate_material
    from brdfbench.protocols.representation import Material
    from brdfbench_generators.harness import grid_values

    name, category, table = generate_material(0, seed=0)
    material = Material(name, table, category)
    model = registry.get("representations", "lambert").load()().fit(material)
    wi, wo = merl.grid_directions(torch.float64)
    want = model.eval(wi, wo).T.numpy().astype(np.float32).reshape(3, *merl.SHAPE)
    assert np.array_equal(grid_values(model), want)
