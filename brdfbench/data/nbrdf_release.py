"""Dataset: the published NBRDF networks of real measured materials, on the MERL grid.

The release (Sztrajman et al. 2021, see shared/data/neural-brdf/README.md) is not part
of the repository. It is found through the environment variable BRDFBENCH_NBRDF_DIR, or
else as a `shared/data/neural-brdf` folder in the current directory, the package's
source directory or any of their parents (the project layout keeps `shared/` beside
the repository clone). Each material's network is evaluated at the MERL cell centres
when it is first loaded; the outputs are kept in the cache folder ($BRDFBENCH_CACHE, else
~/.cache/brdfbench: about 13 MB a network), keyed by the network's weights, so later loads
(every job of a sweep, every fold of a training split) read them back exactly
(`brdfbench.data.grid_cache`).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import torch

from ..errors import ConfigError, DataError
from ..protocols.representation import Material
from . import Dataset
from ..nbrdf.keras_h5 import read_nbrdf_h5
from .grid_cache import ArrayCache, weights_digest
from .nbrdf_h5 import grid_cells, grid_outputs, table_from_outputs
from .content_hash import file_digests

ENV_VAR = "BRDFBENCH_NBRDF_DIR"
RELATIVE = Path("shared", "data", "neural-brdf")
SUBSETS = ("merl", "nielsen", "rgl-isotropic")
#: 2: networks are fingerprinted by content (sha256): all published ones have the same size.
FINGERPRINT_VERSION = 2


def _search_roots() -> list[Path]:
    roots = []
    for start in (Path.cwd(), Path(__file__).resolve().parent):
        for p in (start, *start.parents):
            if p not in roots:
                roots.append(p)
    return roots


def find_release_dir() -> Path | None:
    """The NBRDF release folder, or None where there is none.

    If BRDFBENCH_NBRDF_DIR is set it alone is used (None if it is not a directory);
    otherwise the first `shared/data/neural-brdf` folder found upward from the current
    directory or from this package's source.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        p = Path(env).expanduser()
        return p if p.is_dir() else None
    for root in _search_roots():
        candidate = root / RELATIVE
        if candidate.is_dir():
            return candidate
    return None


def _release_dir(path: str | os.PathLike | None) -> Path:
    if path is not None:
        p = Path(path).expanduser()
        if not p.is_dir():
            raise DataError(f"{p}: NBRDF release folder does not exist or is not a directory")
        return p
    found = find_release_dir()
    if found is not None:
        return found
    env = os.environ.get(ENV_VAR)
    if env:
        raise DataError(f"{ENV_VAR}={env}: NBRDF release folder does not exist or is not a directory")
    looked = sorted({str(r / RELATIVE) for r in (Path.cwd(), Path(__file__).resolve().parent)})
    raise DataError(
        f"NBRDF release not found: no {RELATIVE} folder in {' or '.join(looked)} or any parent directory; "
        f"set {ENV_VAR} to the folder holding merl/, nielsen/ and rgl-isotropic/"
    )


def nbrdf_release_dataset(path: str | None = None, subset: str = "merl", limit: int | None = None) -> Dataset:
    """Materials of one subset of the NBRDF release, each evaluated on the MERL grid.

    `path` is the release folder (holding merl/, nielsen/, rgl-isotropic/); by default
    it is found as `find_release_dir` describes. `limit` keeps the first materials.
    """
    if subset not in SUBSETS:
        raise ConfigError(f"unknown NBRDF subset {subset!r}; expected one of {', '.join(SUBSETS)}")
    if limit is not None and (not isinstance(limit, int) or isinstance(limit, bool) or limit < 0):
        raise ConfigError(f"limit must be a non-negative integer or None, got {limit!r}")
    root = _release_dir(path)
    folder = root / subset
    if not folder.is_dir():
        raise DataError(f"{folder}: NBRDF subset folder {subset!r} does not exist in the release at {root}")
    files = {p.stem: p for p in folder.glob("*.h5") if p.is_file()}
    if not files:
        raise DataError(f"{folder}: no .h5 files; not an NBRDF release subset")
    names = tuple(sorted(files))

    try:
        entries = list(zip(names, file_digests([files[n] for n in names])))
    except OSError as exc:
        raise DataError(f"{exc.filename or folder}: cannot read NBRDF network ({exc.strerror or exc})") from None
    digest = hashlib.sha256(json.dumps([FINGERPRINT_VERSION, subset, entries]).encode()).hexdigest()[:16]
    fingerprint = f"nbrdf_release:{subset}:{digest}"

    cache = ArrayCache("nbrdf_release", f"torch{torch.__version__}")

    def load(name: str) -> Material:
        h5path = files[name]
        weights = read_nbrdf_h5(h5path)
        outputs = cache.get(weights_digest(weights), lambda: grid_outputs(weights), (grid_cells(), 3), np.float32)
        return Material(name, table_from_outputs(outputs), category=subset, source=str(h5path))

    dataset = Dataset("nbrdf_release", names, load, fingerprint, {n: subset for n in names})
    return dataset.subset(limit=limit) if limit is not None else dataset
