"""A disk cache of arrays that are slow to compute and fixed by their inputs: a published
network's outputs at the MERL grid, keyed by a digest of its weights.

Why: a dataset of networks is evaluated on the 90×90×180 grid at every load, and a sweep
loads each material once per job (and a training split once per fold), so the same
evaluation ran dozens of times per material. The cached array is the evaluation's own
output, stored exactly (`.npy`, no pickle), so a table built from it is the one the
evaluation gives, bit for bit.

Like the synthetic set's cache, each file has a `.sha256` record of its content as
written; a file that no longer matches it (edited, damaged, half-copied) is recomputed
with a warning. The folder name carries the cache format and the torch version (the
evaluation's float32 arithmetic is torch's). A cache that cannot be written (read-only,
full disk) only costs the computation: it is never an error.
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from ..atomic import replacing
from .content_hash import DigestCache, cache_root, recorded_digest, sha256_file

log = logging.getLogger(__name__)

#: Bump when what is cached under a key changes (the evaluation, the layout of the array).
FORMAT = 1


def weights_digest(weights: Mapping[str, np.ndarray]) -> str:
    """sha256 of a network's weights: names, dtypes, shapes and bytes, in key order."""
    h = hashlib.sha256()
    for name in sorted(weights):
        a = np.ascontiguousarray(np.asarray(weights[name]))
        h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


class ArrayCache:
    """Arrays of one kind (`name`) under cache_root()/name/v<FORMAT>-<tag>/<key>.npy."""

    def __init__(self, name: str, tag: str, cache_dir: str | os.PathLike | None = None):
        self.folder = cache_root(cache_dir) / name / f"v{FORMAT}-{tag}"
        self._digests = DigestCache(cache_dir)
        self._warned = False

    def get(self, key: str, compute: Callable[[], np.ndarray], shape: tuple[int, ...], dtype) -> np.ndarray:
        """The cached array of `key` (read-only, mapped from the file) if it is intact and of
        this shape and dtype; else compute() (which must return one), stored for the next call."""
        path = self.folder / f"{key}.npy"
        found = self._read(path, shape, np.dtype(dtype))
        if found is not None:
            return found
        array = compute()
        if array.shape != shape or array.dtype != np.dtype(dtype):
            raise ValueError(f"cache {self.folder.parent.name}: computed {array.dtype}{array.shape}, "
                             f"declared {np.dtype(dtype)}{shape}")
        self._write(path, array)
        return array

    def _read(self, path: Path, shape, dtype) -> np.ndarray | None:
        record = path.with_name(path.name + ".sha256")
        if not path.exists():
            return None
        try:
            actual = self._digests.digest(path)
        except OSError:
            return None
        finally:
            self._digests.save()
        expected = recorded_digest(record)
        if expected != actual:
            log.warning("%s: content differs from the array as written (sha256 %s..., recorded %s); recomputing it",
                        path, actual[:12], f"{expected[:12]}..." if expected else "none")
            return None
        try:
            array = np.load(path, mmap_mode="r", allow_pickle=False)  # read-only, from the page cache
        except (OSError, ValueError) as exc:
            log.warning("%s: unreadable (%s); recomputing it", path, exc)
            return None
        if array.shape != shape or array.dtype != dtype:
            log.warning("%s: holds %s%s, expected %s%s; recomputing it", path, array.dtype, array.shape, dtype, shape)
            return None
        return array

    def _write(self, path: Path, array: np.ndarray) -> None:
        record = path.with_name(path.name + ".sha256")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with replacing(path) as tmp:
                with open(tmp, "wb") as f:
                    np.save(f, array, allow_pickle=False)
            with replacing(record) as tmp:
                tmp.write_text(sha256_file(path) + "\n", encoding="ascii")
        except OSError as exc:
            if not self._warned:
                log.warning("%s: cannot write the cache (%s); computing every load instead",
                            self.folder, exc.strerror or exc)
                self._warned = True
