"""NBRDF weight formats (brdfbench/nbrdf/formats.py) and the `brdfbench convert` command.

Layouts under test: Keras h5 kernels are (in, out); the flat vector of hyperdiffusion work
(675 values for 6-21-21-3) is fc1.weight, fc1.bias, fc2.weight, … with torch nn.Linear
(out, in) shapes, row-major; torch state dicts hold {fc1.weight, fc1.bias, …}.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from brdfbench import merl, modelio
from brdfbench.plugins import registry
from brdfbench.nbrdf import formats as nf
from brdfbench.nbrdf import network as nw
from brdfbench.nbrdf.keras_h5 import layout, read_nbrdf_h5
from brdfbench.errors import ModelFileError
from brdfbench.testing import adversarial_pairs
from brdfbench_representations.nbrdf import NBRDF, NaiveMLP

PUBLISHED = (21, 21)
N_PUBLISHED = 675


# --------------------------------------------------------------------------- helpers
# tests/ is not a package and no test module imports another, so the two small h5 helpers
# of test_nbrdf_release.py are repeated here rather than imported.


def random_weights(seed: int = 0, scale: float = 0.3, hidden=PUBLISHED) -> dict[str, np.ndarray]:
    """Keras-layout float32 weights (W (in, out), b) with normal entries."""
    rng = np.random.default_rng(seed)
    return {k: (rng.standard_normal(s) * scale).astype(np.float32) for k, s in nw.weight_shapes(hidden).items()}


def torch_weights(seed: int = 0, hidden=PUBLISHED) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(v) for k, v in random_weights(seed, hidden=hidden).items()}


def write_h5(path, weights: dict[str, np.ndarray], skip: str | None = None, override: dict | None = None,
             hidden=PUBLISHED) -> None:
    """A Keras-2.2-style weights file; `skip` leaves one weight out, `override` replaces arrays."""
    override = override or {}
    with h5py.File(path, "w") as f:
        for name, (key, _) in layout(hidden).items():
            if name != skip:
                f.create_dataset(key, data=override.get(name, weights[name]))


def bits(t: torch.Tensor) -> torch.Tensor:
    """The raw float32 bit patterns, so equality also tells -0.0 from 0.0."""
    return t.detach().to(torch.float32).contiguous().view(torch.int32)


def assert_same_weights(got: dict[str, torch.Tensor], want: dict[str, torch.Tensor]) -> None:
    assert list(got) == list(want)
    for k in want:
        assert got[k].dtype == torch.float32 and tuple(got[k].shape) == tuple(want[k].shape), k
        assert torch.equal(bits(got[k]), bits(want[k])), k


class FcNet(torch.nn.Module):
    """A 6 → hidden… → 3 ReLU MLP whose state dict reads fc1.weight, fc1.bias, …"""

    def __init__(self, hidden=PUBLISHED):
        super().__init__()
        sizes = [6, *hidden, 3]
        self.n = len(sizes) - 1
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:]), start=1):
            setattr(self, f"fc{i}", torch.nn.Linear(a, b))

    def forward(self, x):
        for i in range(1, self.n + 1):
            x = getattr(self, f"fc{i}")(x)
            if i < self.n:
                x = torch.relu(x)
        return x


class Wrapped(torch.nn.Module):
    """FcNet under an attribute, so its keys read net.fc1.weight, …"""

    def __init__(self):
        super().__init__()
        self.net = FcNet()

    def forward(self, x):
        return self.net(x)


CANARY_ENV = "BRDFBENCH_TEST_CANARY"


def _canary_fired(path):
    Path(path).write_text("unpickled")
    return "fired"


class Canary:
    """Pickles to a call that writes a marker file: proof of unpickling if the file appears."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (_canary_fired, (self.marker,))


@pytest.fixture(scope="module")
def pairs():
    """Uniform direction pairs (float32), all above the horizon."""
    wi, wo = adversarial_pairs(4096, torch.float32, seed=0)["uniform"]
    assert bool((wi[:, 2] > 0).all() and (wo[:, 2] > 0).all())
    return wi, wo


# --------------------------------------------------------------------------- flatten / unflatten

hidden_sizes = st.lists(st.integers(1, 32), min_size=1, max_size=3)
finite_f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)


@settings(max_examples=25, deadline=None)
@given(hidden=hidden_sizes, data=st.data())
def test_unflatten_inverts_flatten(hidden, data):
    """Any finite weights of any 6 → hidden… → 3 shape survive flatten/unflatten bit for bit."""
    weights = {k: torch.from_numpy(data.draw(hnp.arrays(np.float32, s, elements=finite_f32), label=k))
               for k, s in nw.weight_shapes(hidden).items()}
    vector = nf.flatten(weights)
    assert isinstance(vector, np.ndarray) and vector.dtype == np.float32 and vector.ndim == 1
    assert vector.size == nw.n_weights(hidden)
    assert_same_weights(nf.unflatten(vector, hidden), weights)
    assert np.array_equal(nf.flatten(nf.unflatten(vector, hidden)).view(np.int32), vector.view(np.int32))


@settings(max_examples=25, deadline=None)
@given(hidden=hidden_sizes, seed=st.integers(0, 2**32 - 1))
def test_unflatten_of_a_torch_vector_equals_that_of_numpy(hidden, seed):
    vector = nf.flatten(torch_weights(seed, hidden))
    assert_same_weights(nf.unflatten(torch.from_numpy(vector), hidden), nf.unflatten(vector, hidden))


def test_published_network_has_675_weights():
    assert nw.n_weights(PUBLISHED) == N_PUBLISHED
    assert nf.flatten(torch_weights()).shape == (N_PUBLISHED,)
    assert nf.unflatten(np.zeros(N_PUBLISHED, np.float32))["W1"].shape == (6, 21)


def test_vector_starts_with_fc1_weight_rows():
    """fc1.weight is (out, in) row-major: the first 6 values are the first output's 6 input weights."""
    w = torch_weights()
    v = nf.flatten(w)
    assert np.array_equal(v[:6], w["W1"][:, 0].numpy())
    assert np.array_equal(v[6:12], w["W1"][:, 1].numpy())
    assert np.array_equal(v[126:147], w["b1"].numpy())
    assert np.array_equal(v[-3:], w["b3"].numpy())


# --------------------------------------------------------------------------- order against real torch stacks


@pytest.mark.parametrize("hidden", [PUBLISHED, (16, 16), (8,), (5, 7, 4)], ids=str)
def test_vector_order_is_that_of_nn_linear_parameters(hidden):
    """unflatten(cat(net.parameters())) computes what the nn.Sequential computes."""
    torch.manual_seed(1)
    sizes = [6, *hidden, 3]
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [torch.nn.Linear(a, b), torch.nn.ReLU()]
    net = torch.nn.Sequential(*layers[:-1])
    vector = torch.cat([p.detach().reshape(-1) for p in net.parameters()])
    assert vector.numel() == nw.n_weights(hidden)
    weights = nf.unflatten(vector, hidden)
    assert nw.hidden_of(weights) == list(hidden)
    x = torch.randn(512, 6)
    with torch.no_grad():
        torch.testing.assert_close(nw.last_layer(weights, x), net(x), rtol=1e-5, atol=1e-6)
    assert np.array_equal(nf.flatten(weights), vector.numpy())


@pytest.mark.parametrize("module", [FcNet, Wrapped], ids=["fc1.weight", "net.fc1.weight"])
def test_from_torch_state_matches_the_module(module):
    torch.manual_seed(2)
    net = module()
    state = net.state_dict()
    weights = nf.from_torch_state(state)
    assert nw.hidden_of(weights) == list(PUBLISHED)
    x = torch.randn(512, 6)
    with torch.no_grad():
        torch.testing.assert_close(nw.last_layer(weights, x), net(x), rtol=1e-5, atol=1e-6)
    # the state dict's parameter order is the flat vector's order
    assert np.array_equal(nf.flatten(weights), torch.cat([p.reshape(-1) for p in state.values()]).numpy())


def test_to_torch_state_loads_into_nn_linear_stack():
    weights = torch_weights(3)
    net = FcNet()
    net.load_state_dict(nf.to_torch_state(weights), strict=True)
    x = torch.randn(256, 6)
    with torch.no_grad():
        torch.testing.assert_close(net(x), nw.last_layer(weights, x), rtol=1e-5, atol=1e-6)
    assert_same_weights(nf.from_torch_state(nf.to_torch_state(weights)), weights)


def test_from_torch_state_infers_hidden_sizes():
    state = FcNet((9, 4, 11)).state_dict()
    assert nw.hidden_of(nf.from_torch_state(state)) == [9, 4, 11]


# --------------------------------------------------------------------------- file round trips


@pytest.mark.parametrize("suffix", [".npy", ".pt", ".pth", ".safetensors"])
@pytest.mark.parametrize("hidden", [PUBLISHED, (16, 16), (4, 5, 6)], ids=str)
def test_write_then_read_gives_identical_weights(tmp_path, suffix, hidden):
    network = nf.Network(torch_weights(4, hidden))
    path = nf.write_network(network, tmp_path / "sub" / f"net{suffix}")
    assert path == tmp_path / "sub" / f"net{suffix}" and path.is_file()
    back = nf.read_network(path, hidden=hidden)
    assert_same_weights(back.weights, network.weights)
    assert back.hidden == list(hidden) and back.features == "rusinkiewicz" and back.raw_units is False
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary files left


def test_npy_is_a_plain_float32_vector(tmp_path):
    weights = torch_weights(5)
    path = nf.write_network(nf.Network(weights), tmp_path / "w.npy")
    array = np.load(path, allow_pickle=False)
    assert array.dtype == np.float32 and array.shape == (N_PUBLISHED,)
    assert np.array_equal(array, nf.flatten(weights))


def test_pt_is_a_plain_state_dict(tmp_path):
    weights = torch_weights(6)
    path = nf.write_network(nf.Network(weights), tmp_path / "w.pt")
    state = torch.load(path, weights_only=True)
    assert isinstance(state, dict)
    assert list(state) == ["fc1.weight", "fc1.bias", "fc2.weight", "fc2.bias", "fc3.weight", "fc3.bias"]
    assert state["fc1.weight"].shape == (21, 6) and state["fc3.weight"].shape == (3, 21)
    assert torch.equal(state["fc1.weight"], weights["W1"].T)
    # loads straight into a torch module
    FcNet().load_state_dict(state, strict=True)


def test_pt_holding_a_flat_tensor_reads(tmp_path):
    weights = torch_weights(7)
    path = tmp_path / "flat.pt"
    torch.save(torch.tensor(nf.flatten(weights)), path)
    assert_same_weights(nf.read_network(path).weights, weights)


def test_pt_float64_state_dict_reads_as_float32(tmp_path):
    weights = torch_weights(8)
    path = tmp_path / "f64.pt"
    torch.save({k: v.double() for k, v in nf.to_torch_state(weights).items()}, path)
    assert_same_weights(nf.read_network(path).weights, weights)


@pytest.mark.parametrize("suffix", [".h5", ".hdf5"])
def test_h5_reads_what_the_release_reader_reads(tmp_path, suffix):
    path = tmp_path / f"mat{suffix}"
    write_h5(path, random_weights(9))
    want = {k: torch.from_numpy(v) for k, v in read_nbrdf_h5(path).items()}
    assert_same_weights(nf.read_network(path).weights, want)


def test_h5_with_other_hidden_sizes(tmp_path):
    path = tmp_path / "small.h5"
    write_h5(path, random_weights(10, hidden=(16, 16)), hidden=(16, 16))
    network = nf.read_network(path, hidden=(16, 16))
    assert network.hidden == [16, 16]
    assert_same_weights(network.weights, torch_weights(10, (16, 16)))


@pytest.mark.parametrize("features, cls", [("rusinkiewicz", NBRDF), ("directions", NaiveMLP)])
def test_model_evaluates_identically_after_safetensors_round_trip(tmp_path, pairs, features, cls):
    network = nf.Network(torch_weights(11), features=features)
    model = nf.to_model(network)
    assert type(model) is cls and model.hidden == list(PUBLISHED)
    wi, wo = pairs
    before = model.eval(wi, wo)
    assert before.shape == (wi.shape[0], 3) and bool(torch.isfinite(before).all()) and bool((before > 0).any())
    path = nf.write_network(network, tmp_path / "m.safetensors")
    name, loaded = modelio.load(path)
    assert name == cls.plugin_name
    assert torch.equal(loaded.eval(wi, wo), before)
    back = nf.read_network(path)
    assert back.features == features and back.raw_units is False
    assert torch.equal(nf.to_model(back).eval(wi, wo), before)


def test_model_from_registry_reads_back(tmp_path, pairs):
    """A brdfbench nbrdf model file (as the runner saves it) converts to a vector and back."""
    model = registry.get("representations", "nbrdf").create(hidden=[21, 21])
    model.weights = torch_weights(12)
    path = modelio.save(model, "nbrdf", tmp_path / "fitted.safetensors")
    network = nf.read_network(path)
    assert_same_weights(network.weights, model.weights)
    vec = nf.write_network(network, tmp_path / "fitted.npy")
    again = nf.to_model(nf.read_network(vec))
    assert torch.equal(again.eval(*pairs), model.eval(*pairs))


def test_raw_units_scale_by_merl_channel_scales(tmp_path, pairs):
    weights = torch_weights(13)
    plain = nf.to_model(nf.Network(weights, raw_units=False)).eval(*pairs)
    raw_network = nf.Network(weights, raw_units=True)
    raw = nf.to_model(raw_network).eval(*pairs)
    assert torch.equal(raw, plain * torch.tensor(merl.CHANNEL_SCALES, dtype=torch.float32))
    path = nf.write_network(raw_network, tmp_path / "raw.safetensors")
    back = nf.read_network(path)  # the model file records the units; the default raw_units=False is ignored
    assert back.raw_units is True
    assert torch.equal(nf.to_model(back).eval(*pairs), raw)


def test_vector_formats_take_units_and_features_from_the_caller(tmp_path):
    path = nf.write_network(nf.Network(torch_weights(14), features="directions", raw_units=True), tmp_path / "v.npy")
    assert nf.read_network(path).features == "rusinkiewicz" and nf.read_network(path).raw_units is False
    back = nf.read_network(path, features="directions", raw_units=True)
    assert back.features == "directions" and back.raw_units is True


# --------------------------------------------------------------------------- bad input


def _npy(array, **kw):
    def make(p):
        np.save(p, array, **kw)
    return make


def _pt(obj):
    def make(p):
        torch.save(obj, p)
    return make


def _state(**changes):
    """A good state dict with entries replaced (None: removed)."""
    state = nf.to_torch_state(torch_weights(20))
    for k, v in changes.items():
        if v is None:
            del state[k.replace("_", ".")]
        else:
            state[k.replace("_", ".")] = v
    return _pt(state)


def _with_nan():
    v = nf.flatten(torch_weights(21))
    v[100] = np.nan
    return v


def _state_with_inf():
    state = nf.to_torch_state(torch_weights(22))
    state["fc2.bias"][3] = float("inf")
    return _pt(state)


def _h5(**kw):
    def make(p):
        write_h5(p, random_weights(23), **kw)
    return make


GOOD_VECTOR = nf.flatten(torch_weights(24))

BAD_FILES = {
    # name: (file name, maker, error class, fragments the message must hold besides the path)
    "npy-nan": ("w.npy", _npy(_with_nan()), ModelFileError, ["non-finite"]),
    "npy-674": ("w.npy", _npy(GOOD_VECTOR[:-1]), ModelFileError, ["674", "675"]),
    "npy-676": ("w.npy", _npy(np.append(GOOD_VECTOR, 0)), ModelFileError, ["676", "675"]),
    "npy-2d": ("w.npy", _npy(GOOD_VECTOR.reshape(25, 27)), ModelFileError, ["1-D", "(25, 27)"]),
    "npy-scalar": ("w.npy", _npy(np.float32(1.0)), ModelFileError, ["1-D"]),
    "npy-int": ("w.npy", _npy(np.arange(N_PUBLISHED)), ModelFileError, ["int64", "floating"]),
    "npy-bool": ("w.npy", _npy(np.ones(N_PUBLISHED, bool)), ModelFileError, ["floating"]),
    "npy-complex": ("w.npy", _npy(GOOD_VECTOR.astype(np.complex64)), ModelFileError, ["floating"]),
    "npy-truncated": ("w.npy", lambda p: (np.save(p, GOOD_VECTOR), p.write_bytes(p.read_bytes()[:-8])),
                      ModelFileError, []),
    "npy-not-npy": ("w.npy", lambda p: p.write_text("hello, not numpy"), ModelFileError, []),
    "pt-inf": ("w.pt", _state_with_inf(), ModelFileError, ["non-finite"]),
    "pt-missing-fc2.bias": ("w.pt", _state(fc2_bias=None), ModelFileError, ["fc2.bias"]),
    "pt-fc1.weight-21x7": ("w.pt", _state(fc1_weight=torch.zeros(21, 7)), ModelFileError,
                           ["fc1.weight", "(21, 7)", "(21, 6)"]),
    "pt-fc3.weight-4-outputs": ("w.pt", _state(fc3_weight=torch.zeros(4, 21), fc3_bias=torch.zeros(4)),
                                ModelFileError, ["fc3.weight", "(3, 21)"]),
    "pt-fc2.weight-chain-broken": ("w.pt", _state(fc2_weight=torch.zeros(21, 20)), ModelFileError,
                                   ["fc2.weight", "(21, 20)"]),
    "pt-bias-1x21": ("w.pt", _state(fc1_bias=torch.zeros(1, 21)), ModelFileError, ["fc1.bias", "(21,)"]),
    "pt-int-weights": ("w.pt", _state(fc1_weight=torch.zeros(21, 6, dtype=torch.int32)), ModelFileError,
                       ["fc1", "floating"]),
    "pt-no-fc-keys": ("w.pt", _pt({"layer.weight": torch.zeros(3)}), ModelFileError, ["fc1.weight", "layer.weight"]),
    "pt-list": ("w.pt", _pt([torch.zeros(3)]), ModelFileError, ["list"]),
    "pt-not-a-tensor": ("w.pt", _state(fc1_weight=[1.0, 2.0]), ModelFileError, ["fc1.weight", "list"]),
    "pt-wrong-length-vector": ("w.pt", _pt(torch.zeros(600)), ModelFileError, ["600", "675"]),
    "pt-garbage": ("w.pt", lambda p: p.write_bytes(b"\x00" * 64), ModelFileError, ["not a torch file", "accepted"]),
    "h5-missing-layer": ("w.h5", _h5(skip="b2"), ModelFileError, ["dense_2/dense_2/bias:0", "missing"]),
    "h5-mis-shaped": ("w.h5", _h5(override={"W2": np.zeros((21, 20), np.float32)}), ModelFileError,
                      ["dense_2/dense_2/kernel:0", "(21, 20)"]),
    "h5-not-hdf5": ("w.h5", lambda p: p.write_text("not hdf5"), ModelFileError, ["HDF5"]),
}


@pytest.mark.parametrize("case", list(BAD_FILES), ids=list(BAD_FILES))
def test_bad_file_is_refused_naming_the_file(tmp_path, case):
    name, make, error, fragments = BAD_FILES[case]
    path = tmp_path / name
    make(path)
    with pytest.raises(error) as info:
        nf.read_network(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    for fragment in fragments:
        assert fragment in message, (fragment, message)


def _object_npy(path, marker):
    np.save(path, np.array([Canary(marker)] * 3, dtype=object), allow_pickle=True)


def _pickled_pt(path, marker):
    torch.save({**nf.to_torch_state(torch_weights(25)), "extra": Canary(marker)}, path)


@pytest.mark.parametrize("name, write, says", [("obj.npy", _object_npy, "never unpickled"),
                                               ("evil.pt", _pickled_pt, "nothing in it ran")])
def test_pickles_are_refused_without_unpickling(tmp_path, name, write, says):
    marker = tmp_path / "unpickled"
    path = tmp_path / name
    write(path, marker)
    with pytest.raises(ModelFileError, match=says) as info:
        nf.read_network(path)
    assert str(path) in str(info.value)
    assert "weights_only" not in str(info.value) and "\n" not in str(info.value)  # none of torch's advice
    assert not marker.exists()


def test_ordered_dict_state_is_fine(tmp_path):
    """torch's own state_dict() is an OrderedDict, which weights_only=True allows."""
    path = tmp_path / "net.pt"
    torch.save(FcNet().state_dict(), path)
    assert nf.read_network(path).hidden == list(PUBLISHED)


def test_non_neural_model_file_is_refused(tmp_path):
    path = modelio.save(registry.get("representations", "lambert").create(), "lambert", tmp_path / "lam.safetensors")
    with pytest.raises(ModelFileError, match="not a neural BRDF") as info:
        nf.read_network(path)
    assert str(path) in str(info.value) and "lambert" in str(info.value)


def test_pickle_renamed_safetensors_is_refused(tmp_path):
    path = tmp_path / "w.safetensors"
    torch.save(nf.to_torch_state(torch_weights(26)), path)
    with pytest.raises(ModelFileError, match="zip archive") as info:
        nf.read_network(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("name", ["gone.npy", "gone.pt", "gone.h5", "gone.safetensors"])
def test_missing_file(tmp_path, name):
    path = tmp_path / name
    with pytest.raises(ModelFileError, match="no such network file") as info:
        nf.read_network(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize("name", ["w.json", "w.npz", "weights"])
def test_unknown_suffix_is_refused_for_reading(tmp_path, name):
    path = tmp_path / name
    np.save(tmp_path / "w.npy", GOOD_VECTOR)
    (tmp_path / "w.npy").rename(path)  # the content is fine: the suffix decides
    with pytest.raises(ModelFileError, match="cannot read") as info:
        nf.read_network(path)
    assert str(path) in str(info.value) and ".npy" in str(info.value)


@pytest.mark.parametrize("name", ["w.json", "w.h5", "w.hdf5", "w"])
def test_unknown_suffix_is_refused_for_writing(tmp_path, name):
    path = tmp_path / "out" / name
    with pytest.raises(ModelFileError, match="cannot write") as info:
        nf.write_network(nf.Network(torch_weights(27)), path)
    assert str(path) in str(info.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("suffix", [".npy", ".pt", ".safetensors"])
def test_non_finite_weights_are_not_written(tmp_path, suffix):
    weights = torch_weights(28)
    weights["W3"][0, 0] = float("nan")
    path = tmp_path / f"w{suffix}"
    with pytest.raises(ModelFileError, match="non-finite"):
        nf.write_network(nf.Network(weights), path)
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_old_file(tmp_path):
    path = nf.write_network(nf.Network(torch_weights(29)), tmp_path / "w.npy")
    before = path.read_bytes()
    bad = torch_weights(30)
    bad["b1"][0] = float("inf")
    with pytest.raises(ModelFileError):
        nf.write_network(nf.Network(bad), path)
    assert path.read_bytes() == before


# --------------------------------------------------------------------------- faults found and fixed


@pytest.mark.parametrize("case", ["empty", "npz-content", "structured", "datetime"])
def test_unreadable_npy_raises_model_file_error(tmp_path, case):
    path = tmp_path / "w.npy"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "npz-content":
        with open(path, "wb") as f:
            np.savez(f, w=GOOD_VECTOR)
    elif case == "structured":
        np.save(path, np.zeros(N_PUBLISHED, dtype=[("a", "<f4")]))
    else:
        np.save(path, np.zeros(N_PUBLISHED, dtype="M8[s]"))
    with pytest.raises(ModelFileError) as info:
        nf.read_network(path)
    assert str(path) in str(info.value)


def test_big_endian_npy_reads(tmp_path):
    """A valid float vector in the other byte order is read, not refused."""
    path = tmp_path / "w.npy"
    np.save(path, GOOD_VECTOR.astype(">f4"))
    assert np.array_equal(nf.flatten(nf.read_network(path).weights), GOOD_VECTOR.astype(np.float32))


def test_bad_h5_raises_model_file_error(tmp_path):
    path = tmp_path / "w.h5"
    write_h5(path, random_weights(31), skip="b2")
    with pytest.raises(ModelFileError, match="dense_2"):
        nf.read_network(path)


def test_non_finite_state_dict_entry_is_named_by_its_key(tmp_path):
    path = tmp_path / "w.pt"
    _state_with_inf()(path)
    with pytest.raises(ModelFileError, match=r"fc2\.bias"):
        nf.read_network(path)


def test_unfitted_neural_model_says_it_is_unfitted(tmp_path):
    path = modelio.save(NBRDF(), "nbrdf", tmp_path / "unfitted.safetensors")
    with pytest.raises(ModelFileError, match="no fitted weights"):
        nf.read_network(path)


def test_flat_tensor_in_pt_must_be_one_dimensional(tmp_path):
    path = tmp_path / "w.pt"
    torch.save(torch.from_numpy(GOOD_VECTOR[:675]).reshape(25, 27), path)
    with pytest.raises(ModelFileError, match="1-D"):
        nf.read_network(path)


def test_state_dict_with_two_networks_is_refused(tmp_path):
    state = {**{f"a.{k}": v for k, v in nf.to_torch_state(torch_weights(1)).items()},
             **{f"b.{k}": v for k, v in nf.to_torch_state(torch_weights(2)).items()}}
    with pytest.raises(ModelFileError, match="several prefixes"):
        nf.from_torch_state(state)


@pytest.mark.parametrize("hidden", [[0], [-1], [], [21, 2.5], "21"])
def test_bad_hidden_sizes_are_refused(tmp_path, hidden):
    path = tmp_path / "w.npy"
    np.save(path, GOOD_VECTOR)
    with pytest.raises(ModelFileError, match="hidden sizes"):
        nf.read_network(path, hidden=hidden)


def test_unknown_features_are_refused():
    with pytest.raises(ModelFileError, match="bogus"):
        nf.to_model(nf.Network(torch_weights(3), features="bogus"))


def test_weights_that_require_grad_are_written(tmp_path):
    weights = {k: v.clone().requires_grad_() for k, v in torch_weights(4).items()}
    nf.write_network(nf.Network(weights), tmp_path / "w.npy")
    nf.write_network(nf.Network(weights), tmp_path / "w.pt")


# --------------------------------------------------------------------------- the convert command


def test_convert_chain_is_byte_identical(tmp_path, cli):
    """h5 → npy → pt → safetensors → npy: both .npy files have the same bytes."""
    src = tmp_path / "mat.h5"
    write_h5(src, random_weights(40))
    first, pt, model, second = (tmp_path / n for n in ("a.npy", "b.pt", "c.safetensors", "d.npy"))
    for a, b in [(src, first), (first, pt), (pt, model), (model, second)]:
        out = cli("convert", a, b, cwd=tmp_path)
        assert out.returncode == 0, out.stderr
        assert str(b) in out.stdout and "6-21-21-3" in out.stdout
    assert first.read_bytes() == second.read_bytes()
    want = {k: torch.from_numpy(v) for k, v in read_nbrdf_h5(src).items()}
    assert_same_weights(nf.read_network(second).weights, want)
    assert modelio.load(model)[0] == "nbrdf"


def _convert_vector(cli, tmp_path, weights, dest_name, *flags):
    """Write `weights` as a .npy vector and convert it to `dest_name`; the command must succeed."""
    src, dest = tmp_path / "v.npy", tmp_path / dest_name
    np.save(src, nf.flatten(weights))
    out = cli("convert", src, dest, *flags, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    return dest, out


def test_convert_with_hidden_sizes(tmp_path, cli):
    weights = torch_weights(41, (16, 16))
    dest, out = _convert_vector(cli, tmp_path, weights, "v.pt", "--hidden", "16", "16")
    assert "6-16-16-3" in out.stdout
    state = torch.load(dest, weights_only=True)
    assert state["fc1.weight"].shape == (16, 6)
    assert_same_weights(nf.read_network(dest).weights, weights)


def test_convert_raw_units_and_features_reach_the_model_file(tmp_path, cli):
    weights = torch_weights(42)
    dest, out = _convert_vector(cli, tmp_path, weights, "m.safetensors", "--raw-units", "--features", "directions")
    assert "raw MERL units" in out.stdout
    name, model = modelio.load(dest)
    assert name == "naive_mlp" and model.params["raw_units"] is True
    assert torch.equal(model.output_scale, torch.tensor(merl.CHANNEL_SCALES, dtype=torch.float32))
    assert_same_weights(model.weights, weights)


TRAINING_PARAMS = ("epochs", "batch_size", "lr", "schedule", "n_samples", "output", "patience", "min_improvement",
                   "batch_materials", "init")


def test_a_converted_network_records_only_what_is_true_of_it(tmp_path, cli):
    """`convert X.h5 Y.safetensors` trains nothing: the model file holds the architecture
    and units (params), the encoding and the source (metadata), and `inspect` shows no
    training parameter or fit result."""
    src, dest = tmp_path / "mat.h5", tmp_path / "mat.safetensors"
    write_h5(src, random_weights(43))
    assert cli("convert", src, dest, cwd=tmp_path).returncode == 0
    name, model = modelio.load(dest)
    assert name == "nbrdf"
    assert model.params == {"hidden": [21, 21], "raw_units": False}
    assert model.metadata() == {"source": str(src), "features": "rusinkiewicz"}
    out = cli("inspect", dest, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "'hidden': [21, 21]" in out.stdout and "'raw_units': False" in out.stdout
    assert f"source: {src}" in out.stdout and "features: rusinkiewicz" in out.stdout
    for key in (*TRAINING_PARAMS, "fit_loss", "fitted_to"):
        assert f"'{key}'" not in out.stdout and f"{key}:" not in out.stdout, key


def test_a_converted_model_converts_again_with_its_own_record(tmp_path):
    """Saved again or converted again, a converted model still records no training."""
    first, second = tmp_path / "a.safetensors", tmp_path / "b.safetensors"
    nf.write_network(nf.Network(torch_weights(44), features="directions", raw_units=True, source="w.pt"), first)
    _, model = modelio.load(first)
    _, resaved = modelio.load(modelio.save(model, "naive_mlp", tmp_path / "again.safetensors"))
    assert resaved.params == {"hidden": [21, 21], "raw_units": True} and resaved.metadata()["source"] == "w.pt"
    nf.write_network(nf.read_network(first), second)
    name, model = modelio.load(second)
    assert name == "naive_mlp" and model.params == {"hidden": [21, 21], "raw_units": True}
    assert model.metadata() == {"source": str(first), "features": "directions"}


def test_an_h5_with_an_extra_layer_is_refused_by_convert(tmp_path, cli):
    src, dest = tmp_path / "deeper.h5", tmp_path / "out.npy"
    write_h5(src, random_weights(46))
    with h5py.File(src, "a") as f:
        f.create_dataset("dense_4/dense_4/kernel:0", data=np.zeros((3, 3), np.float32))
        f.create_dataset("dense_4/dense_4/bias:0", data=np.zeros(3, np.float32))
    with pytest.raises(ModelFileError, match=r"deeper\.h5.*'dense_4/dense_4/bias:0'.*layer 'dense_4'"):
        nf.read_network(src)
    out = cli("convert", src, dest, cwd=tmp_path)
    assert out.returncode == 2 and str(src) in out.stderr and "dense_4" in out.stderr
    assert not dest.exists()


def _wrong_length(tmp_path):
    src = tmp_path / "short.npy"
    np.save(src, GOOD_VECTOR[:-1])
    return src, tmp_path / "out.pt", src


def _h5_destination(tmp_path):
    src = tmp_path / "good.npy"
    np.save(src, GOOD_VECTOR)
    dest = tmp_path / "out.h5"
    return src, dest, dest


def _pickle_source(tmp_path):
    src = tmp_path / "evil.pt"
    torch.save({"fc1.weight": Canary(tmp_path / "unpickled")}, src)
    return src, tmp_path / "out.npy", src


@pytest.mark.parametrize("setup", [_wrong_length, _h5_destination, _pickle_source],
                         ids=["wrong-length-npy", "h5-destination", "pickle-source"])
def test_convert_errors_exit_2_naming_the_file(tmp_path, setup, cli):
    src, dest, named = setup(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    out = cli("convert", src, dest, cwd=tmp_path)
    assert out.returncode == 2, (out.stdout, out.stderr)
    assert str(named) in out.stderr and "Traceback" not in out.stderr
    assert not dest.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written, no temporary files
    assert not (tmp_path / "unpickled").exists()
