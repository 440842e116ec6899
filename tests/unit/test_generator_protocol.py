"""The generator protocol's pieces: weight sets, splits, training data, sample sets, files."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import modelio
from brdfbench.errors import ConfigError, DataError, ModelFileError
from brdfbench.plugins import registry
from brdfbench.protocols.generator import TrainingData, WeightSet, seeded_split
from brdfbench_generators.samples import WeightSamples
from brdfbench_generators.training_set import TrainingSet


def test_a_weight_set_of_mixed_network_sizes_is_refused():
    with pytest.raises(DataError, match="share one architecture"):
        WeightSet(("a", "b"), np.zeros((2, 500), dtype=np.float32))
    with pytest.raises(DataError, match="expected a \\(2, W\\) array"):
        WeightSet(("a", "b"), np.zeros((3, 675), dtype=np.float32))


def test_a_weight_set_with_a_non_finite_weight_names_the_material():
    v = np.zeros((2, 675), dtype=np.float32)
    v[1, 17] = np.inf
    with pytest.raises(DataError, match="'b' has non-finite weights"):
        WeightSet(("a", "b"), v)


def test_training_data_without_weights_says_which_dataset_has_them():
    data = TrainingData(("a",), load=lambda n: None, dataset="synthetic")
    assert not data.has_weights
    with pytest.raises(DataError, match="dataset=neumerl"):
        data.weights()


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 300), fraction=st.floats(0.01, 0.99), seed=st.integers(0, 2**31 - 1))
def test_a_seeded_split_is_deterministic_disjoint_and_complete(n, fraction, seed):
    names = [f"m{i}" for i in range(n)]
    train, test = seeded_split(names, fraction, seed)
    assert (train, test) == seeded_split(names, fraction, seed)
    assert set(train).isdisjoint(test) and set(train) | set(test) == set(names)
    assert train and test and len(test) == min(n - 1, max(1, int(np.floor(fraction * n + 0.5))))
    assert list(train) == [m for m in names if m in set(train)]  # in the names' order


@pytest.mark.parametrize("names, fraction", [(["a"], 0.5), (["a", "b"], 0.0), (["a", "b"], 1.0)])
def test_a_split_that_cannot_be_made_is_refused(names, fraction):
    with pytest.raises(ConfigError):
        seeded_split(names, fraction, 0)


def test_a_sample_set_refuses_to_build_a_non_finite_sample_and_bad_indices():
    array = torch.zeros(3, 675)
    array[1, 0] = float("nan")
    samples = WeightSamples(array)
    assert samples.finite.tolist() == [True, False, True]
    assert len(samples[0:3:2]) == 2
    with pytest.raises(ValueError, match="sample 1 has non-finite"):
        samples[1]
    with pytest.raises(IndexError):
        samples[3]
    with pytest.raises(TypeError):
        samples["0"]
    assert samples[-1].eval(torch.tensor([[0.0, 0.0, 1.0]]), torch.tensor([[0.0, 0.0, 1.0]])).shape == (1, 3)


def test_generator_and_representation_files_do_not_load_as_each_other(tmp_path):
    gen = TrainingSet().fit(TrainingData(("a", "b"), load=lambda n: None))
    path = modelio.save_generator(gen, "training_set", tmp_path / "g.safetensors")
    assert modelio.holds_generator(path)
    with pytest.raises(ModelFileError, match="holds a generator, not a representation"):
        modelio.load(path)
    name, loaded = modelio.load_generator(path)
    assert name == "training_set" and loaded.names == ("a", "b")
    from brdfbench_representations.lambert import Lambert

    rep = modelio.save(Lambert(), "lambert", tmp_path / "r.safetensors")
    assert not modelio.holds_generator(rep)
    with pytest.raises(ModelFileError, match="holds a representation, not a generator"):
        modelio.load_generator(rep)


@pytest.mark.parametrize("name", registry.names("generators"))
def test_an_untrained_generator_saves_and_loads_untrained(name):
    """What an untrained generator saves (no tensors, no metadata) loads back untrained, for
    every built-in: none refuses its own empty state."""
    spec = registry.get("generators", name)
    gen = spec.create(**spec.kit_params)
    assert not gen.fitted
    tensors, metadata = gen.state_dict(), gen.metadata()
    loaded = type(gen).from_state(gen.params, tensors, metadata)
    assert type(loaded) is type(gen) and not loaded.fitted and loaded.state_dict() == tensors == {}
