"""The accuracy harness's per-process geometry and the reused-direction memo
(`brdfbench.reused`): the cached path must score exactly as the straightforward one, for the
first material and later ones, for table lookups, analytic lobes and neural encodings, and
must never serve data for other directions or settings."""

import gc

import pytest
import torch

from brdfbench import merl, reused
from brdfbench.plugins import registry
from brdfbench.data.synthetic import generate_material
from brdfbench.harness import directions
from brdfbench.harness.accuracy import AccuracyGeometry, accuracy_geometry, evaluate_accuracy
from brdfbench.protocols.representation import Material

METRICS = ("l1", "l1_log", "l1_log_cos", "hdr_rmse", "hdr_mae")
N_RANDOM = 2**14


def uncached_accuracy(model, target, specs, *, n_random, seed=0, dtype=torch.float32, chunk=2**18):
    """The harness without any cache: fresh subsets, the table's own lookup for the reference."""
    metrics = [(spec, spec.load()()) for spec in specs]
    domains = {}
    for _, m in metrics:
        domains.setdefault(m.domain, []).append(m)
    wi, wo = merl.grid_directions(torch.float64)
    valid = torch.from_numpy(target.table.valid.reshape(-1)) & merl.grid_above_horizon()
    cases = [("merl_grid", wi[valid], wo[valid], torch.from_numpy(target.table.values.reshape(3, -1)).T[valid])]
    wi, wo = directions.random_pairs(n_random, seed, torch.float64)
    ref = target.table.lookup(wi, wo, "nearest")
    ok = (ref >= 0).all(dim=1)
    cases.append(("random_pairs", wi[ok], wo[ok], ref[ok]))
    for domain, wi, wo, ref in cases:
        if domain not in domains:
            continue
        for start in range(0, wi.shape[0], chunk):
            s = slice(start, start + chunk)
            pred = model.eval(wi[s].to(dtype), wo[s].to(dtype))
            for m in domains[domain]:
                m.update(pred, ref[s], wi[s, 2])
    return [m.compute() for _, m in metrics]


@pytest.fixture(scope="module")
def specs():
    return [registry.get("metrics", name) for name in METRICS]


@pytest.fixture(scope="module")
def materials():
    return [Material(name, table, category) for name, category, table in (generate_material(i, seed=0) for i in (1, 2))]


def _fit(name, target, **params):
    return registry.get("representations", name).create(**params).fit(target)


def _cached(model, target, specs, **kw):
    return [m.value for m in evaluate_accuracy(model, target, specs, n_random=kw.pop("n_random", N_RANDOM), **kw)]


SMALL_NET = dict(epochs=1, n_samples=20_000, batch_materials=1)


@pytest.mark.parametrize("name, params", [("merl", {}), ("lambert", {}), ("ggx", {}), ("cook_torrance", {}),
                                          ("blinn_phong", {}), ("nbrdf", SMALL_NET), ("naive_mlp", SMALL_NET)])
def test_cached_scores_equal_uncached_for_first_and_later_materials(name, params, specs, materials):
    accuracy_geometry.cache_clear()
    for target in materials:  # the first builds the geometry, the second reuses it
        model = _fit(name, target, **params)
        assert _cached(model, target, specs) == uncached_accuracy(model, target, specs, n_random=N_RANDOM)


def test_derived_data_is_computed_once_per_job_and_dropped_by_the_next(specs, materials, monkeypatch):
    from brdfbench.harness import accuracy
    from brdfbench_representations import analytic

    accuracy_geometry.cache_clear()
    calls = []
    real = analytic.geometry
    monkeypatch.setattr(analytic, "geometry", lambda wi, wo: calls.append(wi.shape[0]) or real(wi, wo))
    for target in materials:
        _cached(_fit("ggx", target), target, specs)
    n_pairs = merl.N_CELLS + N_RANDOM
    assert sum(calls) == n_pairs  # every pair once, for both materials
    accuracy.forget_derived()
    _cached(_fit("ggx", materials[0]), materials[0], specs)
    assert sum(calls) == 2 * n_pairs


@pytest.mark.parametrize("params", [{"mode": "trilinear"}, {"downsample": 8}])
def test_cached_table_lookups_equal_uncached_after_another_material(params, specs, materials):
    first, second = materials
    _cached(_fit("merl", first, **params), first, specs)
    model = _fit("merl", second, **params)
    assert _cached(model, second, specs) == uncached_accuracy(model, second, specs, n_random=N_RANDOM)


def test_fp64_cached_scores_equal_uncached(specs, materials):
    first, second = materials
    _cached(_fit("merl", first), first, specs, dtype=torch.float64)
    model = _fit("merl", second)
    got = _cached(model, second, specs, dtype=torch.float64)
    assert got == uncached_accuracy(model, second, specs, n_random=N_RANDOM, dtype=torch.float64)


@pytest.fixture(scope="module")
def random_specs(specs):
    return [spec for spec in specs if spec.name.startswith("hdr")]  # random pairs only: no grid


def test_changed_settings_get_their_own_geometry(random_specs, materials):
    target = materials[1]
    model = _fit("merl", target)
    _cached(model, target, random_specs, n_random=2**12)
    for n_random, seed in ((2**13, 0), (2**12, 1)):
        got = _cached(model, target, random_specs, n_random=n_random, seed=seed)
        assert got == uncached_accuracy(model, target, random_specs, n_random=n_random, seed=seed)
        geometry = accuracy_geometry(n_random, seed, torch.float32, 2**18)
        assert geometry.key == (n_random, seed, torch.float32, 2**18)
        assert geometry.random.wi.shape[0] == n_random
    assert accuracy_geometry(2**12, 0, torch.float32, 2**18) is not accuracy_geometry(2**12, 1, torch.float32, 2**18)


def test_explicit_geometry_must_match_the_settings(random_specs, materials):
    target = materials[0]
    model = _fit("lambert", target)
    geometry = AccuracyGeometry(n_random=2**10, seed=3)
    got = evaluate_accuracy(model, target, random_specs, n_random=2**10, seed=3, geometry=geometry)
    assert [m.value for m in got] == uncached_accuracy(model, target, random_specs, n_random=2**10, seed=3)
    with pytest.raises(ValueError, match="geometry made for"):
        evaluate_accuracy(model, target, random_specs, n_random=2**11, seed=3, geometry=geometry)


# --------------------------------------------------------------------------- the memo


def _pairs(n=1000, seed=0):
    return directions.random_pairs.__wrapped__(n, seed, torch.float32)


def _recording_provider(wi, wo):
    """A provider that records its calls; it keeps copies, so it does not keep wi, wo alive."""
    wi, wo = wi.clone(), wo.clone()
    calls = []

    def provide(fn, args):
        calls.append(args[0])
        return fn(wi, wo, *args)

    return provide, calls


def test_registered_directions_take_their_data_from_the_provider():
    wi, wo = _pairs()
    provide, calls = _recording_provider(wi, wo)
    reused.register(wi, wo, provide)
    for got, want in zip(merl.cell_indices(wi, wo), merl.direction_data(wi, wo, "cells")):
        assert torch.equal(got, want)
    table = generate_material(1, seed=0)[2]
    for mode in ("nearest", "trilinear"):
        assert torch.equal(table.lookup(wi, wo, mode), table.lookup(wi.clone(), wo.clone(), mode))
    assert calls == ["cells", "flat", "continuous"]


def test_equal_but_distinct_tensors_and_changed_tensors_are_recomputed():
    wi, wo = _pairs()
    provide, calls = _recording_provider(wi, wo)
    reused.register(wi, wo, provide)
    merl.cell_indices(wi.clone(), wo.clone())  # same values, other objects
    merl.cell_indices(wo, wi)  # the pair swapped
    assert calls == []
    wi[0] = torch.tensor([0.0, 0.0, 1.0])  # changed in place: the entry is dropped
    ih, id_, ip = merl.cell_indices(wi, wo)
    assert calls == [] and int(ih[0]) == merl.direction_data(wi[:1], wo[:1], "cells")[0].item()
    merl.cell_indices(wi, wo)
    assert calls == []


def test_freed_tensors_leave_the_memo_and_their_ids_never_match():
    wi, wo = _pairs()
    provide, calls = _recording_provider(wi, wo)
    reused.register(wi, wo, provide)
    key = id(wi)
    del wi, provide
    gc.collect()
    assert key not in reused._ENTRIES
    for _ in range(50):  # new tensors, some perhaps at the freed id
        a, b = _pairs()
        merl.cell_indices(a, b)
    assert calls == []


def test_the_memo_is_bounded():
    kept = [_pairs(10, seed) for seed in range(reused.MAX_ENTRIES + 10)]
    for wi, wo in kept:
        reused.register(wi, wo, lambda fn, args: None)
    assert len(reused._ENTRIES) <= reused.MAX_ENTRIES


@pytest.mark.parametrize("name", ["nbrdf", "ggx", "lambert"])
def test_the_device_scoring_path_gives_the_host_path_scores(name, specs, materials, monkeypatch):
    """A model on a GPU is scored at pairs kept on the device and gathered there by index
    (`_score_on`); run on the CPU, that path must give the host path's scores exactly."""
    from brdfbench.harness import accuracy

    target = materials[1]
    model = _fit(name, target, **({"epochs": 1, "n_samples": 20_000} if name == "nbrdf" else {}))
    host = _cached(model, target, specs, n_random=50_000)
    monkeypatch.setattr(accuracy, "_score", lambda model, pairs, mask, ref, metrics: accuracy._score_on(
        torch.device("cpu"), model, pairs, mask.nonzero().squeeze(1), accuracy._rows(ref, mask.nonzero().squeeze(1)),
        metrics))
    device_path = _cached(model, target, specs, n_random=50_000)
    assert device_path == host
