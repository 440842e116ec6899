"""Atomic file replacement: write to a unique temporary file beside the target, then rename.

Readers see either the old file or the complete new one, never a half-written file, and
a failure leaves nothing behind. The temporary name is unique per call (not only per
process), so threads writing the same path cannot collide. The result gets the
permissions a plain open() would give a new file, 0666 less the umask (tempfile.mkstemp
would make it 0600).
"""

from __future__ import annotations

import os
import secrets
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

_ATTEMPTS = 100


def _create_temporary(path: Path) -> tuple[Path, int]:
    """An empty, new file beside `path`, created exclusively under the process umask, and its mode."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(_ATTEMPTS):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:
            continue
        try:
            return tmp, stat.S_IMODE(os.fstat(fd).st_mode)
        finally:
            os.close(fd)
    raise FileExistsError(f"{path.parent}: no unused temporary name for {path.name} after {_ATTEMPTS} tries")


@contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path to write; on success it atomically replaces `path`.

    A writer that replaces the temporary file by one of its own (safetensors writes 0600
    files) gets the umask's mode back before the rename.
    """
    path = Path(path)
    tmp, mode = _create_temporary(path)
    try:
        yield tmp
        if stat.S_IMODE(os.stat(tmp).st_mode) != mode:
            os.chmod(tmp, mode)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
