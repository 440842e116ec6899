"""Dataset: every MERL `.binary` file in a user-given folder."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from ..errors import DataError
from ..merl import read_binary
from ..protocol import Material
from . import Dataset

SUFFIX = ".binary"
FINGERPRINT_VERSION = 1


def merl_folder_dataset(path: str | os.PathLike, recursive: bool = False) -> Dataset:
    """The `.binary` files in `path` (and its subfolders if `recursive`), sorted by name.

    Material names are the file stems; with `recursive`, files below the top level are
    named by their relative path without the suffix (e.g. "metals/chrome"). Files are
    read and validated on load; faults raise `DataError` naming the file.
    """
    if path is None or str(path) == "":
        raise DataError("merl_folder: no folder given; pass the path of a folder of MERL .binary files")
    folder = Path(path).expanduser()
    if not folder.exists():
        raise DataError(f"{folder}: MERL folder does not exist")
    if not folder.is_dir():
        raise DataError(f"{folder}: is not a directory; expected a folder of MERL .binary files")
    try:
        found = folder.rglob(f"*{SUFFIX}") if recursive else folder.glob(f"*{SUFFIX}")
        files = {p.relative_to(folder).with_suffix("").as_posix(): p for p in found if p.is_file()}
    except OSError as exc:
        raise DataError(f"{folder}: cannot list MERL folder ({exc.strerror or exc})") from None
    if not files:
        raise DataError(f"{folder}: is not a MERL folder: no {SUFFIX} files")
    names = tuple(sorted(files))

    entries = []
    for n in names:
        try:
            st = files[n].stat()
        except OSError as exc:
            raise DataError(f"{files[n]}: cannot stat MERL file ({exc.strerror or exc})") from None
        entries.append((n, st.st_size, st.st_mtime_ns))
    digest = hashlib.sha256(json.dumps([FINGERPRINT_VERSION, entries]).encode()).hexdigest()[:16]

    def load(name: str) -> Material:
        p = files[name]
        return Material(name, read_binary(p), category="merl", source=str(p))

    return Dataset("merl_folder", names, load, f"merl_folder:{digest}", {n: "merl" for n in names})
