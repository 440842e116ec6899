"""AugMERL (Zhou et al., Sec. 3.1): a base set's RGB permutations and PCA-space interpolations.

From any registered base dataset of n materials:

- RGB permutations (×6): `<base>~gbr` is base material `<base>` whose red channel holds
  the base's green values, green its blue and blue its red (in 1/sr, re-encoded with the
  destination channel's MERL scale); `~rgb` is the base table itself. Invalid cells stay
  invalid (-1 in every channel). Category: the base material's.
- PCA interpolations: `mix-0000`, … each (1 − t)·c_a + t·c_b of two distinct permuted
  materials' coefficients, t ~ U(0, 1), seeded by (seed, index) only, so a larger `size`
  keeps the smaller one's mixes. The PCA is over the 6n permuted materials, one
  observation per material (its three channels mapped log-relative to the per-cell
  median, cosine-weighted: `brdfbench.logrel`, as the `pca` representation), reduced to k
  components (capped at the rank), computed in kernel form from the base's 3n mapped
  channel vectors (`_augmerl_pca`). A mix's cell is valid where both parents' base
  materials are valid (a reconstruction where a parent was never measured is invented)
  and on the logrel domain (both directions above the horizon). Category "mixture";
  `augmerl_recipe(dataset, name)` gives its parents, their permutations and t.

`size` ≤ 6n keeps a seeded subset of the permuted materials (no PCA at all); a larger size
keeps all 6n and adds size − 6n mixes. `splits` holds a seeded `test_fraction` out
(`brdfbench.protocols.generator.seeded_split`); a test material's parents or siblings may
be in training, as in Zhou et al..

The PCA state (reference, pooled mean, centred base channel vectors, validity,
eigenvectors) is computed on the first mix loaded, kept under
`cache_root(cache_dir)/augmerl/<key>/pca.safetensors` (key: the base's content and k) and
read once per process; mix tables are rebuilt from it on each load. `cache_dir` is also
handed to the base when it takes one and `base_params` does not set it.

`device` (run control, never in the fingerprint: the pipeline hands the job's `device` to
it) is where the two large products run: the base Gram matrix of the PCA build and each
mix's reconstruction (the base channel vectors are then held there, 4 B × 3n × P). On
the CPU (the default) nothing changes. A GPU's products differ from the CPU's in the last
bits, so a state built with a GPU is cached under its own key (the identity records
"device": "cuda") and never stands in for the CPU's, nor the CPU's for it: a CPU job and
a GPU job each see one consistent set of mixes; the two sets agree within float rounding
(tests/gpu/test_generators_gpu.py measures it) and share the fingerprint, as a
representation fitted on either device shares its configuration, each row recording the
device it was computed on.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import logging
import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from .. import logrel, merl
from ..plugins import registry
from ..errors import ConfigError, DataError, PluginError
from ..merl import MerlTable
from ..protocols.representation import Material
from . import _augmerl_pca as kpca, Dataset, material_types
from ._progress import Progress, note
from .content_hash import cache_root
from ..atomic import replacing
from ..device import resolve
from ..protocols.generator import available_memory, ResourceError, seeded_split

log = logging.getLogger(__name__)

#: Bump when AugMERL's output changes: it is in the fingerprint and the PCA cache key.
VERSION = "v1"
DEFAULT_SIZE = 240
DEFAULT_K = 300
MAX_SIZE = 1_000_000
#: Datasets that cannot be a base (they are built on one).
NOT_A_BASE = ("augmerl", "neumerl")
#: Share of the free memory the PCA build may plan to use.
MEMORY_SHARE = 0.8
#: Working memory of a PCA build beyond the channel matrix (chunks, one base table, the grid).
PCA_OVERHEAD = 512 * 2**20
MIXTURE = "mixture"
PERMUTATIONS = kpca.PERMUTATIONS
PERMUTATION_NAMES = kpca.PERMUTATION_NAMES
_KEY = "dataset.params"


@dataclass(frozen=True)
class Permuted:
    """A permuted material: base material `base`, channels `permutation` ("gbr": R ← G, G ← B, B ← R)."""

    name: str
    base: str
    permutation: str
    index: int  # observation index 6m + p in the PCA


@dataclass(frozen=True)
class Mix:
    """An interpolation (1 − t)·c_a + t·c_b in PCA space of permuted materials `a` and `b`."""

    name: str
    a: Permuted
    b: Permuted
    t: float

    @property
    def parents(self) -> tuple[str, str]:
        return self.a.name, self.b.name


# --------------------------------------------------------------------------- permutations


def permutation_of(name: str) -> tuple[int, int, int]:
    """(source channel of R, of G, of B) for a permutation name such as "gbr"."""
    if name not in PERMUTATION_NAMES:
        raise ValueError(f"unknown channel permutation {name!r}; expected one of {', '.join(PERMUTATION_NAMES)}")
    return PERMUTATIONS[PERMUTATION_NAMES.index(name)]


def permute_table(table: MerlTable, permutation: str) -> MerlTable:
    """The table with its channels permuted, values kept in 1/sr: channel c of the result
    holds channel p[c]'s values, stored with channel c's scale. Cells invalid in the base
    are invalid (-1) in every channel; the identity returns the table itself."""
    perm = permutation_of(permutation)
    if perm == (0, 1, 2):
        return table
    return MerlTable.from_values(table.values[list(perm)], table.valid)


# --------------------------------------------------------------------------- parameters


def _fail(key: str, value: Any, why: str) -> ConfigError:
    return ConfigError(f"{_KEY}.{key}={value!r}: {why}")


def _is_int(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def check_scalars(size: Any, test_fraction: Any, seed: Any, k: Any) -> None:
    """ConfigError naming the first bad one of AugMERL's numeric parameters."""
    if not _is_int(size) or not 2 <= size <= MAX_SIZE:
        raise _fail("size", size, f"must be an integer from 2 to {MAX_SIZE} (total materials)")
    if isinstance(test_fraction, bool) or not isinstance(test_fraction, (int, float)) \
            or not math.isfinite(test_fraction) or not 0 < test_fraction < 1:
        raise _fail("test_fraction", test_fraction, "must lie strictly between 0 and 1")
    if not _is_int(seed) or seed < 0:
        raise _fail("seed", seed, "must be a non-negative integer")
    if not _is_int(k) or k < 1:
        raise _fail("k", k, "must be a positive integer (PCA components)")


def _base_factory(base: Any):
    if not isinstance(base, str) or not base:
        raise _fail("base", base, "must be the name of a registered dataset")
    if base in NOT_A_BASE:
        raise _fail("base", base, f"AugMERL needs a dataset of measured-like materials, not {base!r} itself")
    try:
        return registry.get("datasets", base).load()
    except PluginError as exc:
        raise ConfigError(f"{_KEY}.base={base!r}: {exc}") from None


def _base_params(factory, params: Any, cache_dir) -> dict[str, Any]:
    """`params` checked against the base factory's signature (as `check_params` does), with
    `cache_dir` handed down where the base takes one and it is not set. A null value means
    the base's default (the config lists the built-in bases' keys as null, so that a plain
    override such as `dataset.params.base_params.subset=merl` needs no `+`)."""
    where = f"{_KEY}.base_params"
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        raise ConfigError(f"{where}={params!r} must be a mapping of the base dataset's parameters")
    params = {key: value for key, value in params.items() if value is not None}  # null: the base's default
    sig = inspect.signature(factory)
    if not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        for key in params:
            if key not in sig.parameters:
                raise ConfigError(f"unknown key {where}.{key}; {where} takes: {', '.join(sig.parameters) or 'none'}")
    if cache_dir is not None and "cache_dir" in sig.parameters and params.get("cache_dir") is None:
        params["cache_dir"] = cache_dir
    return params


def load_base(base: Any, base_params: Any, cache_dir=None) -> Dataset:
    """The base dataset, every bad name or parameter a ConfigError naming its key."""
    factory = _base_factory(base)
    params = _base_params(factory, base_params, cache_dir)
    try:
        dataset = factory(**params)
    except ConfigError as exc:
        raise ConfigError(f"{_KEY}.base_params (base {base!r}): {exc}") from None
    except TypeError as exc:  # a value of the wrong kind the factory did not check
        raise ConfigError(f"{_KEY}.base_params (base {base!r}): {exc}") from None
    if len(dataset) < 1:
        raise DataError(f"AugMERL base dataset {base!r} has no materials")
    return dataset


# --------------------------------------------------------------------------- names


def permuted_list(base: Dataset) -> list[Permuted]:
    """The 6n permuted materials, base by base, identity first."""
    return [Permuted(f"{m}~{p}", m, p, 6 * i + j) for i, m in enumerate(base.materials)
            for j, p in enumerate(PERMUTATION_NAMES)]


def mix_recipe(index: int, permuted: list[Permuted], seed: int) -> Mix:
    """Mix `index`: a ≠ b uniform over the permuted materials, t ~ U(0, 1), from (seed, index) only."""
    rng = np.random.default_rng([seed, 2, index])
    n = len(permuted)
    a = int(rng.integers(n))
    b = int(rng.integers(n - 1))
    b += b >= a
    return Mix(f"mix-{index:04d}", permuted[a], permuted[b], float(rng.random()))


def choose(permuted: list[Permuted], size: int, seed: int) -> tuple[list[Permuted], list[Mix]]:
    """The kept permuted materials (a seeded subset, in listing order, if size ≤ 6n) and the mixes."""
    if size <= len(permuted):
        keep = np.sort(np.random.default_rng([seed, 1]).permutation(len(permuted))[:size])
        return [permuted[i] for i in keep], []
    return list(permuted), [mix_recipe(j, permuted, seed) for j in range(size - len(permuted))]


def _digest(doc: Any) -> str:
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _base_identity(base_name: str, base: Dataset) -> list:
    """What the base's content is: its fingerprint, names and categories (no paths)."""
    return [base_name, base.fingerprint, list(base.materials), [base.category(m) for m in base.materials]]


# --------------------------------------------------------------------------- the PCA state


@dataclass(frozen=True)
class PcaState:
    """Everything a mix needs: per-cell `reference` and pooled `mean` (P,), centred base
    channel vectors `channels` (3n, P), base validity `valid` (n, P), eigenpairs."""

    reference: torch.Tensor
    mean: torch.Tensor
    channels: torch.Tensor
    valid: torch.Tensor
    comp: kpca.Components


def pca_nbytes(n: int) -> int:
    """Peak bytes of building (or holding) the PCA state of n base materials."""
    p = int(logrel.domain()[0].numel())
    return 3 * n * p * 4 + n * p + PCA_OVERHEAD


def check_memory(n: int) -> None:
    """Refuse, before any work, a PCA that needs more than MEMORY_SHARE of the free memory."""
    need, free = pca_nbytes(n), available_memory()
    if need > MEMORY_SHARE * free:
        raise ResourceError(
            f"{_KEY}.base: AugMERL's PCA over {n} base materials ({6 * n} permuted) needs about {need / 2**30:.1f} GiB "
            f"(3n mapped channel vectors of {int(logrel.domain()[0].numel())} cells, fp32), more than "
            f"{MEMORY_SHARE:.0%} of the {free / 2**30:.1f} GiB this machine has free; use a smaller base "
            f"(e.g. {_KEY}.base_params.limit) or a size of at most {6 * n} (no interpolations)"
        )


def build_state(base: Dataset, k: int, device: torch.device = torch.device("cpu")) -> PcaState:
    """The PCA state (on the CPU) of the base's 6n permutations, reading one base table at a
    time; the Gram matrix is accumulated on `device`."""
    cells, w = logrel.domain()
    n, p = len(base), cells.numel()
    values = torch.empty(3 * n, p, dtype=torch.float32)
    valid = torch.empty(n, p, dtype=torch.bool)
    progress = Progress("augmerl PCA", n, "base materials read")
    for m, name in enumerate(base.materials):
        table = base.load(name).table
        values[3 * m : 3 * m + 3] = torch.from_numpy(table.values.reshape(3, -1))[:, cells].float()
        valid[m] = torch.from_numpy(table.valid.reshape(-1))[cells]
        progress.update()
    progress.close()
    reference = kpca.pooled_reference(values, valid)
    channels = kpca.map_channels_(values, valid, reference, w)
    mean = kpca.pooled_mean(channels)
    kpca.centre_(channels, mean)
    comp = kpca.components(kpca.permuted_gram(kpca.base_gram(channels, device)), k)
    return PcaState(reference, mean, channels, valid, comp)


def _state_tensors(state: PcaState) -> dict[str, torch.Tensor]:
    return {"reference": state.reference, "mean": state.mean, "channels": state.channels,
            "valid": kpca.pack_mask(state.valid), "eigvals": state.comp.eigvals, "eigvecs": state.comp.eigvecs}


def write_state(path: Path, state: PcaState, identity: dict[str, Any]) -> None:
    """Save the state as safetensors, atomically; a cache that cannot be written is only slower."""
    from safetensors.torch import save_file

    meta = {"identity": json.dumps(identity, sort_keys=True), "rank": str(state.comp.rank),
            "k_asked": str(state.comp.k_asked)}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with replacing(path) as tmp:
            save_file({k: v.contiguous() for k, v in _state_tensors(state).items()}, str(tmp), metadata=meta)
    except OSError as exc:
        log.warning("%s: cannot write the AugMERL PCA cache (%s); it will be rebuilt next time", path, exc)


def read_state(path: Path, identity: dict[str, Any], n: int) -> PcaState | None:
    """The cached state if it is there, readable and of this very base and k; else None (with
    a warning when a file was there)."""
    if not path.exists():
        return None
    from safetensors import safe_open

    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
            if json.loads(meta.get("identity", "null")) != json.loads(json.dumps(identity, sort_keys=True)):
                raise ValueError("it was built from other data")
            t = {key: f.get_tensor(key) for key in ("reference", "mean", "channels", "valid", "eigvals", "eigvecs")}
            rank, k_asked = int(meta["rank"]), int(meta["k_asked"])
        p = int(logrel.domain()[0].numel())
        kk = t["eigvals"].shape[0]
        shapes = {"reference": (p,), "mean": (p,), "channels": (3 * n, p), "valid": (n, (p + 7) // 8),
                  "eigvals": (kk,), "eigvecs": (6 * n, kk)}
        for key, shape in shapes.items():
            if tuple(t[key].shape) != shape:
                raise ValueError(f"tensor {key!r} has shape {tuple(t[key].shape)}, expected {shape}")
        if not all(torch.isfinite(t[key]).all() for key in ("reference", "mean", "channels", "eigvals", "eigvecs")):
            raise ValueError("non-finite values")
    except Exception as exc:  # noqa: BLE001 - any damage means: rebuild
        log.warning("%s: unusable AugMERL PCA cache (%s); rebuilding it", path, exc)
        return None
    comp = kpca.Components(t["eigvals"], t["eigvecs"], rank, k_asked)
    return PcaState(t["reference"], t["mean"], t["channels"], kpca.unpack_mask(t["valid"], p), comp)


def describe_k(comp: kpca.Components) -> str:
    """How many components were kept and, where fewer than asked, why."""
    text = f"k={comp.k} components of {comp.k_asked} asked"
    if comp.k == comp.k_asked:
        return text
    if comp.k == comp.rank:
        return f"{text} (capped at the rank of the {comp.eigvecs.shape[0]} permuted materials)"
    return (f"{text} (component {comp.k + 1} is one of a degenerate pair, which the channel permutations make; "
            f"keeping half a pair is not a basis; rank {comp.rank})")


_STATES: dict[str, PcaState] = {}  # one state per process: a paper-size one is ~1.3 GB
_STATES_LOCK = threading.Lock()


# --------------------------------------------------------------------------- the loader


class AugmerlLoader:
    """The dataset's loader: builds a permuted or mixed material by name; holds the recipes."""

    def __init__(self, base_name: str, base: Dataset, recipes: dict[str, Permuted | Mix], k: int, cache_dir,
                 device: torch.device = torch.device("cpu")):
        self.base_name, self.base, self.recipes, self.k = base_name, base, recipes, k
        self.device = device
        self.identity = {"version": VERSION, "base": _base_identity(base_name, base), "k": k}
        if device.type != "cpu":  # a GPU's PCA is not the CPU's bit for bit: its own cache entry
            self.identity["device"] = device.type
        self.pca_key = _digest(self.identity)
        self.pca_path = cache_root(cache_dir) / "augmerl" / self.pca_key / "pca.safetensors"
        self._last: tuple[str, MerlTable] | None = None  # the six permutations of a base come in a row
        self._lock = threading.Lock()
        self._placed: tuple[PcaState, torch.Tensor, torch.Tensor] | None = None  # (state, channels, mean) on device

    def __call__(self, name: str) -> Material:
        recipe = self.recipes[name]
        if isinstance(recipe, Mix):
            t = recipe.t
            return Material(name, self.mix_table(recipe), MIXTURE,
                            source=f"augmerl {name}: (1 - {t:.4f})·{recipe.a.name} + {t:.4f}·{recipe.b.name} in PCA space")
        table = permute_table(self._base_table(recipe.base), recipe.permutation)
        return Material(name, table, self.base.category(recipe.base),
                        source=f"augmerl {name}: {recipe.base} with channels {recipe.permutation}")

    def _base_table(self, name: str) -> MerlTable:
        with self._lock:
            if self._last is not None and self._last[0] == name:
                return self._last[1]
        table = self.base.load(name).table
        with self._lock:
            self._last = (name, table)
        return table

    def state(self) -> PcaState:
        """The PCA state, read or built once per process."""
        with _STATES_LOCK:
            state = _STATES.get(self.pca_key)
            if state is None:
                _STATES.clear()  # free the previous one first: one at a time fits in memory
                state = read_state(self.pca_path, self.identity, len(self.base))
                if state is None:
                    check_memory(len(self.base))
                    note(f"augmerl: building the PCA of {6 * len(self.base)} permuted materials of {self.base_name!r}")
                    state = build_state(self.base, self.k, self.device)
                    write_state(self.pca_path, state, self.identity)
                note(f"augmerl: PCA with {describe_k(state.comp)}")
                _STATES[self.pca_key] = state
            return state

    def _operands(self, state: PcaState) -> tuple[torch.Tensor, torch.Tensor]:
        """The state's channel vectors and mean where the reconstruction runs (moved once)."""
        if self.device.type == "cpu":
            return state.channels, state.mean
        with self._lock:
            if self._placed is None or self._placed[0] is not state:
                self._placed = None  # free the previous state's copy first
                self._placed = (state, state.channels.to(self.device), state.mean.to(self.device))
            return self._placed[1], self._placed[2]

    def mix_mapped(self, mix: Mix) -> torch.Tensor:
        """(3, P) fp64 mapped channels of a mix (its PCA reconstruction), on the CPU."""
        state = self.state()
        beta = kpca.channel_weights(kpca.mix_weights(state.comp, mix.a.index, mix.b.index, mix.t))
        return kpca.reconstruct(beta, *self._operands(state)).cpu()

    def mix_table(self, mix: Mix) -> MerlTable:
        state = self.state()
        cells, w = logrel.domain()
        on_domain = logrel.from_mapped(self.mix_mapped(mix), state.reference.double(), w)
        valid_domain = state.valid[mix.a.index // 6] & state.valid[mix.b.index // 6]
        values = np.zeros((3, merl.N_CELLS), dtype=np.float64)
        values[:, cells.numpy()] = on_domain.numpy()
        valid = np.zeros(merl.N_CELLS, dtype=bool)
        valid[cells.numpy()] = valid_domain.numpy()
        return MerlTable.from_values(values.reshape(3, *merl.SHAPE), valid.reshape(merl.SHAPE))


# --------------------------------------------------------------------------- the dataset


def augmerl_dataset(base: str = "synthetic", base_params: Mapping[str, Any] | None = None, size: int = DEFAULT_SIZE,
                    test_fraction: float = 0.1, seed: int = 0, k: int = DEFAULT_K,
                    cache_dir: str | os.PathLike | None = None, device: str = "cpu") -> Dataset:
    """AugMERL over `base` (see the module docstring): `size` materials in total, a seeded
    `test_fraction` held out. Cheap to build: tables (and the PCA) are made on first load.
    `device`: where the PCA's products run (run control; see the module docstring)."""
    placed = resolve(device, f"{_KEY}.device")
    check_scalars(size, test_fraction, seed, k)
    size, seed, k, test_fraction = int(size), int(seed), int(k), float(test_fraction)
    base_ds = load_base(base, base_params, cache_dir)
    permuted, mixes = choose(permuted_list(base_ds), size, seed)
    if mixes:
        check_memory(len(base_ds))
    recipes: dict[str, Permuted | Mix] = {r.name: r for r in (*permuted, *mixes)}
    names = tuple(recipes)

    train, test = seeded_split(names, test_fraction, seed)
    loader = AugmerlLoader(base, base_ds, recipes, k, cache_dir, placed)
    fingerprint = "augmerl-" + VERSION + ":" + _digest(
        [VERSION, _base_identity(base, base_ds), size, test_fraction, seed, k])
    categories = {r.name: MIXTURE if isinstance(r, Mix) else base_ds.category(r.base) for r in recipes.values()}
    types = {r.name: recipe_types(base_ds, r) for r in recipes.values()}
    descriptions = {r.name: recipe_description(base_ds, r) for r in recipes.values()}
    return Dataset("augmerl", names, loader, fingerprint, categories, {"train": train, "test": test},
                   types=types, descriptions=descriptions)


def recipe_types(base: Dataset, recipe: Permuted | Mix) -> tuple[str, ...]:
    """A permuted material keeps its base material's types; a mix has both parents' (once each)."""
    if isinstance(recipe, Permuted):
        return base.material_types(recipe.base)
    return tuple(dict.fromkeys((*base.material_types(recipe.a.base), *base.material_types(recipe.b.base))))


def recipe_description(base: Dataset, recipe: Permuted | Mix) -> str:
    """Zhou et al. § 4.4: a permuted copy's base description without its colour words (the
    identity keeps them), "a mixture of A and B" for a mix of permuted materials A and B."""
    if isinstance(recipe, Mix):
        return material_types.mixture(recipe_description(base, recipe.a), recipe_description(base, recipe.b))
    text = base.description(recipe.base)
    return text if recipe.permutation == PERMUTATION_NAMES[0] else material_types.without_colour(text)


def unaugmented(dataset: Dataset, names: tuple[str, ...]) -> tuple[str, ...]:
    """The materials among `names` that are a base material unchanged (the identity
    permutation, no mix): what a generator "without augmentation" trains on (Hu 2026,
    Table 4.5). Refused for a dataset that is not AugMERL or NeuMERL."""
    recipes = _loader_of(dataset).recipes
    identity = PERMUTATION_NAMES[0]
    return tuple(n for n in names if isinstance(recipes.get(n), Permuted) and recipes[n].permutation == identity)


def _loader_of(dataset: Dataset) -> AugmerlLoader:
    loader = dataset.loader
    if not isinstance(loader, AugmerlLoader):
        raise ConfigError(f"dataset {dataset.name!r} is not an AugMERL dataset")
    return loader


def augmerl_recipe(dataset: Dataset, name: str) -> Permuted | Mix:
    """How material `name` of an AugMERL (or NeuMERL) dataset is made: a `Permuted` (base
    material, permutation) or a `Mix` (parents a and b, each a `Permuted`, and t)."""
    recipes = _loader_of(dataset).recipes
    if name not in recipes:
        raise DataError(f"dataset {dataset.name!r} has no material {name!r}")
    return recipes[name]


def augmerl_pca(dataset: Dataset) -> PcaState:
    """The PCA state behind an AugMERL dataset's mixes (read or built on first use):
    `comp.k` components kept of `comp.k_asked` asked, `comp.rank` the numerical rank."""
    return _loader_of(dataset).state()
