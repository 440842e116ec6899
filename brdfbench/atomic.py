"""Atomic file replacement: write to a unique temporary file beside the target, then rename.

Readers see either the old file or the complete new one, never a half-written file, and
a failure leaves nothing behind. The temporary name is unique per call (not only per
process), so threads writing the same path cannot collide.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


@contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path to write; on success it atomically replaces `path`."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
