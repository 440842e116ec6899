"""Tabulated MERL variants: nearest, trilinear, and downsampled block sampling."""

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.errors import ConfigError
from brdfbench.protocols.representation import Material
from brdfbench_representations.merl import DENSITIES, TabulatedMERL, block_samples


def _index_table():
    """raw value = flat cell index, so a lookup tells which cell it read."""
    raw = np.broadcast_to(np.arange(merl.N_CELLS, dtype=np.float64).reshape(merl.SHAPE), (3, *merl.SHAPE)).copy()
    return raw


@pytest.mark.parametrize("x", [2, 8, 24])
def test_downsampled_lookup_reads_the_block_centre(x):
    raw = _index_table()
    model = TabulatedMERL(downsample=x).fit(Material("idx", merl.MerlTable(raw)))
    wi, wo = merl.grid_directions()
    cell = (model.eval(wi, wo)[:, 0] / merl.CHANNEL_SCALES[0]).round().long()
    ih, id_, ip = np.unravel_index(cell.numpy(), merl.SHAPE)
    gh, gd, gp = np.unravel_index(np.arange(merl.N_CELLS), merl.SHAPE)
    above = ((wi[:, 2] > 0) & (wo[:, 2] > 0)).numpy()
    # Same block as the query cell, and at its centre (clipped to the table where the block overhangs).
    for got, query, n in ((ih, gh, 90), (id_, gd, 90), (ip, gp, 180)):
        assert np.array_equal(got[above] // x, query[above] // x)
        centre = np.minimum(query // x * x + (x - 1) // 2 + (x % 2 == 0) * 0, n - 1)
        assert np.abs(got[above] - centre[above]).max() <= 1


def test_invalid_centre_falls_back_to_nearest_valid_cell_in_block():
    raw = np.ones((3, *merl.SHAPE))
    raw[:, 0:4, 0:4, 0:4] = merl.INVALID_RAW
    raw[:, 3, 3, 3] = 7.0  # the only valid cell of the first 4x4x4 block
    samples = block_samples(raw, 4)
    assert samples[0, 0, 0, 0] == 7.0
    raw[:, 3, 3, 3] = merl.INVALID_RAW
    assert block_samples(raw, 4)[0, 0, 0, 0] < 0  # no valid cell: stays invalid (evaluates to 0)


def test_sizes_shrink_with_density():
    target = Material("ones", merl.MerlTable(np.ones((3, *merl.SHAPE))))
    sizes = [TabulatedMERL(downsample=x).fit(target).nbytes for x in DENSITIES]
    assert sizes == sorted(sizes, reverse=True)
    assert sizes[0] == 3 * merl.N_CELLS * 8 and sizes[-1] == 3 * 3 * 3 * 6 * 8


def test_downsample_one_is_the_reference_lookup():
    raw = _index_table()
    a = TabulatedMERL().fit(Material("idx", merl.MerlTable(raw)))
    b = TabulatedMERL(downsample=1).fit(Material("idx", merl.MerlTable(raw)))
    wi, wo = merl.grid_directions()
    assert torch.equal(a.eval(wi[:5000], wo[:5000]), b.eval(wi[:5000], wo[:5000]))


@pytest.mark.parametrize("params,match", [
    ({"downsample": 3}, "downsample=3"),
    ({"downsample": 4, "mode": "trilinear"}, "nearest neighbour"),
    ({"mode": "cubic"}, "'cubic'"),
])
def test_bad_parameters(params, match):
    with pytest.raises(ConfigError, match=match):
        TabulatedMERL(**params)
