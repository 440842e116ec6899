"""Functional image metrics: pred and target are float tensors (H, W, 3) or batches (N, H, W, 3).

Every metric runs in one of two spaces, chosen explicitly with `space=`:
- "ldr": both images are tone-mapped first (`brdfbench.images.tonemap`: 2^exposure scale,
  clamp, sRGB curve), as a viewer sees them; values in [0, 1], data range 1.
- "hdr": the raw linear radiance. PSNR's data range is then the target's maximum (per
  image, over all channels) unless `data_range` is given, so the figure does not depend on
  the scene's absolute brightness. SSIM runs on log(1 + x), which compresses highlights
  so a specular peak does not swamp the structure term, with the target's max of
  log(1 + x) as data range. FLIP runs NVIDIA's HDR-FLIP.

A batch reduces to the mean of its per-image values (`reduction="none"` keeps them), so a
set of images scores the same in one call or in many. PSNR is capped at `max_db` (100 dB by
default) so that one exact image does not make a mean over images infinite.

Devices: MSE, RMSE, MAE, MAPE, PSNR and SSIM are torch and take `device=` (default: where `pred` lies;
a CUDA device computes there in fp64, and the figures agree with the CPU's to rounding);
their values (and maps) come back on `pred`'s device. FLIP is the `flip-evaluator` package
(numpy, on the CPU): it takes no device and always runs on the CPU.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..images import tonemap

SPACES = ("ldr", "hdr")
SSIM_WINDOW, SSIM_SIGMA, SSIM_K1, SSIM_K2 = 11, 1.5, 0.01, 0.03
FLIP_PPD = 67.0
PSNR_MAX_DB = 100.0
#: MAPE's ε: |p − t| / (t + ε), so dark pixels (t → 0) do not dominate; 0.01 of the LDR range.
MAPE_EPS = 1e-2
#: a reference whose luminance never exceeds this has no exposure range for HDR-FLIP.
_DARK = 1e-30


# --------------------------------------------------------------------------- input checks


def _batched(name: str, pred: torch.Tensor, target: torch.Tensor,
             device: "torch.device | str | None" = None) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """Validated float64 (N, H, W, 3) copies of pred and target on `device` (None: pred's), and
    whether the input was one image."""
    for label, x in (("pred", pred), ("target", target)):
        if not isinstance(x, torch.Tensor) or not x.is_floating_point():
            got = f"dtype {x.dtype}" if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(f"{name}: {label} must be a float tensor of linear radiance, got {got}")
        if x.ndim not in (3, 4) or x.shape[-1] != 3:
            raise ValueError(f"{name}: {label} must have shape (H, W, 3) or (N, H, W, 3), got {tuple(x.shape)}")
    if pred.shape != target.shape:
        raise ValueError(f"{name}: pred and target shapes differ: {tuple(pred.shape)} vs {tuple(target.shape)}")
    if pred.numel() == 0:
        raise ValueError(f"{name}: empty images of shape {tuple(pred.shape)}")
    for label, x in (("pred", pred), ("target", target)):
        bad = ~torch.isfinite(x)
        if bad.any():
            raise ValueError(f"{name}: {label} has {int(bad.sum())} non-finite (NaN/Inf) values")
    single = pred.ndim == 3
    where = pred.device if device is None else torch.device(device)
    p, t = (x.detach().to(device=where, dtype=torch.float64) for x in (pred, target))
    return (p[None], t[None], single) if single else (p, t, single)


def _space(name: str, space: str) -> str:
    if space not in SPACES:
        raise ValueError(f"{name}: unknown space {space!r}; expected 'ldr' or 'hdr'")
    return space


def _nonnegative(name: str, **images: torch.Tensor) -> None:
    for label, x in images.items():
        low = float(x.min())
        if low < 0:
            raise ValueError(f"{name} in HDR space needs non-negative radiance; {label} has minimum {low:g}")


def _in_space(name: str, pred, target, space: str, exposure: float, device=None):
    p, t, single = _batched(name, pred, target, device)
    if _space(name, space) == "ldr":
        p, t = tonemap(p, exposure), tonemap(t, exposure)
    return p, t, single


def _reduce(values: torch.Tensor, single: bool, reduction: str) -> torch.Tensor:
    if reduction == "mean":
        return values.mean()
    if reduction == "none":
        return values[0] if single else values
    raise ValueError(f"unknown reduction {reduction!r}; expected 'mean' or 'none'")


def _home(x: torch.Tensor, pred) -> torch.Tensor:
    """A result back on `pred`'s device (a no-op where it was computed there)."""
    return x if x.device == pred.device else x.to(pred.device)


def _data_range(name: str, t: torch.Tensor, space: str, data_range: float | None) -> torch.Tensor:
    """(N,) data range per image: given, 1 for LDR, the target's max for HDR."""
    if data_range is not None:
        if not (math.isfinite(data_range) and data_range > 0):
            raise ValueError(f"{name}: data_range must be a positive finite number, got {data_range!r}")
        return torch.full((t.shape[0],), float(data_range), dtype=torch.float64, device=t.device)
    if space == "ldr":
        return torch.ones(t.shape[0], dtype=torch.float64, device=t.device)
    peak = t.flatten(1).amax(dim=1)
    if (peak <= 0).any():
        i = int(torch.nonzero(peak <= 0)[0])
        raise ValueError(f"{name}: target image {i} has no positive value, so it has no HDR data range; "
                         "pass data_range explicitly")
    return peak


# --------------------------------------------------------------------------- MSE, RMSE, MAE, MAPE, PSNR


def _mse_per_image(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    return ((p - t) ** 2).flatten(1).mean(dim=1)


def mse(pred, target, *, space: str, exposure: float = 0.0, reduction: str = "mean",
        device: "torch.device | str | None" = None) -> torch.Tensor:
    """Mean squared error over pixels and channels (computed on `device`: see the module docstring)."""
    p, t, single = _in_space("mse", pred, target, space, exposure, device)
    return _home(_reduce(_mse_per_image(p, t), single, reduction), pred)


def rmse(pred, target, *, space: str, exposure: float = 0.0, reduction: str = "mean",
         device: "torch.device | str | None" = None) -> torch.Tensor:
    """Root mean squared error of each image (a batch averages the per-image RMSEs)."""
    p, t, single = _in_space("rmse", pred, target, space, exposure, device)
    return _home(_reduce(_mse_per_image(p, t).sqrt(), single, reduction), pred)


def mae(pred, target, *, space: str, exposure: float = 0.0, reduction: str = "mean",
        device: "torch.device | str | None" = None) -> torch.Tensor:
    """Mean absolute error over pixels and channels (a batch averages the per-image MAEs)."""
    p, t, single = _in_space("mae", pred, target, space, exposure, device)
    return _home(_reduce((p - t).abs().flatten(1).mean(dim=1), single, reduction), pred)


def mape(pred, target, *, space: str, exposure: float = 0.0, eps: float = MAPE_EPS, reduction: str = "mean",
         device: "torch.device | str | None" = None) -> torch.Tensor:
    """Mean absolute percentage error, 100 · mean over pixels and channels of |p − t| / (t + ε),
    in % (the relative error of Sztrajman et al.'s convergence plots, with ε keeping dark
    pixels finite; a batch averages the per-image values). HDR needs a non-negative target."""
    if not (isinstance(eps, (int, float)) and math.isfinite(eps) and eps > 0):
        raise ValueError(f"mape: eps must be a positive finite number, got {eps!r}")
    p, t, single = _in_space("mape", pred, target, space, exposure, device)
    if space == "hdr":
        _nonnegative("mape", target=t)
    values = 100.0 * ((p - t).abs() / (t + eps)).flatten(1).mean(dim=1)
    return _home(_reduce(values, single, reduction), pred)


def psnr(pred, target, *, space: str, exposure: float = 0.0, data_range: float | None = None,
         max_db: float = PSNR_MAX_DB, reduction: str = "mean", device: "torch.device | str | None" = None) -> torch.Tensor:
    """10 log10(L² / MSE) in dB, with L = `data_range` (default: 1 for LDR, the target's max for HDR).

    Capped at `max_db`: identical images score `max_db`, not infinity.
    """
    p, t, single = _in_space("psnr", pred, target, space, exposure, device)
    peak = _data_range("psnr", t, space, data_range)
    floor = peak**2 * 10.0 ** (-max_db / 10.0)
    values = 10.0 * torch.log10(peak**2 / torch.maximum(_mse_per_image(p, t), floor))
    return _home(_reduce(values, single, reduction), pred)


# --------------------------------------------------------------------------- SSIM


def _gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    w = torch.exp(-(x**2) / (2 * sigma**2))
    return w / w.sum()


def _mirror_index(n: int, r: int) -> torch.Tensor:
    """Indices of 0..n-1 padded by r on each side, mirrored about the edge pixels (d c b | a b c d | c b a)."""
    i = torch.arange(-r, n + r).abs()
    return torch.where(i > n - 1, 2 * (n - 1) - i, i)


def _blur_axis(x: torch.Tensor, window: torch.Tensor, dim: int) -> torch.Tensor:
    n, r = x.shape[dim], window.numel() // 2
    padded = x.index_select(dim, _mirror_index(n, r).to(x.device))
    out = window[0] * padded.narrow(dim, 0, n)
    for k in range(1, window.numel()):
        out = out + window[k] * padded.narrow(dim, k, n)
    return out


def _blur(x: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter over the last two dims with mirror padding: the output keeps H × W.

    A sum of shifted copies, not conv2d: torch's float64 convolution splits even a tiny image
    across threads, which on a loaded machine cost 100x; elementwise ops go parallel only
    when the image is large enough to pay for it.
    """
    return _blur_axis(_blur_axis(x, window, -1), window, -2)


def ssim_map(p: torch.Tensor, t: torch.Tensor, data_range: torch.Tensor) -> torch.Tensor:
    """Per-pixel SSIM (N, H, W) of float64 images (N, H, W, C): each channel separately, then averaged."""
    n, h, w, c = p.shape
    window = _gaussian_window().to(p.device)
    x = p.permute(0, 3, 1, 2).reshape(n * c, h, w)
    y = t.permute(0, 3, 1, 2).reshape(n * c, h, w)
    mu_x, mu_y = _blur(x, window), _blur(y, window)
    var_x = _blur(x * x, window) - mu_x**2
    var_y = _blur(y * y, window) - mu_y**2
    cov = _blur(x * y, window) - mu_x * mu_y
    L = data_range.repeat_interleave(c).view(-1, 1, 1)
    c1, c2 = (SSIM_K1 * L) ** 2, (SSIM_K2 * L) ** 2
    s = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))
    return s.view(n, c, h, w).mean(dim=1)


def ssim(pred, target, *, space: str, exposure: float = 0.0, data_range: float | None = None,
         return_map: bool = False, reduction: str = "mean", device: "torch.device | str | None" = None):
    """Structural similarity (Wang et al. 2004): Gaussian window 11, σ = 1.5, K1 = 0.01, K2 = 0.03.

    Computed on each RGB channel and averaged; the window is mirror-padded at the borders so
    the map covers every pixel. HDR space compares log(1 + radiance), with data range the
    target's max of log(1 + radiance) unless given. `return_map=True` also returns the
    per-pixel map, (H, W) for one image or (N, H, W) for a batch. Computed on `device`
    (default: pred's); values and map come back on pred's device.
    """
    p, t, single = _batched("ssim", pred, target, device)
    if p.shape[1] < SSIM_WINDOW or p.shape[2] < SSIM_WINDOW:
        raise ValueError(f"ssim: images must be at least {SSIM_WINDOW}×{SSIM_WINDOW} (the Gaussian window), "
                         f"got {tuple(pred.shape)}")
    if _space("ssim", space) == "ldr":
        p, t = tonemap(p, exposure), tonemap(t, exposure)
    else:
        _nonnegative("ssim", pred=p, target=t)
        p, t = torch.log1p(p), torch.log1p(t)
    smap = ssim_map(p, t, _data_range("ssim", t, space, data_range))
    value = _home(_reduce(smap.flatten(1).mean(dim=1), single, reduction), pred)
    return (value, _home(smap[0] if single else smap, pred)) if return_map else value


# --------------------------------------------------------------------------- FLIP


def _luminance(img: np.ndarray) -> float:
    return float((img.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])).max())


def _flip_one(reference: np.ndarray, test: np.ndarray, hdr: bool, ppd: float) -> np.ndarray:
    """FLIP error map (H, W) of one pair of float32 (H, W, 3) arrays."""
    import flip_evaluator

    params: dict = {"ppd": ppd}
    if hdr and _luminance(reference) <= _DARK:
        # HDR-FLIP takes its exposure range from the reference; a black one has none (the
        # library would exit the process). Take the test image's range, or exposure 0 when
        # both are black.
        if _luminance(test) <= _DARK:
            params.update(startExposure=0.0, stopExposure=0.0)
        else:
            _, _, used = flip_evaluator.evaluate(test, test, "HDR", applyMagma=False, computeMeanError=False,
                                                 parameters={"ppd": ppd})
            params.update(startExposure=used["startExposure"], stopExposure=used["stopExposure"])
    error, _, _ = flip_evaluator.evaluate(reference, test, "HDR" if hdr else "LDR", applyMagma=False,
                                          computeMeanError=False, parameters=params)
    return error[..., 0]


def flip(pred, target, *, space: str, exposure: float = 0.0, ppd: float = FLIP_PPD,
         return_map: bool = False, reduction: str = "mean"):
    """NVIDIA ꟻLIP (Andersson et al. 2020, the `flip-evaluator` package): mean per-pixel error in [0, 1].

    LDR space runs LDR-FLIP on the tone-mapped (sRGB-encoded) images; HDR space runs
    HDR-FLIP on the radiance, which sweeps its own exposures (from the target's luminance
    range, ACES tone mapper: the library's defaults), so `exposure` does not apply there.
    `ppd` is the pixels per degree of visual angle (67: a 0.7 m wide 4K monitor at 0.7 m).
    The target is FLIP's reference. `return_map=True` also returns the error map.
    The library runs OpenMP threads; on an oversubscribed machine OMP_NUM_THREADS=1 is faster.
    It computes on the CPU (numpy) whatever device the images are on: it takes no `device`.
    """
    if not (isinstance(ppd, (int, float)) and math.isfinite(ppd) and ppd > 0):
        raise ValueError(f"flip: ppd (pixels per degree) must be a positive finite number, got {ppd!r}")
    p, t, single = _batched("flip", pred, target, "cpu")  # the package is numpy: FLIP runs on the CPU
    hdr = _space("flip", space) == "hdr"
    if hdr:
        _nonnegative("flip", pred=p, target=t)
    else:
        p, t = tonemap(p, exposure), tonemap(t, exposure)
    p32, t32 = (x.to(torch.float32).numpy() for x in (p, t))
    if not (np.isfinite(p32).all() and np.isfinite(t32).all()):
        raise ValueError("flip: radiance beyond the float32 range (FLIP computes in float32)")
    maps = torch.from_numpy(np.stack([_flip_one(np.ascontiguousarray(t32[i]), np.ascontiguousarray(p32[i]), hdr,
                                                float(ppd)) for i in range(p.shape[0])]))
    value = _home(_reduce(maps.double().flatten(1).mean(dim=1), single, reduction), pred)
    return (value, _home(maps[0] if single else maps, pred)) if return_map else value
