"""The built-in harnesses' plugin specs (light: listing plugins imports nothing heavy)."""

from __future__ import annotations

from ..plugins.specs import HarnessSpec

ACCURACY = HarnessSpec(
    name="accuracy",
    description="BRDF space: L1 / log L1 / cosine-weighted log L1 on the MERL grid, HDR RMSE / MAE on random pairs, throughput",
    target="brdfbench.harness.accuracy_harness:AccuracyHarness",
)
RENDER = HarnessSpec(
    name="render",
    description="Image space: renders against the table's render through the cheapest exact simulator (PSNR, SSIM, FLIP, RMSE)",
    target="brdfbench.harness.render:RenderHarness",
)
CONVERGENCE = HarnessSpec(
    name="convergence",
    description="Monte Carlo error against spp of a model's own renders, per importance sampler",
    target="brdfbench.harness.convergence:ConvergenceHarness",
)
