"""The NBRDF fitter's hand-written CPU backward pass against torch autograd, the reference:
the same gradients for each output and loss, with masked-out samples and a material
that has no valid sample in the minibatch, and the same fits; and the best-constant
reference of the naive MLP's collapse detector."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from brdfbench import merl
from brdfbench.data.synthetic import generate_material
from brdfbench.nbrdf import network as net
from brdfbench_representations import nbrdf_fit as nf

S, M, BATCH = 3000, 4, 1000


def _inits(hidden, n=M):
    inits = [net.glorot_init(hidden, torch.Generator().manual_seed(i)) for i in range(n)]
    last = f"b{len(hidden) + 1}"
    for i, w in enumerate(inits):  # outputs on both sides of 0, where the clamped output's gradient stops
        w[last] = w[last] + torch.tensor([0.5, -0.5, 0.0]) * i
    return inits


def _problem(in_features=6):
    g = torch.Generator().manual_seed(0)
    x = torch.rand(S, in_features, generator=g) * 2 - 1
    cos = torch.rand(S, generator=g).clamp(nf.COS_MIN, 1 - 2.0**-24)
    y = torch.rand(S, M, 3, generator=g) * 2
    mask = (torch.rand(S, M, generator=g) > 0.2).float()  # about 20 % of the samples masked out
    mask[:BATCH, 2] = 0  # material 2 has no valid sample in the first minibatch
    return x, torch.log(cos), torch.log1p(-cos), y, mask


def _gradients(engine, inits, recipe, problem, idx):
    names = list(inits[0])
    if engine == "manual":
        epochs = nf._CpuEpochs(nf._FlatStack(inits, names), recipe, *problem, 10)
    else:
        epochs = nf._AutogradEpochs(nf._Stack(inits, names), recipe, *problem, 10)
    return epochs.gradients(idx)


@pytest.mark.parametrize("output", ["log", "clamped"])
@pytest.mark.parametrize("loss", ["l1", "l2"])
@pytest.mark.parametrize("hidden", [(21, 21), (8, 5, 7)], ids=["published", "three_hidden"])
def test_hand_written_gradients_equal_autograd(output, loss, hidden):
    recipe = nf.Recipe(output=output, loss=loss, batch_size=BATCH)
    problem = _problem()
    inits = _inits(hidden)
    shuffled = torch.randperm(S, generator=torch.Generator().manual_seed(1))[:BATCH]
    for first, idx in ((True, torch.arange(BATCH)), (False, shuffled)):
        ref = _gradients("autograd", inits, recipe, problem, idx)
        got = _gradients("manual", inits, recipe, problem, idx)
        for i, (a, b) in enumerate(zip(ref, got)):
            assert list(a) == list(b)
            for k in a:
                scale = float(a[k].abs().max())
                torch.testing.assert_close(b[k], a[k], rtol=1e-5, atol=1e-5 * scale + 1e-12, msg=f"material {i} {k}")
        if first:  # material 2 has no valid sample here: no gradient
            assert all(float(g.abs().max()) == 0 for g in got[2].values())
        assert all(float(g.abs().max()) > 0 for g in ref[0].values())


@pytest.mark.parametrize("loss", ["l1", "l2"])
def test_hand_written_fit_follows_autograd(loss):
    """A short fit with an early stop (rows dropped mid-fit) ends where the reference ends."""
    tables = [generate_material(i, seed=0)[2] for i in (1, 4, 9)]
    recipe = nf.Recipe(epochs=4, batch_size=1024, lr=1e-2, n_samples=30_000, patience=1, min_improvement=0.02,
                       loss=loss)
    inits = [net.glorot_init((21, 21), torch.Generator().manual_seed(i)) for i in range(3)]
    ref = nf.fit_batched(tables, inits, recipe=recipe, engine="autograd")
    got = nf.fit_batched(tables, inits, recipe=recipe, engine="manual")
    for a, b in zip(ref, got):
        assert a.epochs == b.epochs
        assert b.loss == pytest.approx(a.loss, rel=1e-3)
        for k in a.weights:
            torch.testing.assert_close(b.weights[k], a.weights[k], rtol=1e-3, atol=1e-4)


def test_an_unknown_engine_is_refused():
    with pytest.raises(ValueError, match="engine"):
        nf.fit_batched([generate_material(1, seed=0)[2]], _inits((21, 21), 1), recipe=nf.Recipe(n_samples=1000),
                       engine="numba")


def test_the_best_constant_of_a_constant_brdf_fits_it():
    """The collapse detector's reference: a constant BRDF's best constant is itself (loss ~0),
    and any fit's ratio is its loss over the best constant's."""
    values = np.broadcast_to(np.array([0.05, 0.2, 1.5])[:, None, None, None], (3, *merl.SHAPE)).copy()
    flat = merl.MerlTable.from_values(values)
    samples = nf.draw_samples(40_000, "directions", seed=0)
    sharp = generate_material(11, seed=0)[2]
    const = nf.constant_loss([flat, sharp], samples)
    assert float(const[0]) < 1e-5 and float(const[1]) > 0.05
    assert nf.collapse_ratio([sharp], [float(const[1]) / 2], samples) == pytest.approx([0.5])
