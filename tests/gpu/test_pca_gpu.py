"""PCA trained and projected on a GPU reconstructs the CPU's table; its evaluation is the
reference reader's lookup on the host, values returned on the inputs' device."""

from __future__ import annotations

import numpy as np
import torch

from brdfbench.data.synthetic import generate_material
from brdfbench.protocols.representation import Material
from brdfbench_representations.pca import PCA


def _materials(n):
    return [Material(name, table, category) for name, category, table in (generate_material(i, seed=0) for i in range(n))]


def test_a_gpu_trained_pca_reconstructs_the_cpu_table(gpu):
    mats = _materials(9)
    cpu = PCA(k=6).train(mats[1:], seed=0).fit(mats[0])
    dev = PCA(k=6).to(gpu).train(mats[1:], seed=0).fit(mats[0])
    assert dev.basis.device.type == "cuda" and dev.coefficients.device.type == "cuda"
    a, b = cpu.table.values, dev.table.values
    valid = cpu.table.valid
    assert np.array_equal(valid, dev.table.valid)
    # other summation orders in the Gram matrix and the projection: a few ulps of fp32, amplified by exp
    np.testing.assert_allclose(b[:, valid], a[:, valid], rtol=1e-4, atol=1e-7)
    wi = torch.nn.functional.normalize(torch.rand(10_000, 3, dtype=torch.float64) + 0.01, dim=1)
    wo = torch.nn.functional.normalize(torch.rand(10_000, 3, dtype=torch.float64) + 0.01, dim=1)
    out = dev.eval(wi.to(gpu), wo.to(gpu))
    assert out.device.type == "cuda"
    assert torch.equal(out.cpu(), dev.eval(wi, wo))  # the same host lookup wherever the inputs live
