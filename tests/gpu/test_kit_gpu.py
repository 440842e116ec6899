"""The conformance kit's device check on a GPU, against plugins broken in ways only a GPU
shows: values left on the CPU, and a GPU fit that is not the CPU fit's equal."""

from __future__ import annotations

import pytest

from brdfbench.plugins import registry
from brdfbench.plugins.specs import RepresentationSpec
from brdfbench.testing import check_representation
from brdfbench_representations.lambert import Lambert


class LeavesValuesOnTheCpu(Lambert):
    """Declares "cuda" but returns its values on the CPU whatever the inputs."""

    tags = Lambert.tags

    def _eval(self, wi, wo):
        return super()._eval(wi, wo).cpu()

    def eval(self, wi, wo):
        return super().eval(wi, wo).cpu()


class FitsWorseOnTheGpu(Lambert):
    """Its GPU fit halves the albedo: the moved CPU model agrees, the GPU fit does not."""

    tags = Lambert.tags

    def fit(self, target, *, seed=0):
        super().fit(target, seed=seed)
        if self.device.type == "cuda":
            self.albedo = self.albedo * 0.5
        return self


@pytest.mark.parametrize("cls", [LeavesValuesOnTheCpu, FitsWorseOnTheGpu])
def test_the_kit_catches_what_only_a_gpu_shows(cls):
    spec = RepresentationSpec(name=f"gpu_broken_{cls.__name__.lower()}", description="test",
                              target=f"{__name__}:{cls.__name__}", tags=Lambert.tags)
    registry.register("representations", spec)
    try:
        report = check_representation(spec, n_pairs=20_000)
    finally:
        registry.unregister("representations", spec.name)
    assert report.outcomes["device_agreement"] == "failed", report.summary()
    assert report.outcomes["devices_declared"] == "passed"


@pytest.mark.parametrize("name", ["lambert", "ggx", "cook_torrance", "blinn_phong"])
def test_analytic_models_pass_the_device_check(name):
    report = check_representation(name, n_pairs=50_000)
    assert report.outcomes["device_agreement"] == "passed", report.summary()
