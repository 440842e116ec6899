"""The `device` run-control key on a machine without a GPU: what it accepts and refuses,
that it never enters a configuration's hash, and what every row records about it; a cell
whose plugin runs out of device memory is a failure row naming the device and the size."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from brdfbench import device as devices
from brdfbench.plugins import registry
from brdfbench.errors import ConfigError
from brdfbench.pipeline.plan import check, config_hash, hashed_config
from brdfbench.pipeline.config import RunConfig, harness_config
from brdfbench.pipeline.sweep import run_job as run
from brdfbench.plugins.specs import RepresentationSpec
from brdfbench.store.sqlite import ResultsStore
from brdfbench_representations.lambert import Lambert

QUICK = harness_config(n_random=1024, throughput_batch=256, timeout_s=120)
no_gpu = pytest.mark.skipif(devices.cuda_count() > 0, reason="checks the refusals of a machine without a GPU")


def _cfg(tmp_path, synthetic_cache, name="lambert", **kw):
    return RunConfig(representation=name, representation_params={}, label=name, dataset="synthetic",
                     dataset_params={"size": "small", "cache_dir": str(synthetic_cache)}, harness=QUICK,
                     results_dir=tmp_path, limit=2, progress="none", **kw)


@pytest.mark.parametrize("spec", ["auto", "cpu", "CPU", " cpu "])
def test_cpu_and_auto_resolve_to_the_cpu_here(spec):
    if devices.cuda_count():
        pytest.skip("a GPU is here: auto resolves to it")
    assert devices.resolve(spec) == torch.device("cpu")


@no_gpu
@pytest.mark.parametrize("spec, words", [
    ("cuda", "torch sees no CUDA device|torch was built without CUDA"),
    ("cuda:0", "torch sees no CUDA device|torch was built without CUDA"),
    ("cuda:7", "torch sees no CUDA device|torch was built without CUDA"),
    ("tpu", "expected one of auto, cpu, cuda, cuda:N"),
    ("", "expected one of"),
    (3, "expected one of"),
    ("cuda:-1", "expected one of"),
])
def test_a_device_this_machine_lacks_is_refused_naming_the_key(tmp_path, synthetic_cache, spec, words):
    with pytest.raises(ConfigError, match=rf"^device={spec!r}: ({words}).*devices here: cpu") as err:
        _cfg(tmp_path, synthetic_cache, device=spec)
    assert "\n" not in str(err.value)


def test_the_device_never_enters_the_configuration_hash(tmp_path, synthetic_cache):
    a = _cfg(tmp_path, synthetic_cache, device="cpu")
    b = _cfg(tmp_path, synthetic_cache, device="auto")
    checked = check(a)
    assert config_hash(hashed_config(a, checked.harness_cls)) == config_hash(hashed_config(b, checked.harness_cls))
    assert "device" not in repr(hashed_config(a, checked.harness_cls))


def test_rows_record_the_device_they_were_computed_on(tmp_path, synthetic_cache):
    counts = run(_cfg(tmp_path, synthetic_cache, device="cpu"))
    assert counts["done"] == 2
    store = ResultsStore(tmp_path / "brdfbench.sqlite")
    df = store.frame()
    assert set(df.device) == {"cpu"} and set(df.device_detail) == {"cpu"}
    assert [e.device for e in store.environments()] == ["cpu"]


def test_describe_names_the_cpu_plainly():
    assert devices.describe(torch.device("cpu")) == "cpu" and devices.name(torch.device("cpu")) == "cpu"


def test_an_undeclared_device_type_is_refused_by_to():
    class CpuOnly(Lambert):
        devices = frozenset({"cpu"})

    with pytest.raises(ConfigError, match="runs on cpu, not cuda:0"):
        CpuOnly().to("cuda:0")
    model = CpuOnly()
    assert model.to("cpu") is model and model.device == torch.device("cpu")


def test_a_plugin_on_the_cpu_keeps_a_job_device_it_does_not_declare():
    class CpuOnly(Lambert):
        devices = frozenset({"cpu"})

    assert devices.for_plugin(torch.device("cuda", 0), CpuOnly) == torch.device("cpu")
    assert devices.for_plugin(torch.device("cuda", 0), Lambert) == torch.device("cuda", 0)


class OutOfDeviceMemory(Lambert):
    """Raises what torch raises when a GPU allocation fails (its message as torch writes it)."""

    def fit(self, target, *, seed=0):
        if target.category == "metal":
            raise torch.cuda.OutOfMemoryError(
                "CUDA out of memory. Tried to allocate 37.25 GiB. GPU 0 has a total capacity of 139.81 GiB of which "
                "2.10 GiB is free. Of the allocated memory 120.00 GiB is allocated by PyTorch")
        return super().fit(target, seed=seed)


def test_running_out_of_device_memory_is_a_failure_row_and_the_job_goes_on(tmp_path, synthetic_cache):
    registry.register("representations", RepresentationSpec(
        name="oom_plugin", description="test", target=f"{__name__}:OutOfDeviceMemory", tags=Lambert.tags))
    try:
        counts = run(replace(_cfg(tmp_path, synthetic_cache, name="oom_plugin", device="cpu"), limit=3))
    finally:
        registry.unregister("representations", "oom_plugin")
    assert counts == {"done": 2, "skipped": 0, "failed": 1}
    df = ResultsStore(tmp_path / "brdfbench.sqlite").frame()
    message = df[df.status == "failed"].message.iloc[0]
    assert message == "out of memory on cpu: asked for 37.25 GiB of 139.81 GiB"


def test_memory_message_names_the_device_and_the_size():
    exc = torch.cuda.OutOfMemoryError("CUDA out of memory. Tried to allocate 2.00 MiB. GPU 0 has a total capacity of "
                                      "79.10 GiB of which 1.00 MiB is free.")
    assert devices.out_of_memory(exc) and not devices.out_of_memory(ValueError("no"))
    assert devices.memory_message(exc, torch.device("cpu")) == "out of memory on cpu: asked for 2.00 MiB of 79.10 GiB"
