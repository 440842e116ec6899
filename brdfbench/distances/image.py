"""Image-space distances between two sets of materials, as the distances the distributional
metrics (`distributional`) are computed from (Zhou et al., Sec. 4.2 and supplementary D.1;
Hu 2026 §4.3): each member is rendered on a sphere, and every pair of renders compared.

- `render_set`: every member of a set rendered through the project's own render path (the
  scene plugin, the render harness's config and checks, `build_simulator`), with one
  simulator for the whole set and one seed for every member: common random numbers, so
  differences between two images come from the materials, not from the Monte Carlo noise.
- `image_distance_matrix`: (|A|, |B|) distances of kind
  - `rmse`: root mean squared error over pixels and channels,
  - `neg_psnr`: −PSNR in dB (capped at `image_functional.PSNR_MAX_DB`),
  - `neg_ssim`: −SSIM (Gaussian window 11, σ 1.5),

  negated similarities being distances in the sense Zhou et al. use (a smaller value means
  more alike; they can be negative). By default on tone-mapped images in [0, 1] (space
  "ldr", `brdfbench.images.tonemap`, as Zhou et al. D.1 define them). Space "hdr" compares
  radiance (SSIM: log(1 + radiance)) with one data range for the whole matrix, the peak
  over both sets, so every entry is on the same scale and the matrix is symmetric (the
  per-image metrics take the target's own peak, which is not symmetric).

The definitions are `image_functional`'s (`rmse`, `psnr` with its cap, `ssim` with its
window, mirror padding and constants; the tests hold every entry to them pair by pair),
computed for all pairs at once, in fp64: each image is brought into its metric space once;
RMSE and PSNR come from exact sums of squared differences (no |a|² + |b|² − 2a·b
shortcut, so an image against itself is exactly 0); SSIM computes each image's local mean
and variance once, and per pair only the blurred product, in blocks of pairs, its blur a
matrix product. A set against itself is computed once per unordered pair (in blocks on and
above the diagonal), mirrored. The loops run on one torch thread (`brdfbench.threads`).

`device=` (None: the CPU) is where the matrices are computed: on a CUDA device the images
move there once (fp64) and the same arithmetic runs in larger blocks (`DEVICE_ROWS`,
`DEVICE_CHUNK_VALUES`); entries agree with the CPU's to rounding. Rendering stays on the
CPU (Mitsuba), as does FLIP (`image_functional.flip`, numpy), which no matrix here uses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import torch

from ..errors import RenderError
from ..images import tonemap
from ..threads import torch_threads

from . import image_functional as F
from ..pipeline.config import harness_class, harness_config
from ..pipeline.plan import check_params
from ..plugins import registry
from ..render.build import build_simulator

KINDS = ("rmse", "neg_psnr", "neg_ssim")
SPACES = F.SPACES
#: Default render size: small enough for sets of hundreds of materials on two cores, large
#: enough that a sharp highlight spans a few of SSIM's 11-pixel windows.
DEFAULT_SIZE = 64
#: Default samples per pixel for Monte Carlo scenes: the scene's own default (so renders
#: match `harness=render`'s). Fewer leave noise that reorders nearest neighbours even with
#: a common seed; `sphere_directional` (closed form) has none at all.
DEFAULT_SPP = 64
#: fp64 values per stack of a block of SSIM pairs (about four such stacks are live at once):
#: small blocks stay in cache (9 pairs of 64 × 64 images).
CHUNK_VALUES = 1 << 17
#: Rows per block of an RMSE / PSNR matrix: small blocks let a set against itself skip the
#: lower triangle.
ROWS = 16
#: The same on a CUDA device: larger blocks, fewer kernel launches (about 4 stacks of
#: DEVICE_CHUNK_VALUES fp64 values are live at once: 512 MiB).
DEVICE_CHUNK_VALUES = 1 << 24
DEVICE_ROWS = 256
#: Tests set this to run the device path's block sizes on the CPU, where CI checks them.
_DEVICE_PATH_ON_CPU = False

Progress = Callable[[int, int], None]


# --------------------------------------------------------------------------- rendering


def _label(member, i: int, labels: Sequence[str] | None) -> str:
    return f"member {i} ({labels[i] if labels is not None else type(member).__name__})"


def build_set_simulator(scene: str = "sphere_envmap", *, spp: int | None = DEFAULT_SPP, simulator: str | None = None,
                        sampler: str | None = None, sampler_params: dict[str, Any] | None = None,
                        backend: str | None = None, dtype: str | None = None, **scene_params: Any):
    """The simulator the render harness builds for scene plugin `scene` with `scene_params`
    (width and height default to `DEFAULT_SIZE`); the other keys are the render harness's,
    None taking its default. Build it once and `render_with` it for several sets (the
    reference and each sample draw): the scene, environment and kernels load once."""
    scene_params = {"width": DEFAULT_SIZE, "height": DEFAULT_SIZE, **scene_params}
    factory = registry.get("scenes", scene).load()
    check_params(factory, scene_params, "scene.params")
    built = factory(**scene_params)
    keys = dict(spp=spp, simulator=simulator, sampler=sampler, sampler_params=sampler_params, backend=backend,
                dtype=dtype)
    c = harness_config("render", metrics=(), **{k: v for k, v in keys.items() if v is not None})
    harness_class("render").validate(c, built, [])
    return build_simulator(built, name=c.simulator, sampler=c.sampler, sampler_params=c.sampler_params, spp=c.spp,
                           dtype=getattr(torch, c.dtype), backend=c.backend)


def _check_set(members: list, labels: Sequence[str] | None, seed: int) -> None:
    if not members:
        raise ValueError("render_set: the set is empty; give at least one member")
    if labels is not None and len(labels) != len(members):
        raise ValueError(f"render_set: {len(labels)} labels for {len(members)} members")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"render_set: seed={seed!r} must be a non-negative integer")


def render_with(sim, members: Sequence, *, seed: int = 0, labels: Sequence[str] | None = None,
                progress: Progress | None = None) -> torch.Tensor:
    """Linear radiance (N, H, W, 3) float32 of each fitted representation in `members`,
    rendered by the simulator `sim` with the same `seed` for every member. `labels` name the
    members in errors; `progress(done, total)` is called after each render. A non-finite
    render is a RenderError naming the member."""
    members = list(members)
    _check_set(members, labels, seed)
    out = None
    for i, member in enumerate(members):
        who = _label(member, i, labels)
        try:
            image = sim.render(member, seed=seed, label=who)
        except RenderError as exc:
            raise RenderError(f"render_set: {who}: {exc}") from None
        if not torch.isfinite(image).all():  # whatever the simulator checked, a set takes none
            raise RenderError(f"render_set: {who}: the render has non-finite pixels")
        if out is None:
            out = torch.empty((len(members), *image.shape), dtype=torch.float32)
        out[i] = image
        if progress is not None:
            progress(i + 1, len(members))
    return out


def render_set(members: Sequence, scene: str = "sphere_envmap", *, spp: int | None = DEFAULT_SPP, seed: int = 0,
               simulator: str | None = None, sampler: str | None = None, sampler_params: dict[str, Any] | None = None,
               backend: str | None = None, dtype: str | None = None, labels: Sequence[str] | None = None,
               progress: Progress | None = None, **scene_params: Any) -> torch.Tensor:
    """`render_with` a simulator built once for the set (`build_set_simulator` with these
    keys): (N, H, W, 3) float32 linear radiance, one seed for every member."""
    members = list(members)
    _check_set(members, labels, seed)
    sim = build_set_simulator(scene, spp=spp, simulator=simulator, sampler=sampler, sampler_params=sampler_params,
                              backend=backend, dtype=dtype, **scene_params)
    return render_with(sim, members, seed=seed, labels=labels, progress=progress)


# --------------------------------------------------------------------------- distances


def checked_images(x, name: str) -> torch.Tensor:
    """Validated float (N ≥ 1, H, W, 3) images of linear radiance, detached, on the CPU (a
    ValueError names the set and the first non-finite image)."""
    if isinstance(x, np.ndarray):
        x = torch.from_numpy(x)
    if not isinstance(x, torch.Tensor) or not x.is_floating_point():
        got = f"dtype {x.dtype}" if hasattr(x, "dtype") else type(x).__name__
        raise ValueError(f"{name} must be a float tensor (N, H, W, 3) of linear radiance, got {got}")
    if x.ndim != 4 or x.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (N, H, W, 3), got {tuple(x.shape)}")
    if x.shape[0] == 0 or x.shape[1] == 0 or x.shape[2] == 0:
        raise ValueError(f"{name} is empty (shape {tuple(x.shape)}): a set needs at least one image")
    bad = ~torch.isfinite(x).flatten(1).all(dim=1)
    if bad.any():
        raise ValueError(f"{name}: image {int(bad.nonzero()[0])} has non-finite (NaN/Inf) values "
                         f"({int(bad.sum())} such images); exclude and count them before scoring")
    return x.detach().cpu()


def _images(x, name: str) -> torch.Tensor:
    """Validated float64 (N, H, W, 3) images."""
    return checked_images(x, name).to(torch.float64)


def _check_kind(kind: str, space: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"unknown image distance {kind!r}: one of {', '.join(KINDS)}")
    if space not in SPACES:
        raise ValueError(f"unknown space {space!r}: one of {', '.join(SPACES)}")


def to_metric_space(images: torch.Tensor, kind: str, space: str, exposure: float, name: str) -> torch.Tensor:
    """Images as the metric compares them: tone-mapped (ldr), log(1 + radiance) (hdr SSIM)
    or the radiance itself (hdr RMSE and PSNR)."""
    if space == "ldr":
        return tonemap(images, exposure)
    if kind == "neg_ssim":
        low = float(images.min())
        if low < 0:
            raise ValueError(f"{name}: HDR SSIM needs non-negative radiance, got a minimum of {low:g}")
        return torch.log1p(images)
    return images


def _common_range(space: str, data_range: float | None, *stacks: torch.Tensor) -> float:
    """One data range for every pair: 1 for LDR, the given one, or the peak over both sets."""
    if data_range is not None:
        if not (np.isfinite(data_range) and data_range > 0):
            raise ValueError(f"data_range must be a positive finite number, got {data_range!r}")
        return float(data_range)
    if space == "ldr":
        return 1.0
    peak = max(float(s.max()) for s in stacks)
    if peak <= 0:
        raise ValueError("no image of either set has a positive value, so there is no HDR data range; "
                         "pass data_range explicitly")
    return peak


def _squared_sums(xa: torch.Tensor, xb: torch.Tensor) -> torch.Tensor:
    """(|a|, |b|) fp64 sums of squared differences over pixels and channels, from the
    differences themselves (`cdist` without the |a|² + |b|² − 2a·b shortcut, which cancels:
    an image against itself would not come out exactly 0)."""
    d = torch.cdist(xa.flatten(1)[None], xb.flatten(1)[None], compute_mode="donot_use_mm_for_euclid_dist")[0]
    return d * d


def _pixel_matrix(kind: str, xa: torch.Tensor, xb: torch.Tensor | None, data_range: float,
                  progress: Progress | None, block_rows: int = ROWS) -> torch.Tensor:
    """RMSE or −PSNR (capped as `image_functional.psnr`: `PSNR_MAX_DB`) of every pair, on
    xa's device, in blocks of `block_rows` rows (xb None: xa against itself, each row block
    against the columns from its first row on, mirrored)."""
    symmetric = xb is None
    xb = xa if symmetric else xb
    n_values = xa[0].numel()
    floor = data_range**2 * 10.0 ** (-F.PSNR_MAX_DB / 10.0)
    out = torch.empty((xa.shape[0], xb.shape[0]), dtype=torch.float64, device=xa.device)
    starts = range(0, xa.shape[0], block_rows)
    for done, i in enumerate(starts, 1):
        rows, cols = slice(i, i + block_rows), slice(i if symmetric else 0, None)
        mse = _squared_sums(xa[rows], xb[cols]) / n_values
        d = mse.sqrt() if kind == "rmse" else -10.0 * torch.log10(data_range**2 / torch.clamp_min(mse, floor))
        out[rows, cols] = d
        if symmetric:
            out[cols, rows] = d.T
        if progress is not None:
            progress(done, len(starts))
    return out


@lru_cache(maxsize=8)
def blur_matrix(n: int) -> torch.Tensor:
    """(n, n) fp64 matrix of `image_functional`'s SSIM filter along one axis: its Gaussian
    window with the mirror padding folded in, so `G_h @ x @ G_w.T` is its separable blur."""
    # A matrix product runs a stack of images at BLAS speed: ~25x the shifted sums of
    # image_functional._blur on two busy cores, despite the zeros it multiplies.
    window = F._gaussian_window()
    taps = window.numel()
    src = F._mirror_index(n, taps // 2)[torch.arange(n)[:, None] + torch.arange(taps)[None, :]]
    g = torch.zeros(n, n, dtype=torch.float64)
    g.index_put_((torch.arange(n)[:, None].expand(n, taps), src), window.expand(n, taps).clone(), accumulate=True)
    return g


@lru_cache(maxsize=8)
def _blur_matrix_on(n: int, device: torch.device) -> torch.Tensor:
    """`blur_matrix(n)` on `device` (one copy per device and size)."""
    return blur_matrix(n).to(device)


def _blur(x: torch.Tensor) -> torch.Tensor:
    """The SSIM blur of images (..., H, W), on their device."""
    if x.device.type == "cpu":
        return blur_matrix(x.shape[-2]) @ (x @ blur_matrix(x.shape[-1]).T)
    return _blur_matrix_on(x.shape[-2], x.device) @ (x @ _blur_matrix_on(x.shape[-1], x.device).T)


@dataclass(frozen=True)
class _SsimStats:
    """What SSIM needs of each image alone, computed once per image instead of once per
    pair: the channel-first image x, its local mean μ, and μ² + C1/2 and σ² + C2/2, whose
    pairwise sums are the factors of SSIM's denominator (N, 3, H, W)."""

    x: torch.Tensor
    mu: torch.Tensor
    m: torch.Tensor
    v: torch.Tensor

    @classmethod
    def of(cls, images: torch.Tensor, data_range: float) -> "_SsimStats":
        c1, c2 = (F.SSIM_K1 * data_range) ** 2, (F.SSIM_K2 * data_range) ** 2
        x = images.permute(0, 3, 1, 2).contiguous()
        mu = _blur(x)
        return cls(x, mu, mu * mu + c1 / 2, _blur(x * x) - mu * mu + c2 / 2)


def _ssim_block(a: _SsimStats, b: _SsimStats, ra: slice, rb: slice, data_range: float) -> torch.Tensor:
    """(r, c) −SSIM of the pairs a[ra] × b[rb]: Wang et al.'s formula with
    `image_functional.ssim_map`'s window and constants, averaged over channels and pixels.
    Broadcast, not gathered, and in place: a pair's images are never copied."""
    c1, c2 = (F.SSIM_K1 * data_range) ** 2, (F.SSIM_K2 * data_range) ** 2
    prod = a.x[ra, None] * b.x[None, rb]
    cov2 = _blur(prod)  # E[xy], then 2σxy + C2
    mu_xy = a.mu[ra, None] * b.mu[None, rb]  # μxμy, then the numerator
    cov2.sub_(mu_xy).mul_(2).add_(c2)
    mu_xy.mul_(2).add_(c1).mul_(cov2)
    torch.add(a.m[ra, None], b.m[None, rb], out=cov2)
    torch.add(a.v[ra, None], b.v[None, rb], out=prod)
    mu_xy.div_(cov2.mul_(prod))
    return -mu_xy.flatten(2).mean(dim=2)


def _ssim_matrix(xa: torch.Tensor, xb: torch.Tensor | None, data_range: float, side: int | None,
                 progress: Progress | None, chunk_values: int = CHUNK_VALUES) -> torch.Tensor:
    """−SSIM of every pair, on xa's device, in blocks of side × side pairs (default: about
    `chunk_values` values per stack; xb None: xa against itself, upper blocks only, mirrored)."""
    side = side or max(1, math.isqrt(max(1, chunk_values // xa[0].numel())))
    a = _SsimStats.of(xa, data_range)
    b = a if xb is None else _SsimStats.of(xb, data_range)
    na, nb = a.x.shape[0], b.x.shape[0]
    blocks = [(i, j) for i in range(0, na, side) for j in range(i if xb is None else 0, nb, side)]
    out = torch.empty((na, nb), dtype=torch.float64, device=xa.device)
    for done, (i, j) in enumerate(blocks, 1):
        ra, rb = slice(i, min(i + side, na)), slice(j, min(j + side, nb))
        d = _ssim_block(a, b, ra, rb, data_range)
        out[ra, rb] = d
        if xb is None:
            out[rb, ra] = d.T
        if progress is not None:
            progress(done, len(blocks))
    return out




def image_distance_matrix(images_a, images_b=None, kind: str = "rmse", *, space: str = "ldr", exposure: float = 0.0,
                          data_range: float | None = None, block: int | None = None,
                          progress: Progress | None = None, device: "torch.device | str | None" = None) -> np.ndarray:
    """(len(a), len(b)) float64 distances of kind `kind` between image sets (N, H, W, 3) of
    linear radiance (b = a when None: each unordered pair once, mirrored); `data_range`
    overrides the common one in space "hdr"; `block`: SSIM's pairs per block side (default
    from `CHUNK_VALUES`, or `DEVICE_CHUNK_VALUES` on a CUDA device); `progress(done, total)`
    counts blocks of pairs; `device` (None: the CPU) is where the matrix is computed."""
    _check_kind(kind, space)
    if block is not None and (isinstance(block, bool) or not isinstance(block, int) or block < 1):
        raise ValueError(f"block must be a positive integer, got {block!r}")
    symmetric = images_b is None
    a = _images(images_a, "images_a")
    b = a if symmetric else _images(images_b, "images_b")
    if a.shape[1:] != b.shape[1:]:
        raise ValueError(f"images_a and images_b differ in image shape: {tuple(a.shape[1:])} vs {tuple(b.shape[1:])}")
    h, w = a.shape[1], a.shape[2]
    if kind == "neg_ssim" and min(h, w) < F.SSIM_WINDOW:
        raise ValueError(f"neg_ssim needs images of at least {F.SSIM_WINDOW}×{F.SSIM_WINDOW} (the Gaussian window), "
                         f"got {h}×{w}")
    device = torch.device("cpu") if device is None else torch.device(device)
    big = device.type != "cpu" or _DEVICE_PATH_ON_CPU  # the device path's block sizes
    if device.type != "cpu":
        a = a.to(device)
        b = a if symmetric else b.to(device)
    with torch_threads(1):
        xa = to_metric_space(a, kind, space, exposure, "images_a")
        xb = xa if symmetric else to_metric_space(b, kind, space, exposure, "images_b")
        L = _common_range(space, data_range, xa, xb)
        if kind == "neg_ssim":
            out = _ssim_matrix(xa, None if symmetric else xb, L, block, progress,
                               DEVICE_CHUNK_VALUES if big else CHUNK_VALUES)
        else:
            out = _pixel_matrix(kind, xa, None if symmetric else xb, L, progress, DEVICE_ROWS if big else ROWS)
        return out.cpu().numpy()
