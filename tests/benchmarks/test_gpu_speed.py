"""Speed on a GPU, each figure beside its physical limit (skipped without a CUDA device).

    python -m pytest tests/benchmarks/test_gpu_speed.py --benchmark-enable -p no:xdist

`.ci/gpu` runs this file on a GPU host and prints one table of the figures with their
targets and limits (tests/tools/gpu_table.py). Each benchmark stores in its extra_info the
figure it measures (`value`, `unit`), the issue's `target` and the device's `limit` (the
arithmetic at the card's fp32 rate, or its memory traffic at its bandwidth: what no
implementation can beat). The card's rates are measured here, at the start of the run,
not taken from a datasheet.
"""

from __future__ import annotations

import statistics
import time

import pytest
import torch

from brdfbench import device as devices
from brdfbench.data.nbrdf_release import find_release_dir, nbrdf_release_dataset
from brdfbench.harness.cost import evaluation_throughput
from brdfbench.nbrdf import network as nw
from brdfbench_representations.nbrdf import NBRDF
from brdfbench_representations.nbrdf_fit import Recipe, draw_samples, fit_batched

pytestmark = pytest.mark.skipif(not devices.cuda_count(), reason="no CUDA device: GPU benchmarks run where torch sees one")

#: FLOP per material of the default NBRDF recipe: 15 epochs over ~5·10⁵ samples, forward
#: and backward (3 × the forward's multiply-adds) through 6-21-21-3.
NBRDF_FIT_FLOP = 15 * 496_000 * 3 * 2 * (6 * 21 + 21 * 21 + 21 * 3)


@pytest.fixture(scope="module")
def gpu():
    return torch.device("cuda", 0)


@pytest.fixture(scope="module")
def rates(gpu):
    """(fp32 FLOP/s, bytes/s) this card reaches: a large fp32 matrix product (TF32 off, as
    brdfbench computes) and a device-to-device copy, each the best of five."""
    torch.backends.cuda.matmul.allow_tf32 = False
    a = torch.randn(8192, 8192, device=gpu)
    b = torch.randn(8192, 8192, device=gpu)
    x = torch.empty(2**28, device=gpu)
    y = torch.empty_like(x)
    flops, bw = [], []
    for _ in range(5):
        devices.synchronize(gpu)
        t0 = time.perf_counter()
        a @ b
        devices.synchronize(gpu)
        flops.append(2 * 8192**3 / (time.perf_counter() - t0))
        t0 = time.perf_counter()
        y.copy_(x)
        devices.synchronize(gpu)
        bw.append(2 * x.numel() * 4 / (time.perf_counter() - t0))
    del a, b, x, y
    torch.cuda.empty_cache()
    return max(flops), max(bw)


def _store(benchmark, **info):
    benchmark.extra_info.update(device=devices.describe(torch.device("cuda", 0)), **info)


@pytest.fixture(scope="module")
def merl_tables():
    root = find_release_dir()
    if root is None:
        pytest.skip("the published NBRDF release is absent (../shared/data/neural-brdf or $BRDFBENCH_NBRDF_DIR)")
    ds = nbrdf_release_dataset(str(root), subset="merl")
    return [ds.load(name) for name in ds.materials]


def test_nbrdf_fit_per_material_over_the_100_merl_tables(benchmark, enabled, gpu, rates, merl_tables):
    """The default recipe, all 100 published MERL tables in one batch on the GPU."""
    recipe = Recipe()
    samples = draw_samples(recipe.n_samples, "rusinkiewicz", seed=0)
    model = NBRDF()
    inits = [model._random_init(m, 0) for m in merl_tables]
    tables = [m.table for m in merl_tables]
    fit_batched(tables[:2], inits[:2], recipe=Recipe(epochs=1, n_samples=20_000), device=gpu)  # warm-up: CUDA, cuBLAS

    def fit():
        out = fit_batched(tables, inits, recipe=recipe, samples=samples, device=gpu)
        devices.synchronize(gpu)
        return out

    outcomes = benchmark.pedantic(fit, rounds=1, iterations=1)
    per_material = benchmark.stats.stats.mean / len(tables)
    _store(benchmark, value=per_material, unit="s per material", target="<= 0.02", higher_is_better=False,
           limit=NBRDF_FIT_FLOP / rates[0], limit_what="its FLOP at the card's fp32 rate",
           materials=len(tables), mean_loss=statistics.mean(o.loss for o in outcomes),
           epochs=statistics.mean(o.epochs for o in outcomes))


@pytest.mark.parametrize("name", ["nbrdf", "naive_mlp"])
def test_eval_throughput_in_the_accuracy_harness(benchmark, enabled, gpu, rates, name, synthetic_cache):
    """`evals_per_s` as the accuracy harness measures it on a GPU (encoding included)."""
    from brdfbench.plugins import registry
    from brdfbench.data.synthetic import synthetic_dataset
    from brdfbench.harness.accuracy_harness import AccuracyConfig

    target = synthetic_dataset("small", seed=0, cache_dir=str(synthetic_cache)).load("synth-plastic-green-00")
    model = registry.get("representations", name).create(epochs=1, n_samples=20_000).to(gpu).fit(target)
    batch = AccuracyConfig().gpu_throughput_batch
    measured = benchmark.pedantic(lambda: evaluation_throughput(model, batch=batch), rounds=3, iterations=1)
    flop = model.flops_per_eval
    _store(benchmark, value=measured.value, unit="evals/s", target=">= 1e9", higher_is_better=True,
           limit=min(rates[0] / flop, rates[1] / 36), limit_what=f"{flop} FLOP/eval at the fp32 rate, or 36 B/eval "
           "(two fp32 direction pairs in, RGB out) at the copy bandwidth", batch=batch)


def test_nbrdf_network_alone(benchmark, enabled, gpu, rates):
    """The 6-21-21-3 network on encoded inputs: the harness figure's ceiling."""
    w = {k: v.to(gpu) for k, v in nw.glorot_init((21, 21), torch.Generator().manual_seed(0)).items()}
    x = torch.rand(2**24, 6, device=gpu)

    def run():
        nw.forward(w, x)
        devices.synchronize(gpu)

    benchmark.pedantic(run, rounds=5, iterations=1, warmup_rounds=1)
    _store(benchmark, value=x.shape[0] / benchmark.stats.stats.median, unit="evals/s", target="(reference)",
           higher_is_better=True, limit=rates[0] / nw.mlp_flops((21, 21)), limit_what="the network's FLOP at the fp32 rate")
