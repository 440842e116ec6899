import pickle

import pytest
import torch

from brdfbench import modelio
from brdfbench.errors import ModelFileError
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
    with pytest.raises(ModelFileError, match=rf"{path}.*'lambret'.*Did you mean 'lambert'.*Registered: .*ggx"):
        modelio.load(path)


def relabel(path, tensors, **header):
    """Rewrite a model file with the given tensors and brdfbench header fields (as a hand-edited file would be)."""
    import json

    import safetensors.torch

    header = {"format": "brdfbench.model/1", "representation": "lambert", "params": {}, "metadata": {}, **header}
    safetensors.torch.save_file(tensors, str(path), metadata={"brdfbench": json.dumps(header)})
    return path


@pytest.fixture
def ggx_file(tmp_path):
    from brdfbench.plugins import registry

    model = registry.get("representations", "ggx").create()
    return modelio.save(model, "ggx", tmp_path / "ggx.safetensors"), model


def test_file_naming_another_representation_names_the_missing_tensor(tmp_path, ggx_file):
    """A ggx model's tensors under a 'lambert' header: no KeyError, the file and the tensor named."""
    _, ggx = ggx_file
    path = relabel(tmp_path / "m.safetensors", ggx.state_dict(), representation="lambert")
    with pytest.raises(ModelFileError, match=rf"{path}: lacks tensor\(s\) 'albedo'.*'lambert'.*holds: '"):
        modelio.load(path)


def test_missing_tensors_are_all_named(tmp_path, ggx_file):
    _, ggx = ggx_file
    tensors = ggx.state_dict()
    dropped = sorted(tensors)[:2]
    path = relabel(tmp_path / "m.safetensors", {k: v for k, v in tensors.items() if k not in dropped},
                   representation="ggx", params=ggx.params)
    with pytest.raises(ModelFileError) as err:
        modelio.load(path)
    assert str(path) in str(err.value) and all(repr(k) in str(err.value) for k in dropped)


def test_unknown_parameter_names_it_and_what_is_taken(tmp_path, ggx_file):
    path, ggx = ggx_file
    relabel(path, ggx.state_dict(), representation="ggx", params={**ggx.params, "bogus": 1})
    with pytest.raises(ModelFileError, match=rf"{path}: representation 'ggx' takes no param\(s\) 'bogus'; "
                                             r"it takes: n_samples, restarts"):
        modelio.load(path)
    relabel(path, {"albedo": torch.ones(3)}, params={"k": 3})
    with pytest.raises(ModelFileError, match=r"'lambert' takes no param\(s\) 'k'; it takes: no params"):
        modelio.load(path)


@pytest.mark.parametrize("field, value", [("representation", ["lambert"]), ("params", [1]), ("metadata", "x")])
def test_header_fields_of_the_wrong_type(tmp_path, field, value):
    path = relabel(tmp_path / "m.safetensors", {"albedo": torch.ones(3)}, **{field: value})
    with pytest.raises(ModelFileError, match=rf"{path}: brdfbench metadata key '{field}' must be"):
        modelio.load(path)


def test_tensor_of_the_wrong_shape_is_a_model_file_error(tmp_path, ggx_file):
    path, ggx = ggx_file
    tensors = {k: torch.ones(7, dtype=torch.float64) for k in ggx.state_dict()}
    relabel(path, tensors, representation="ggx", params=ggx.params)
    with pytest.raises(ModelFileError, match=rf"{path}: ggx model: tensor 'kd' has 7 value\(s\), expected 3"):
        modelio.load(path)
