"""The tripleplane model: texture reads (pole, circular φ, exact at nodes, linear between),
reciprocity and isotropy by construction, the blur preconditioner, FLOPs by the project's
counter, batch-mate independence of the fit, and bad input naming the key or tensor."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from brdfbench import flops, modelio
from brdfbench.errors import ConfigError, ModelFileError
from brdfbench.protocols.representation import Material
from brdfbench_representations import triplane_fit as tf
from brdfbench_representations import triplane_model as tm
from brdfbench_representations.triplane import Tripleplane, TriplaneGated

SMALL = {"h_res": 8, "d_res": [6, 10], "channels": [3, 4], "hidden": [5]}


def _random_model(seed: int = 0, **params) -> Tripleplane:
    model = Tripleplane(**{**SMALL, **params})
    g = torch.Generator().manual_seed(seed)
    state = {k: torch.randn(s, generator=g) * 0.5 for k, s in model.shape.tensor_shapes().items()}
    return Tripleplane.from_state(model.params, state, {})


def _pairs(n: int, seed: int, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g, dtype=dtype)
    v[..., 2] = v[..., 2].abs() + 0.05
    v = v / v.norm(dim=-1, keepdim=True)
    return v[0], v[1]


def test_the_pole_is_one_vector_for_every_phi():
    pole, rings = torch.randn(1, 4), torch.randn(1, 5, 7, 4)
    phi = torch.linspace(0, 3.0, 9)
    out = tm.read_polar(pole, rings, torch.zeros(9), phi)
    assert torch.allclose(out, pole[:, None, :].expand(1, 9, 4))
    near = tm.read_polar(pole, rings, torch.full((9,), 1e-7), phi)
    assert torch.allclose(near, out, atol=1e-5)  # continuous at the pole


def test_phi_is_circular_with_period_pi_and_nodes_are_exact():
    pole, rings = torch.randn(2, 3, dtype=torch.float64), torch.randn(2, 4, 6, 3, dtype=torch.float64)
    r = torch.tensor([1 / 4, 2 / 4, 1.0], dtype=torch.float64)  # rings 1, 2, 4 of nodes at i/4
    for j in range(6):
        phi = torch.full((3,), j * math.pi / 6, dtype=torch.float64)
        got = tm.read_polar(pole, rings, r, phi)
        assert torch.allclose(got, rings[:, [0, 1, 3], j], atol=1e-12)
        assert torch.allclose(tm.read_polar(pole, rings, r, phi + math.pi), got, atol=1e-12)
    # just below π blends the last φ node into node 0 (circular padding)
    phi = torch.full((3,), math.pi - 1e-12, dtype=torch.float64)
    assert torch.allclose(tm.read_polar(pole, rings, r, phi), rings[:, [0, 1, 3], 0], atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(r=st.floats(0, 1), phi=st.floats(0, 2 * math.pi, exclude_max=True))
def test_reads_are_bilinear_between_the_four_nodes_around(r, phi):
    torch.manual_seed(0)
    pole, rings = torch.randn(1, 2, dtype=torch.float64), torch.randn(1, 3, 5, 2, dtype=torch.float64)
    grid = torch.cat((pole[:, None, None].expand(1, 1, 5, 2), rings), dim=1)[0]  # (4, 5, 2)
    u, v = r * 3, (phi % math.pi) / math.pi * 5
    i, j = min(int(u), 2), int(v) % 5
    t, s = u - i, v - math.floor(v)
    want = ((1 - t) * ((1 - s) * grid[i, j] + s * grid[i, (j + 1) % 5])
            + t * ((1 - s) * grid[i + 1, j] + s * grid[i + 1, (j + 1) % 5]))
    got = tm.read_polar(pole, rings, torch.tensor([r], dtype=torch.float64), torch.tensor([phi], dtype=torch.float64))
    assert torch.allclose(got[0, 0], want, atol=1e-9)


def _reciprocal_and_isotropic(model, seed: int, angle: float) -> torch.Tensor:
    """Values at random pairs, checked against swapped and rotated pairs."""
    wi, wo = _pairs(4000, seed)
    a = model.eval(wi, wo)
    assert torch.allclose(a, model.eval(wo, wi), rtol=1e-9, atol=0)
    c, s = math.cos(angle), math.sin(angle)
    rot = torch.tensor([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=torch.float64)
    assert torch.allclose(a, model.eval(wi @ rot.T, wo @ rot.T), rtol=1e-8, atol=0)
    return a


def test_a_model_is_reciprocal_and_isotropic_by_construction():
    a = _reciprocal_and_isotropic(_random_model(), seed=1, angle=1.1)
    assert torch.isfinite(a).all() and (a > 0).all()


def test_blur_is_an_invertible_preconditioner_that_keeps_constants():
    w = tf.blur_weights((8, 12), 5.0)
    assert w[0, 0] == 1 and (w > 0).all() and (w <= 1).all()
    const = torch.full((2, 8, 12, 3), 0.7)
    assert torch.allclose(tf.blur(const, w, (1, 2)), const, atol=1e-6)
    x = torch.randn(2, 8, 12, 3)
    y = tf.blur(x, w, (1, 2))
    back = torch.fft.ifftn(torch.fft.fftn(y, dim=(1, 2)) / w[None, :, :, None], dim=(1, 2)).real
    assert torch.allclose(back, x, atol=1e-4) and y.std() < x.std()


def test_flops_follow_the_project_counter_and_the_default_is_equal_flop():
    model = Tripleplane()
    c_h, c_d = model.shape.channels
    want = (tm.COORD_FLOPS + flops.linear_read(c_h) + flops.bilinear_read(c_d)
            + flops.mlp([c_h + c_d, 16, 3], "silu") + 6)
    assert model.flops_per_eval == want
    assert 800 <= model.flops_per_eval <= 900  # Timonen et al., Table 3's band
    assert model.nbytes == 4 * (64 * 8 + 8 * (1 + 31 * 32) + (16 * 16 + 16) + (16 * 3 + 3))


@pytest.mark.parametrize("cls", ["Tripleplane", "TriplaneGated"])
def test_fit_does_not_depend_on_batch_mates_and_learns(sharp_materials, cls):
    cls = {"Tripleplane": Tripleplane, "TriplaneGated": TriplaneGated}[cls]
    params = {**SMALL, "epochs": 3, "n_samples": 40_000, "batch_size": 2048}
    alone = cls(**params).fit(sharp_materials[0], seed=3)
    together = cls(**params).fit_many(sharp_materials, seed=3)[0]
    for k, t in alone.tensors.items():
        assert torch.allclose(t, together.tensors[k], rtol=1e-4, atol=1e-5), k
    curve = alone.fit_info["training_curve"]
    assert len(curve) == 3 and curve[-1] < curve[0]
    if cls is TriplaneGated:
        assert not torch.equal(alone.tensors["warp_h_alpha"], torch.tensor([0.9, 1.1]))  # the warps trained


def test_save_and_load_round_trip(tmp_path):
    model = _random_model(seed=4)
    path = tmp_path / "tp.safetensors"
    modelio.save(model, "tripleplane", path)
    name, loaded = modelio.load(path)
    assert name == "tripleplane" and loaded.params == model.params
    wi, wo = _pairs(100, 5, torch.float32)
    assert torch.equal(loaded.eval(wi, wo), model.eval(wi, wo))


@pytest.mark.parametrize("key,value", [("h_res", 0), ("h_res", -3), ("d_res", [32]), ("d_res", [0, 8]),
                                       ("channels", [8, -1]), ("hidden", []), ("h_res", 2.5), ("d_res", "big"),
                                       ("d_res", [100_000, 100_000])])
def test_bad_sizes_name_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        Tripleplane(**{key: value})


@pytest.mark.parametrize("key,value", [("loss", "l2"), ("ema", 2.0), ("lr", 0), ("precondition", -1.0), ("epochs", 0)])
def test_bad_recipe_names_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        Tripleplane(**{key: value})


def test_loaded_tensors_are_checked():
    model = _random_model()
    state = model.state_dict()
    bad = dict(state, D=state["D"].clone())
    bad["D"][0, 0, 0] = float("nan")
    with pytest.raises(ModelFileError, match="'D'"):
        Tripleplane.from_state(model.params, bad, {})
    with pytest.raises(ModelFileError, match="'H'.*shape"):
        Tripleplane.from_state(model.params, dict(state, H=torch.zeros(3, 3)), {})
    with pytest.raises(ModelFileError, match="unexpected"):
        Tripleplane.from_state(model.params, dict(state, extra=torch.zeros(1)), {})


@pytest.fixture(scope="module")
def sharp_materials():
    from brdfbench.data.synthetic import generate_material

    out = []
    for i in (1, 0):  # a chrome metal and a plastic
        name, category, table = generate_material(i, seed=0)
        out.append(Material(name=name, table=table, category=category))
    return out


# --------------------------------------------------------------------------- triplane-gated


def _random_gated(seed: int = 0, **params) -> TriplaneGated:
    model = TriplaneGated(**{**SMALL, "latent": 3, "warps": 2, **params})
    g = torch.Generator().manual_seed(seed)
    state = {k: torch.randn(s, generator=g) * 0.5 for k, s in model.shape.tensor_shapes().items()}
    for tex in ("h", "d"):
        state[f"warp_{tex}_alpha"] = torch.tensor([0.7, 1.6])
        state[f"warp_{tex}_weight"] = torch.tensor([0.3, 0.7])
    return TriplaneGated.from_state(model.params, state, {})


def test_warps_are_a_partition_of_unity_of_powers_started_near_the_identity():
    r = torch.linspace(0, 1, 101, dtype=torch.float64)
    alpha, weight = torch.tensor([[0.5, 2.0]], dtype=torch.float64), torch.tensor([[0.25, 0.75]], dtype=torch.float64)
    want = 0.25 * r.sqrt() + 0.75 * r**2
    assert torch.allclose(tm.warp(r, alpha, weight)[0], want, atol=1e-12)
    shape = TriplaneGated(**SMALL).shape
    raw = tf.initial_state(shape, torch.zeros(3), torch.Generator().manual_seed(0), 0.1)
    stack = tf._Stack(shape, [raw], tf.Recipe())
    eff = stack.effective({k: v.detach() for k, v in stack.params.items()})
    assert torch.allclose(eff["warp_h_weight"].sum(-1), torch.ones(1))
    assert (eff["warp_d_alpha"] >= tm.WARP_ALPHA_MIN).all()
    warped = tm.warp(r.float(), eff["warp_h_alpha"], eff["warp_h_weight"])[0]
    assert (warped - r.float()).abs().max() < 0.05  # near the identity at the start
    grad_r = torch.tensor([0.0, 1e-30, 0.5], requires_grad=True)
    a = torch.tensor([[0.6, 1.2]], requires_grad=True)
    tm.warp(grad_r, a, torch.tensor([[0.5, 0.5]])).sum().backward()
    assert torch.isfinite(a.grad).all() and torch.isfinite(grad_r.grad).all()  # finite at r = 0


def test_the_gated_model_is_reciprocal_isotropic_and_gates_by_its_latent():
    model = _random_gated()
    a = _reciprocal_and_isotropic(model, seed=7, angle=0.4)
    wi, wo = _pairs(4000, 7)
    other = dict(model.state_dict(), z_s=model.state_dict()["z_s"] * -2.0)
    assert not torch.allclose(TriplaneGated.from_state(model.params, other, {}).eval(wi, wo), a)


def test_gated_flops_count_the_warps_and_skip_a_one_dimensional_gating():
    one = TriplaneGated()
    assert one.flops_per_eval == Tripleplane().flops_per_eval + 2 * (1 + 5 * 2)
    assert 800 <= one.flops_per_eval <= 900
    three = TriplaneGated(latent=3)
    assert three.flops_per_eval > one.flops_per_eval and three.nbytes > 2.9 * Tripleplane().texture_nbytes


def test_a_loaded_warp_out_of_bounds_is_refused_naming_the_tensor():
    model = _random_gated()
    state = model.state_dict()
    with pytest.raises(ModelFileError, match="'warp_h_alpha'"):
        TriplaneGated.from_state(model.params, dict(state, warp_h_alpha=torch.tensor([0.3, 1.0])), {})
    with pytest.raises(ModelFileError, match="'warp_d_weight'"):
        TriplaneGated.from_state(model.params, dict(state, warp_d_weight=torch.tensor([0.9, 0.9])), {})
    with pytest.raises(ConfigError, match="warps"):
        TriplaneGated(warps=0)
