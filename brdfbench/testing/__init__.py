"""The public conformance kit, in the style of scikit-learn's `check_estimator`.

One line certifies a representation plugin, registered or not:

    from brdfbench.testing import check_representation
    check_representation("my_brdf").raise_on_failure()

In pytest, one test per check:

    from brdfbench.testing import representation_checks
    @pytest.mark.parametrize("check", representation_checks("my_brdf"), ids=str)
    def test_conformance(check): check()

Capability tags on the spec select the checks (`fittable`, `reciprocal`, `isotropic`);
a spec's `xfail_checks` maps a check name to the reason it is expected to fail, and its
`kit_params` are the constructor arguments of the default, quick run (a short fit, say);
`full=True` (`brdfbench check NAME --full`) checks the representation's defaults.

Every other plugin kind has a kit of its own, each returning a `ConformanceReport`:
`check_generator("pca_brdf")` / `generator_checks` (`brdfbench.testing.generators`),
`check_sampler("ggx")` / `sampler_checks` (`brdfbench.testing.samplers`, with Mitsuba's
χ² test), `check_metric("my_metric")` / `metric_checks` (`brdfbench.testing.metrics`, by the
metric's domain), `check_harness("my_harness")` / `harness_checks`
(`brdfbench.testing.harnesses`: typed config, hash, validation, measuring) and
`check_dataset("my_dataset", params={...})` / `dataset_checks`
(`brdfbench.testing.datasets`). `brdfbench check NAME --kind KIND` runs any of them with
each check isolated in a worker process (`brdfbench.testing.isolated`).
"""

from __future__ import annotations

from .adversarial import FAMILIES, adversarial_pairs
from .datasets import check_dataset, dataset_checks
from .generators import check_generator, generator_checks
from .harnesses import check_harness, harness_checks
from .kit import Check, ConformanceReport, check_representation, representation_checks
from .metrics import check_metric, metric_checks
from .samplers import check_sampler, sampler_checks

__all__ = [
    "FAMILIES",
    "Check",
    "ConformanceReport",
    "adversarial_pairs",
    "check_dataset",
    "check_generator",
    "check_harness",
    "check_metric",
    "dataset_checks",
    "generator_checks",
    "harness_checks",
    "metric_checks",
    "check_representation",
    "check_sampler",
    "representation_checks",
    "sampler_checks",
]
