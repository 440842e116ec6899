"""The fit_loss figure: one definition (harness.cost.fit_loss) for the benchmark's cells and
for `brdfbench.evaluate`, so the two cannot drift (a bool is not a loss)."""

from __future__ import annotations

import math

import pytest

from brdfbench import api
from brdfbench.plugins import registry
from brdfbench.harness.cost import fit_loss
from brdfbench.testing.kit import reference_material


MATERIAL = reference_material()


def _lambert(loss):
    cls = registry.get("representations", "lambert").load()

    class Reporting(cls):
        def metadata(self):
            return {"fit_loss": loss}

    return Reporting().fit(MATERIAL)


@pytest.mark.parametrize(("loss", "want"), [(0.25, [0.25]), (3, [3.0]), (True, []), ("0.1", []), (None, [])])
def test_only_a_real_number_is_a_fit_loss(loss, want):
    got = fit_loss(_lambert(loss))
    assert [m.value for m in got] == want
    assert all(m.metric == "fit_loss" and m.unit == "objective" and not m.higher_is_better for m in got)


def test_evaluate_and_the_pipeline_share_it():
    import inspect

    from brdfbench.pipeline import execute

    assert "fit_loss(model)" in inspect.getsource(execute) and "fit_loss(model)" in inspect.getsource(api.evaluate)
    scores = api.evaluate(_lambert(True), MATERIAL, metrics=["l1"], n_random=4096)
    assert "fit_loss" not in {m.metric for m in scores.measurements}
    scores = api.evaluate(_lambert(0.5), MATERIAL, metrics=["l1"], n_random=4096)
    assert math.isclose(next(m.value for m in scores.measurements if m.metric == "fit_loss"), 0.5)
