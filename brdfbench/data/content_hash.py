"""Content digests of data files: sha256 of the bytes, cached by (path, size, mtime_ns).

Why: a dataset fingerprint made of file sizes (or mtimes) cannot tell two files of the
same size apart (all published NBRDF networks are 18736 bytes), so a replaced file would
be reported as already in the results store. Hashing every 35 MB MERL file on every run
would be slow, so digests are kept in a small JSON file under the cache folder, valid
while the file's size and mtime are unchanged.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
import time
from pathlib import Path

from ..atomic import replacing

log = logging.getLogger(__name__)

CACHE_NAME = "file-digests.json"
_FORMAT = 1
_CHUNK = 1 << 20
#: A file changed this recently may change again within the same mtime tick, unseen by
#: (size, mtime): hash it, but do not cache its digest yet.
SETTLE_NS = 2 * 10**9


def cache_root(cache_dir: str | os.PathLike | None = None) -> Path:
    """`cache_dir`, else $BRDFBENCH_CACHE, else ~/.cache/brdfbench."""
    root = cache_dir if cache_dir is not None else os.environ.get("BRDFBENCH_CACHE") or "~/.cache/brdfbench"
    return Path(root).expanduser()


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes, read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def recorded_digest(record: Path) -> str | None:
    """The sha256 written in a `.sha256` record beside a cache file when it was made; None
    if there is none or it is not a digest."""
    try:
        text = record.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return text if len(text) == 64 and all(c in "0123456789abcdef" for c in text) else None


class DigestCache:
    """sha256 digests of files, remembered in CACHE_NAME under the cache root.

    A damaged or unwritable cache file only costs re-hashing; it is never an error.
    Entries of files that no longer exist are dropped when the cache is saved.
    """

    def __init__(self, cache_dir: str | os.PathLike | None = None):
        self.path = cache_root(cache_dir) / CACHE_NAME
        self._lock = threading.Lock()
        self._entries = self._read()
        self._new: dict[str, list] = {}

    def _read(self) -> dict[str, list]:
        try:
            doc = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError, UnicodeDecodeError):
            return {}
        if not isinstance(doc, dict) or doc.get("format") != _FORMAT or not isinstance(doc.get("files"), dict):
            return {}
        return {k: v for k, v in doc["files"].items() if isinstance(v, list) and len(v) == 3}

    def digest(self, path: str | os.PathLike) -> str:
        """The file's sha256; OSError if it cannot be read."""
        key = str(Path(path).resolve())
        before = os.stat(key)
        with self._lock:
            entry = self._new.get(key) or self._entries.get(key)
        if entry and entry[0] == before.st_size and entry[1] == before.st_mtime_ns:
            return entry[2]
        digest = sha256_file(key)
        after = os.stat(key)
        unchanged = (after.st_size, after.st_mtime_ns) == (before.st_size, before.st_mtime_ns)
        if unchanged and time.time_ns() - after.st_mtime_ns > SETTLE_NS:
            with self._lock:
                self._new[key] = [after.st_size, after.st_mtime_ns, digest]
        return digest

    def save(self) -> None:
        """Merge new digests into the cache file (atomically); keep going if it cannot be written."""
        with self._lock:
            if not self._new:
                return
            merged = {**self._read(), **self._new}
            merged = {k: v for k, v in merged.items() if os.path.exists(k)}
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                with replacing(self.path) as tmp:
                    tmp.write_text(json.dumps({"format": _FORMAT, "files": merged}, sort_keys=True), encoding="utf-8")
            except OSError as exc:
                log.debug("cannot write the digest cache %s: %s", self.path, exc)
                return
            self._entries, self._new = merged, {}


def file_digests(paths: list[Path], cache_dir: str | os.PathLike | None = None) -> list[str]:
    """sha256 of each file, through the digest cache; OSError names the unreadable file."""
    cache = DigestCache(cache_dir)
    try:
        return [cache.digest(p) for p in paths]
    finally:
        cache.save()
