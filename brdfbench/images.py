"""Rendered images: tone mapping and file I/O (EXR for radiance, PNG for display).

An image is a float torch tensor (H, W, 3) of linear radiance (HDR). `tonemap` turns it
into display values in [0, 1] with the simplest operator that keeps the comparison honest:
an exposure scale 2^exposure, a hard clamp to [0, 1], then the sRGB transfer curve
(IEC 61966-2-1). No filmic curve: the clamp saturates highlights instead of reshaping
them, so differences below white are compared as a display shows them, and the operator
is identical for every model. EXR files keep the radiance exactly (float32); PNG files
are 8-bit sRGB of the tone-mapped image. Every write is atomic.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from .atomic import replacing
from .errors import DataError

#: sRGB transfer curve: linear segment below this value, a 1/2.4 power above it.
_SRGB_KNEE = 0.0031308


def srgb_oetf(linear: torch.Tensor) -> torch.Tensor:
    """Encode linear values in [0, 1] with the piecewise sRGB curve."""
    power = 1.055 * linear.clamp_min(_SRGB_KNEE) ** (1 / 2.4) - 0.055
    return torch.where(linear <= _SRGB_KNEE, 12.92 * linear, power)


def tonemap(img: torch.Tensor, exposure: float = 0.0) -> torch.Tensor:
    """Display values in [0, 1]: scale by 2^exposure, clamp, sRGB-encode (elementwise)."""
    if not img.is_floating_point():
        raise ValueError(f"tonemap expects a float image of linear radiance, got dtype {img.dtype}")
    return srgb_oetf((img * 2.0 ** float(exposure)).clamp(0.0, 1.0))


def _as_rgb_array(img: torch.Tensor, path: Path) -> np.ndarray:
    """(H, W, 3) float32 array of `img`, or a ValueError naming `path` and the fault."""
    if not isinstance(img, torch.Tensor) or not img.is_floating_point():
        raise ValueError(f"refusing to write {path}: expected a float torch tensor (H, W, 3), got {type(img).__name__}"
                         + (f" of dtype {img.dtype}" if isinstance(img, torch.Tensor) else ""))
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"refusing to write {path}: expected an image of shape (H, W, 3), got {tuple(img.shape)}")
    arr = img.detach().to("cpu", torch.float32).numpy()
    bad = ~np.isfinite(arr).all(axis=-1)
    if bad.any():
        y, x = np.argwhere(bad)[0]
        raise ValueError(f"refusing to write {path}: {int(bad.sum())} pixels have NaN/Inf values (in float32), "
                         f"first at (row {y}, column {x})")
    return np.ascontiguousarray(arr)


def write_exr(path: str | os.PathLike, img: torch.Tensor) -> None:
    """Write linear radiance as a float32 RGB OpenEXR file (ZIP compression, lossless)."""
    import OpenEXR

    path = Path(path)
    arr = _as_rgb_array(img, path)
    channels = {c: np.ascontiguousarray(arr[..., i]) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with replacing(path) as tmp:
        OpenEXR.File(header, channels).write(str(tmp))


def read_exr(path: str | os.PathLike) -> torch.Tensor:
    """Read the R, G, B channels of an OpenEXR file as a float32 tensor (H, W, 3)."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such EXR file" if not path.exists() else f"{path}: is not a file")
    if not OpenEXR.isOpenExrFile(str(path)):
        raise DataError(f"{path}: not an OpenEXR file (bad magic number)")
    try:
        channels = OpenEXR.File(str(path), separate_channels=True).channels()
    except (RuntimeError, ValueError, OSError) as exc:
        raise DataError(f"{path}: cannot read EXR file ({exc})") from None
    missing = [c for c in "RGB" if c not in channels]
    if missing:
        raise DataError(f"{path}: EXR file lacks channel(s) {', '.join(missing)}; it has {sorted(channels) or 'none'}")
    arr = np.stack([np.asarray(channels[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
    bad = ~np.isfinite(arr).all(axis=-1)
    if bad.any():
        raise DataError(f"{path}: {int(bad.sum())} pixels have NaN/Inf values")
    return torch.from_numpy(arr)


def to_srgb8(img: torch.Tensor, exposure: float = 0.0) -> np.ndarray:
    """(H, W, 3) uint8 sRGB code values of the tone-mapped image (rounded to nearest)."""
    return (tonemap(img.double(), exposure) * 255.0).round().to(torch.uint8).numpy()


def write_png(path: str | os.PathLike, img: torch.Tensor, exposure: float = 0.0) -> None:
    """Write the tone-mapped image as an 8-bit sRGB PNG (Pillow, a dependency of matplotlib)."""
    from PIL import Image

    path = Path(path)
    _as_rgb_array(img, path)  # validates shape and finiteness
    data = to_srgb8(img.detach().cpu(), exposure)
    with replacing(path) as tmp:
        Image.fromarray(data).save(tmp, format="PNG")
