"""Entry-point specs of the built-in metrics."""

from brdfbench.specs import MetricSpec

L1 = MetricSpec(
    name="l1", description="Mean |f1 - f2| over valid MERL grid cells", target="brdfbench_metrics.base:L1",
    unit="1/sr", higher_is_better=False, tags=frozenset({"brdf_space", "merl_grid"}),
)
L1_LOG = MetricSpec(
    name="l1_log", description="Mean |log(1+f1) - log(1+f2)| over valid MERL grid cells (seed 000)",
    target="brdfbench_metrics.base:L1Log", unit="log(1+1/sr)", higher_is_better=False,
    tags=frozenset({"brdf_space", "merl_grid"}),
)
L1_LOG_COS = MetricSpec(
    name="l1_log_cos", description="Mean |log(1+f1 cos θi) - log(1+f2 cos θi)| over valid MERL grid cells (seed 000)",
    target="brdfbench_metrics.base:L1LogCos", unit="log(1+1/sr)", higher_is_better=False,
    tags=frozenset({"brdf_space", "merl_grid"}),
)
HDR_RMSE = MetricSpec(
    name="hdr_rmse", description="RMSE of unclipped BRDF values over random (ωi, ωo) pairs",
    target="brdfbench_metrics.base:HDRRMSE", unit="1/sr", higher_is_better=False,
    tags=frozenset({"brdf_space", "random_pairs"}),
)
HDR_MAE = MetricSpec(
    name="hdr_mae", description="MAE of unclipped BRDF values over random (ωi, ωo) pairs",
    target="brdfbench_metrics.base:HDRMAE", unit="1/sr", higher_is_better=False,
    tags=frozenset({"brdf_space", "random_pairs"}),
)
