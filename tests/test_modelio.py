import pickle

import pytest
import torch

from brdfbench import modelio
from brdfbench.errors import ModelFileError, PluginError
from brdfbench_representations.lambert import Lambert


def test_roundtrip_keeps_params_and_values(tmp_path):
    model = Lambert()
    model.albedo = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    path = modelio.save(model, "lambert", tmp_path / "m.safetensors")
    name, loaded = modelio.load(path)
    assert name == "lambert" and torch.equal(loaded.albedo, model.albedo)
    assert not list(tmp_path.glob(".*.tmp"))


def test_pickle_is_refused_without_being_unpickled(tmp_path):
    class Boom:
        def __reduce__(self):
            return (exec, ("raise SystemExit('pickle code ran')",))

    path = tmp_path / "model.safetensors"
    path.write_bytes(pickle.dumps(Boom()))
    with pytest.raises(ModelFileError, match=rf"{path}.*pickle"):
        modelio.load(path)


def test_torch_save_archive_is_refused(tmp_path):
    path = tmp_path / "model.pt"
    torch.save({"albedo": torch.ones(3)}, path)
    with pytest.raises(ModelFileError, match=rf"{path}.*zip archive"):
        modelio.load(path)
    # The weights-only importer reads plain tensors but refuses code.
    assert torch.equal(modelio.load_torch_weights(path)["albedo"], torch.ones(3))


def test_garbage_and_missing_files(tmp_path):
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x10\x00\x00\x00\x00\x00\x00\x00{not json}")
    with pytest.raises(ModelFileError, match=str(junk)):
        modelio.load(junk)
    with pytest.raises(ModelFileError, match="cannot read"):
        modelio.load(tmp_path / "absent.safetensors")


def test_safetensors_without_brdfbench_header(tmp_path):
    import safetensors.torch

    path = tmp_path / "plain.safetensors"
    safetensors.torch.save_file({"x": torch.ones(2)}, str(path))
    with pytest.raises(ModelFileError, match="lacks brdfbench metadata"):
        modelio.load(path)


def test_unknown_representation_in_file(tmp_path):
    model = Lambert()
    path = modelio.save(model, "lambert", tmp_path / "m.safetensors")
    import json

    import safetensors.torch

    header = {"format": "brdfbench.model/1", "representation": "lambret", "params": {}, "metadata": {}}
    safetensors.torch.save_file(model.state_dict(), str(path), metadata={"brdfbench": json.dumps(header)})
    with pytest.raises(PluginError, match="Did you mean 'lambert'"):
        modelio.load(path)
