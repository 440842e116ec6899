"""NeuMERL (Zhou et al., Sec. 3.2): AugMERL plus an aligned NBRDF weight vector per material.

The tables, names, categories and splits are AugMERL's (`brdfbench.data.augmerl`); the
dataset adds `weights(names) -> WeightSet`: each material's 6-21-21-3 NBRDF (hidden sizes
configurable) flattened as `brdfbench.nbrdf.layouts.flatten` orders it (675 values).

Alignment (Zhou et al.'s weight initialisation): the anchor, the first material of the
train split, is fitted from its own random initialisation; every other material starts
from the anchor's fitted network, so the vectors of different materials stay close and
their hidden units correspond. Fits go through the registered `nbrdf` representation's
batched fitter (`batch_materials` at a time; a material's result does not depend on its
batch-mates), every material on the same training samples (`fit_seed`).

Cache: `cache_root(cache_dir)/neumerl/<key>/`, key = hash of the AugMERL fingerprint, the
fitting recipe and the anchor. Each material is `<name>.npy` (the 675-vector layout, as
`brdfbench.nbrdf.formats.write_network` writes it) plus `<name>.json` recording its
sha256, the anchor's sha256 and the fit loss; both are written atomically as each batch
finishes, so an interrupted fit resumes where it stopped. A file that is unreadable, not
the recorded content, or fitted from another anchor is refitted with a warning.

Device: `device` (run control, like AugMERL's: never in the fingerprint; the pipeline hands
the job's `device` to it) is where the fits run, through the `nbrdf` fitter's device path
(`nbrdf_fit.fit_batched(device=…)`), `GPU_BATCH_MATERIALS` materials per batch on a GPU.
A GPU fit is not bitwise the CPU's, so the vectors a GPU fits are cached apart: the cache
key and every record name the device type (the CPU's key is unchanged), the anchor is
fitted on the same device as the rest, and a set never mixes CPU and GPU fits. Both sets
share the dataset fingerprint, as representation fits on either device share their
configuration: the two agree within the fitter's GPU tolerance (fit losses within a few
per cent, tests/gpu), and each result row records the device it was computed on.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import threading
from pathlib import Path
from typing import Any, Mapping, Sequence
from urllib.parse import quote

import numpy as np
import torch

from ..plugins import registry
from ..errors import ConfigError, DataError, ModelFileError
from ..protocols.generator import WeightSet
from ..nbrdf.formats import read_network, representation_for, write_network
from ..nbrdf.layouts import flatten
from ..nbrdf.network import Network
from . import Dataset
from ._progress import Progress, note
from .augmerl import DEFAULT_K, DEFAULT_SIZE, augmerl_dataset
from .content_hash import cache_root, sha256_file
from ..atomic import replacing
from ..device import describe, resolve

log = logging.getLogger(__name__)

#: Bump when the fitting procedure changes: it is in the fingerprint and the cache key.
VERSION = "v1"
#: The input encoding of the networks fitted: their representation is the one registered
#: for it (`brdfbench.nbrdf.formats.representation_for`).
FEATURES = "rusinkiewicz"
#: The fitting recipe: that representation's (NBRDF's) defaults (minibatch 2048, lr 2e-2, one-cycle) with 10
#: epochs over 150k drawn pairs instead of 15 over 800k, 8x fewer sample passes: every
#: material but the anchor starts from a fitted network.
DEFAULT_EPOCHS = 10
DEFAULT_N_SAMPLES = 150_000
DEFAULT_BATCH_SIZE = 2048
DEFAULT_LR = 2e-2
DEFAULT_BATCH_MATERIALS = 16
#: Fitter settings NeuMERL fixes. No early stop: a material leaving the stack changes the
#: stack's size for its batch-mates, and with it the last bits of their fits.
FIXED = {"patience": None}
_KEY = "dataset.params"
_RECORD_FORMAT = 1
RANDOM_INIT = "random"


# --------------------------------------------------------------------------- parameters


def _positive_int(key: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{_KEY}.{key}={value!r}: must be a positive integer")
    return int(value)


def fit_params(hidden, epochs, n_samples, batch_size, lr) -> dict[str, Any]:
    """The recipe parameters handed to the nbrdf fitter, checked, each error naming its key."""
    widths = list(hidden) if not isinstance(hidden, (str, bytes, Mapping)) and hasattr(hidden, "__iter__") else []
    if not widths or any(isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 1 for h in widths):
        raise ConfigError(f"{_KEY}.hidden={hidden!r}: must be a non-empty list of positive layer widths")
    widths = [int(h) for h in widths]
    if isinstance(lr, bool) or not isinstance(lr, (int, float)) or not math.isfinite(lr) or lr <= 0:
        raise ConfigError(f"{_KEY}.lr={lr!r}: must be a positive number")
    return {"hidden": widths, "epochs": _positive_int("epochs", epochs),
            "n_samples": _positive_int("n_samples", n_samples), "batch_size": _positive_int("batch_size", batch_size),
            "lr": float(lr)}


def _digest(doc: Any) -> str:
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:16]


def file_stem(name: str) -> str:
    """A file name for a material name (`/` and other unsafe characters %-escaped)."""
    return quote(name, safe="-_.~+")


# --------------------------------------------------------------------------- the weights


class NeumerlWeights:
    """`weights(names)` of a NeuMERL dataset: cached vectors, fitting the missing ones."""

    def __init__(self, tables: Dataset, params: dict[str, Any], batch_materials: int, fit_seed: int, cache_dir,
                 device: torch.device = torch.device("cpu")):
        self.tables = tables
        self.params = params
        self.batch_materials = batch_materials
        self.fit_seed = fit_seed
        self.device = device
        self.anchor = tables.splits["train"][0]
        self.fitter_name = representation_for(FEATURES)
        spec = registry.get("representations", self.fitter_name)
        probe = spec.create(**params, **FIXED)  # a bad value fails now, naming it; its params fill in the defaults
        if device.type != "cpu":  # the fitter batches more materials at once on a GPU
            self.batch_materials = max(batch_materials, probe.to(device).fit_batch_size)
        #: What a fitted vector depends on: the fitter, its full recipe and the sample seed (not
        #: `batch_materials`: results do not depend on batch-mates).
        self.recipe = {"fitter": self.fitter_name, "version": registry.version("representations", self.fitter_name),
                       "fit_seed": fit_seed,
                       **{k: v for k, v in probe.params.items() if k not in ("init", "batch_materials")}}
        keyed = [VERSION, tables.fingerprint, self.recipe, self.anchor]
        if device.type != "cpu":  # a GPU's fits are cached apart from the CPU's (see the module docstring)
            keyed.append(device.type)
        self.key = _digest(keyed)
        self.folder = cache_root(cache_dir) / "neumerl" / self.key
        self._lock = threading.Lock()

    # -- files -----------------------------------------------------------------------
    def paths(self, name: str) -> tuple[Path, Path]:
        stem = file_stem(name)
        return self.folder / f"{stem}.npy", self.folder / f"{stem}.json"

    def read(self, name: str, anchor_sha: str) -> np.ndarray | None:
        """The cached vector of `name` fitted from the anchor with digest `anchor_sha` (RANDOM_INIT
        for the anchor itself); None if absent, and a warning if present but unusable."""
        npy, record = self.paths(name)
        if not npy.exists() and not record.exists():
            return None
        try:
            doc = json.loads(record.read_text(encoding="utf-8"))
            if not isinstance(doc, dict) or doc.get("format") != _RECORD_FORMAT or doc.get("name") != name \
                    or doc.get("key") != self.key:
                raise ValueError(f"{record} records another material or recipe")
            if doc.get("anchor_sha256") != anchor_sha:
                raise ValueError(f"{npy} was fitted from another anchor")
            if sha256_file(npy) != doc.get("sha256"):
                raise ValueError(f"{npy} is not the file that was fitted (sha256 differs from {record.name})")
            weights = read_network(npy, hidden=self.params["hidden"]).weights
        except (OSError, ValueError, ModelFileError) as exc:
            log.warning("neumerl: %s: unusable cached weights (%s); refitting", name, exc)
            return None
        return flatten(weights)

    def write(self, name: str, weights: dict[str, torch.Tensor], anchor_sha: str, info: dict[str, Any]) -> str:
        """Write `name`'s vector and its record, each atomically (the record last); the vector's sha256."""
        npy, record = self.paths(name)
        try:
            write_network(Network(weights=weights), npy)
            digest = sha256_file(npy)
            doc = {"format": _RECORD_FORMAT, "name": name, "key": self.key, "sha256": digest,
                   "anchor": self.anchor, "anchor_sha256": anchor_sha, **info}
            if self.device.type != "cpu":
                doc["fitted_on"] = describe(self.device)
            with replacing(record) as tmp:
                tmp.write_text(json.dumps(doc, sort_keys=True) + "\n", encoding="utf-8")
        except OSError as exc:
            raise DataError(f"{npy}: cannot write NeuMERL weights ({exc.strerror or exc})") from None
        return digest

    # -- fitting -------------------------------------------------------------------------
    def _fitter(self, init: str):
        fitter = registry.get("representations", self.fitter_name).create(
            **self.params, **FIXED, init=init, batch_materials=max(2, self.batch_materials))
        return fitter if self.device.type == "cpu" else fitter.to(self.device)

    def _fit(self, names: Sequence[str], init: str) -> list[tuple[dict[str, torch.Tensor], dict[str, Any]]]:
        """Fit `names` as one batch. A lone material is fitted beside a copy of itself: the
        fitter's arithmetic for a stack of one differs from a stack of two or more in the last
        bits, and a resumed set must equal a one-shot one exactly."""
        targets = [self.tables.load(n) for n in names]
        models = self._fitter(init).fit_many(targets * 2 if len(targets) == 1 else targets, seed=self.fit_seed)
        return [({k: v.cpu() for k, v in m.weights.items()},
                 {"fit_loss": m.fit_info.get("fit_loss"), "epochs": m.fit_info.get("epochs")})
                for m in models[: len(names)]]

    def anchor_vector(self) -> tuple[np.ndarray, str]:
        """The anchor's vector (fitted from its random initialisation if not cached) and its file's sha256."""
        vector = self.read(self.anchor, RANDOM_INIT)
        npy, _ = self.paths(self.anchor)
        if vector is not None:
            return vector, sha256_file(npy)
        note(f"neumerl: fitting the anchor {self.anchor!r} from a random initialisation")
        [(weights, info)] = self._fit([self.anchor], RANDOM_INIT)
        digest = self.write(self.anchor, weights, RANDOM_INIT, info)
        return flatten(weights), digest

    def __call__(self, names: Sequence[str]) -> WeightSet:
        names = tuple(names)
        unknown = [n for n in names if n not in self.tables.materials]
        if unknown:
            raise DataError(f"dataset 'neumerl' has no material(s) {', '.join(map(repr, unknown[:5]))}")
        with self._lock:
            vectors = self._vectors(list(dict.fromkeys(names)))
        return WeightSet(names, np.stack([vectors[n] for n in names]).astype(np.float32),
                         hidden=tuple(self.params["hidden"]))

    def _vectors(self, wanted: list[str]) -> dict[str, np.ndarray]:
        anchor_vec, anchor_sha = self.anchor_vector()
        vectors = {self.anchor: anchor_vec}
        pending = []
        for name in wanted:
            if name not in vectors:
                vector = self.read(name, anchor_sha)
                if vector is None:
                    pending.append(name)
                else:
                    vectors[name] = vector
        if pending:
            self._fit_pending(pending, anchor_sha, vectors, total=len(wanted))
        return vectors

    def _fit_pending(self, pending: list[str], anchor_sha: str, vectors: dict[str, np.ndarray], total: int) -> None:
        """Fit `pending` from the anchor, a batch at a time, writing each batch as it finishes."""
        anchor_file = str(self.paths(self.anchor)[0])
        progress = Progress("neumerl", total, "materials fitted", initial=total - len(pending))
        try:
            for start in range(0, len(pending), self.batch_materials):
                batch = pending[start : start + self.batch_materials]
                for name, (weights, info) in zip(batch, self._fit(batch, anchor_file)):
                    self.write(name, weights, anchor_sha, info)
                    vectors[name] = flatten(weights)
                progress.update(len(batch))
        finally:
            progress.close()

    def fit_info(self) -> dict[str, dict[str, Any]]:
        """name → {fit_loss, epochs, …} of every material whose vector is cached now."""
        out = {}
        for name in self.tables.materials:
            try:
                doc = json.loads(self.paths(name)[1].read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            if isinstance(doc, dict) and doc.get("key") == self.key:
                out[name] = doc
        return out


# --------------------------------------------------------------------------- the dataset


def neumerl_dataset(base: str = "synthetic", base_params: Mapping[str, Any] | None = None, size: int = DEFAULT_SIZE,
                    test_fraction: float = 0.1, seed: int = 0, k: int = DEFAULT_K,
                    cache_dir: str | os.PathLike | None = None, hidden: Sequence[int] = (21, 21),
                    epochs: int = DEFAULT_EPOCHS, n_samples: int = DEFAULT_N_SAMPLES,
                    batch_size: int = DEFAULT_BATCH_SIZE, lr: float = DEFAULT_LR,
                    batch_materials: int = DEFAULT_BATCH_MATERIALS, fit_seed: int = 0, device: str = "cpu") -> Dataset:
    """AugMERL's tables and splits (same parameters) plus aligned NBRDF weight vectors,
    fitted on first use and cached (see the module docstring). `device`: where the fits
    (and AugMERL's PCA products) run; run control, not part of the fingerprint."""
    placed = resolve(device, f"{_KEY}.device")
    params = fit_params(hidden, epochs, n_samples, batch_size, lr)
    batch_materials = _positive_int("batch_materials", batch_materials)
    if isinstance(fit_seed, bool) or not isinstance(fit_seed, (int, np.integer)) or fit_seed < 0:
        raise ConfigError(f"{_KEY}.fit_seed={fit_seed!r}: must be a non-negative integer")
    tables = augmerl_dataset(base, base_params, size, test_fraction, seed, k, cache_dir, device=str(placed))
    weights = NeumerlWeights(tables, params, batch_materials, int(fit_seed), cache_dir, placed)
    fingerprint = f"neumerl-{VERSION}:{_digest([VERSION, tables.fingerprint, weights.recipe])}"
    return Dataset("neumerl", tables.materials, tables.loader, fingerprint, tables.categories, tables.splits, weights,
                   tables.types, tables.descriptions)


def neumerl_fit_info(dataset: Dataset) -> dict[str, dict[str, Any]]:
    """The fit record (loss, epochs, anchor, sha256) of every material of a NeuMERL dataset fitted so far."""
    source = dataset.weights
    if not isinstance(source, NeumerlWeights):
        raise ConfigError(f"dataset {dataset.name!r} is not a NeuMERL dataset")
    return source.fit_info()
