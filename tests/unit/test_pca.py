"""PCA after Nielsen et al.: held-out projection, least squares on valid cells, bad input."""

import json

import numpy as np
import pytest
import safetensors.torch
import torch

from brdfbench import merl, modelio
from brdfbench.errors import ConfigError, DataError, ModelFileError
from brdfbench.harness.accuracy import evaluate_accuracy
from brdfbench.protocols.representation import Material
from brdfbench.plugins.registry import get
from brdfbench.pipeline.plan import plan_folds
from brdfbench.testing.kit import reference_material, training_materials
from brdfbench_representations.pca import PCA, _domain


@pytest.fixture(scope="module")
def trained():
    return PCA().train(training_materials())


def test_held_out_material_beats_lambert(trained):
    target = reference_material()  # not in the training split
    metric = [get("metrics", "l1_log_cos")]
    pca_err = evaluate_accuracy(trained.fit(target), target, metric, n_random=1024)[0].value
    lambert = get("representations", "lambert").create().fit(target)
    lambert_err = evaluate_accuracy(lambert, target, metric, n_random=1024)[0].value
    assert pca_err < 0.5 * lambert_err


def test_k_defaults_to_all_available_below_300(trained):
    from brdfbench.testing.kit import TRAINING_INDICES

    assert trained.basis.shape[1] == 3 * len(TRAINING_INDICES) - 1
    gram = trained.basis.double().T @ trained.basis.double()
    assert torch.allclose(gram, torch.eye(gram.shape[0], dtype=torch.float64), atol=1e-4)


def test_k_larger_than_training_rank_is_a_clear_error():
    with pytest.raises(ConfigError, match=r"k=100 is larger than the 17 components that 6 training materials"):
        PCA(k=100).train(training_materials())
    with pytest.raises(ConfigError, match="positive integer"):
        PCA(k=0)


def test_projection_is_least_squares_on_valid_cells(trained):
    target = reference_material()
    model = PCA(k=5).train(training_materials()).fit(target)
    values = torch.from_numpy(target.table.values.reshape(3, -1))[:, _domain()[0]]
    valid = torch.from_numpy(target.table.valid.reshape(-1))[_domain()[0]]
    assert (~valid).any(), "the reference material should have invalid cells for this test"
    centred = model._map(values) - model.mean.double()
    reference = torch.linalg.lstsq(model.basis.double()[valid], centred[:, valid].T).solution.T
    # The projection multiplies fp32 blocks (the basis is stored in fp32), summed in fp64:
    # accurate relative to the coefficient vector, per channel.
    error = torch.linalg.vector_norm(model.coefficients - reference, dim=1)
    assert (error <= 1e-5 * torch.linalg.vector_norm(reference, dim=1)).all(), error


def test_all_invalid_and_nan_targets_are_clear_errors(trained):
    raw = np.full((3, *merl.SHAPE), merl.INVALID_RAW)
    with pytest.raises(DataError, match="'dead': every cell is invalid"):
        trained.fit(Material("dead", merl.MerlTable(raw)))
    raw = reference_material().table.raw.copy()
    raw[0, 10, 10, 10] = np.nan
    with pytest.raises(DataError, match="'nanny': non-finite"):
        trained.fit(Material("nanny", merl.MerlTable(raw)))


def test_bytes_per_material_and_shared(trained):
    trained.fit(reference_material())
    k = trained.basis.shape[1]
    assert trained.nbytes == 3 * k * 8
    p = _domain()[0].numel()
    assert trained.shared_nbytes == (p * k + p + 3 * p) * 4


def test_model_file_with_mismatched_basis_is_refused(trained, tmp_path):
    trained.fit(reference_material())
    path = modelio.save(trained, "pca", tmp_path / "pca.safetensors")
    _, loaded = modelio.load(path)
    assert torch.equal(loaded.coefficients, trained.coefficients)
    state = {k: v for k, v in trained.state_dict().items()}
    state["basis"] = state["basis"][:-7]  # a basis for a different table shape
    header = {"format": "brdfbench.model/1", "representation": "pca", "params": {"k": None}, "metadata": {}}
    safetensors.torch.save_file(state, str(path), metadata={"brdfbench": json.dumps(header)})
    with pytest.raises(ModelFileError, match=rf"{path}: pca model: tensor 'basis' has shape \(\d+, \d+\), expected \(\d+, any\)"):
        modelio.load(path)


def test_cross_validation_fits_each_material_once_never_on_its_training_data():
    materials = tuple(f"m{i}" for i in range(10))
    plan = plan_folds(materials, True, 4, seed=3)
    fitted = [m for _, fit in plan for m in fit]
    assert sorted(fitted) == sorted(materials)
    for train, fit in plan:
        assert not set(train) & set(fit) and set(train) | set(fit) == set(materials)
    assert plan == plan_folds(materials, True, 4, seed=3)
    assert plan_folds(materials, False, 4, seed=3) == [(None, list(materials))]
    with pytest.raises(ConfigError, match="harness.folds=1"):
        plan_folds(materials, True, 1, seed=0)
    with pytest.raises(ConfigError, match="2 materials"):
        plan_folds(("only",), True, 4, seed=0)
    leave_one_out = plan_folds(materials[:3], True, 4, seed=0)
    assert sorted(len(fit) for _, fit in leave_one_out) == [1, 1, 1]
