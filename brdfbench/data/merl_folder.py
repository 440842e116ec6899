"""Dataset: every MERL `.binary` file in a user-given folder."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import stat
from pathlib import Path

from ..errors import DataError
from ..merl import read_binary
from ..protocols.representation import Material
from . import Dataset
from .content_hash import file_digests

log = logging.getLogger(__name__)
_warned: set[str] = set()  # entries already reported by this process (validation lists the folder again)
SUFFIX = ".binary"
#: 2: files are fingerprinted by content (sha256), no longer by size and mtime.
FINGERPRINT_VERSION = 2
_HINT = "pass the folder holding your MERL .binary files as dataset.params.path"


def _why(exc: OSError) -> str:
    if isinstance(exc, PermissionError):
        return "permission denied"
    return exc.strerror or str(exc)


def _check_folder(folder: Path) -> None:
    """A clear message for a path that is missing, a file, or not reachable."""
    try:
        st = os.stat(folder)
    except (FileNotFoundError, NotADirectoryError):
        raise DataError(f"{folder}: MERL folder does not exist; {_HINT}") from None
    except OSError as exc:
        raise DataError(f"{folder}: cannot reach MERL folder ({_why(exc)}); {_HINT}") from None
    if stat.S_ISDIR(st.st_mode):
        return
    if folder.suffix == SUFFIX:
        raise DataError(f"{folder}: is a MERL file, not a directory; pass its folder ({folder.parent}) as dataset.params.path")
    raise DataError(f"{folder}: is a file, not a directory; {_HINT}")


def _warn_once(path: str, what: str) -> None:
    if path not in _warned:
        _warned.add(path)
        log.warning("%s: %s", path, what)


def _list(folder: Path, recursive: bool) -> dict[str, Path]:
    """Material name -> file, for the `.binary` files in `folder`; an unlistable folder raises."""
    files: dict[str, Path] = {}
    pending = [folder]
    while pending:
        current = pending.pop()
        try:
            with os.scandir(current) as it:
                entries = list(it)
        except OSError as exc:
            fix = "; check its permissions" if isinstance(exc, PermissionError) else ""
            raise DataError(f"{current}: cannot list MERL folder ({_why(exc)}){fix}") from None
        for entry in entries:
            try:
                if entry.is_dir(follow_symlinks=False):
                    if recursive:
                        pending.append(Path(entry.path))
                    elif entry.name.endswith(SUFFIX):
                        _warn_once(entry.path, "a folder named like a MERL file, skipped (recursive=true reads its files)")
                elif entry.name.endswith(SUFFIX) and entry.is_file():
                    path = Path(entry.path)
                    files[path.relative_to(folder).with_suffix("").as_posix()] = path
                elif entry.name.endswith(SUFFIX):
                    _warn_once(entry.path, "not a regular file (a broken link, a pipe or a device), skipped")
            except OSError as exc:
                raise DataError(f"{entry.path}: cannot stat ({_why(exc)})") from None
    return files


def merl_folder_dataset(path: str | os.PathLike, recursive: bool = False) -> Dataset:
    """The `.binary` files in `path` (and its subfolders if `recursive`), sorted by name.

    Material names are the file stems; with `recursive`, files below the top level are
    named by their relative path without the suffix (e.g. "metals/chrome"). The
    fingerprint is the sha256 of every file (cached by size and mtime, see
    `content_hash`), so replacing a file by another of the same size is new data. Files
    are read and validated on load; faults raise `DataError` naming the file.
    """
    if path is None or str(path) == "":
        raise DataError(f"merl_folder: no folder given; {_HINT}")
    folder = Path(path).expanduser()
    _check_folder(folder)
    files = _list(folder, recursive)
    if not files:
        raise DataError(f"{folder}: is not a MERL folder: no {SUFFIX} files; {_HINT}")
    names = tuple(sorted(files))

    try:
        digests = file_digests([files[n] for n in names])
    except OSError as exc:
        raise DataError(f"{exc.filename or folder}: cannot read MERL file ({_why(exc)})") from None
    entries = list(zip(names, digests))
    digest = hashlib.sha256(json.dumps([FINGERPRINT_VERSION, entries]).encode()).hexdigest()[:16]

    def load(name: str) -> Material:
        p = files[name]
        return Material(name, read_binary(p), category="merl", source=str(p))

    return Dataset("merl_folder", names, load, f"merl_folder:{digest}", {n: "merl" for n in names})
