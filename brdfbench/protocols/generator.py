"""The material-generator protocol every generator plugin implements.

A generator learns a distribution over materials from a training split (`fit`) and draws
new materials from it (`sample`). What it learns from is declared by `learns_from`:

- "tables": the split's MERL tables, read one at a time (`TrainingData.tables()`);
- "nbrdf": the split's NBRDF weight vectors, aligned across materials (fitted with a
  shared initialisation), as one (N, W) float32 array (`TrainingData.weights()`).

`sample(n, condition=None, seed=...)` returns a `SampleSet`: n samples, each a fitted
`brdfbench.protocols.representation.Representation` (an NBRDF network, a table) that the rest of the
project evaluates, scores and renders, built lazily so that a set of full tables never
has to sit in memory at once. Its `array` holds each sample's raw parameters (n, ...),
which determinism checks compare and the non-finite check reads per sample.

State for saving is a flat dict of tensors plus JSON-able metadata, as for
representations (`brdfbench.modelio.save_generator`): loading never runs code.

Devices: as for representations (`brdfbench.device.Placed`): a generator whose class lists
"cuda" in `devices` trains and samples on the device it was moved to with `to`; its
samples may live there too, and evaluate inputs on their own device.
"""

from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch

from ..device import Placed
from ..errors import ConfigError, DataError
from .representation import Material, Representation
from ..nbrdf.network import n_weights

LEARNS_FROM = ("tables", "nbrdf")
#: `metadata()` key of a generator's training curves: {name: [value per epoch]} (e.g.
#: {"loss": [...], "held-out loss": [...]}); reports plot them against the epoch.
TRAINING_CURVE_KEY = "training_curve"


class ResourceError(ConfigError):
    """A request that would exceed this machine's memory, refused before allocating."""


@dataclass(frozen=True)
class WeightSet:
    """Aligned NBRDF weight vectors of a split: `vectors[i]` is material `names[i]`'s network
    flattened as `brdfbench.nbrdf.layouts.flatten` does (fc1.weight, fc1.bias, …)."""

    names: tuple[str, ...]
    vectors: np.ndarray  # (N, W) float32
    hidden: tuple[int, ...] = (21, 21)
    features: str = "rusinkiewicz"
    raw_units: bool = False

    def __post_init__(self):
        v = self.vectors
        if not isinstance(v, np.ndarray) or v.ndim != 2 or v.shape[0] != len(self.names):
            raise DataError(f"weight set: expected a ({len(self.names)}, W) array, got "
                            f"{getattr(v, 'shape', type(v).__name__)}")
        expected = n_weights(self.hidden)
        if v.shape[1] != expected:
            raise DataError(f"weight set: vectors have {v.shape[1]} values, a 6-{'-'.join(map(str, self.hidden))}-3 "
                            f"network has {expected}: every material of a NeuMERL set must share one architecture")
        if not np.isfinite(v).all():
            row = int(np.argwhere(~np.isfinite(v))[0, 0])
            raise DataError(f"weight set: material {self.names[row]!r} has non-finite weights")


@dataclass(frozen=True)
class TrainingData:
    """What a generator learns from: one split's materials.

    `load(name)` reads one material (a MERL table); `weights(names)` returns their aligned
    NBRDF weight vectors where the dataset provides them (None: it does not).
    """

    names: tuple[str, ...]
    load: Callable[[str], Material]
    categories: Mapping[str, str] = field(default_factory=dict)
    weight_source: Callable[[tuple[str, ...]], WeightSet] | None = None
    dataset: str = ""

    def __len__(self) -> int:
        return len(self.names)

    def tables(self) -> Iterator[Material]:
        """The split's materials, loaded one at a time (a full table is 35 MB)."""
        return (self.load(n) for n in self.names)

    @property
    def has_weights(self) -> bool:
        return self.weight_source is not None

    def weights(self) -> WeightSet:
        """The split's NBRDF weight vectors (fitted and cached by the dataset on first use)."""
        if self.weight_source is None:
            raise DataError(f"dataset {self.dataset or '?'!r} provides no NBRDF weight vectors; a generator that "
                            "learns from NBRDF weights needs dataset=neumerl")
        ws = self.weight_source(self.names)
        if ws.names != self.names:
            raise DataError(f"dataset {self.dataset!r}: weight vectors came back for other materials than asked")
        return ws


class SampleSet(Sequence):
    """n generated materials: `set[i]` builds sample i as a fitted Representation.

    Subclasses implement `_build(i)`; `array` holds the raw per-sample parameters (n, ...)
    and `representation` names the plugin each sample is an instance of (for saving and
    rendering). Samples with a non-finite parameter are not built: `finite` marks them,
    and `set[i]` of one raises, naming the sample.
    """

    #: the registered representation the samples are instances of
    representation: str = ""

    def __init__(self, array: torch.Tensor):
        if not isinstance(array, torch.Tensor) or array.ndim < 2:
            raise TypeError(f"a sample set's array must be a tensor (n, ...), got {type(array).__name__}")
        self.array = array

    def __len__(self) -> int:
        return int(self.array.shape[0])

    @property
    def finite(self) -> torch.Tensor:
        """(n,) bool: every parameter of the sample is finite."""
        return torch.isfinite(self.array.reshape(len(self), -1)).all(dim=1)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        if not isinstance(i, (int, np.integer)) or isinstance(i, bool):
            raise TypeError(f"sample index must be an integer, got {i!r}")
        i = int(i)
        if not -len(self) <= i < len(self):
            raise IndexError(f"sample {i} of a set of {len(self)}")
        i %= len(self)
        if not bool(self.finite[i]):
            raise ValueError(f"sample {i} has non-finite parameters; it cannot be built")
        return self._build(i)

    @abstractmethod
    def _build(self, i: int) -> Representation:
        """Sample i (finite) as a fitted representation."""


def available_memory() -> int:
    """Bytes this process can still allocate: MemAvailable (Linux), else physical memory."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 2**63 - 1


#: Share of the available memory a sample set may take.
MEMORY_SHARE = 0.5


class Generator(Placed, ABC):
    """Base class for material generators; see the module docstring.

    Subclasses implement `fit`, `_sample`, `sample_nbytes`, `state_dict` / `from_state`;
    `params` are the constructor keyword arguments, recorded with saved generators and
    results.
    """

    #: Capability tags the conformance kit reads (e.g. "conditional").
    tags: ClassVar[frozenset[str]] = frozenset()
    #: "tables" or "nbrdf": what `fit` reads from its TrainingData.
    learns_from: ClassVar[str] = "tables"

    def __init__(self, **params: Any):
        self.params = dict(params)

    # -- learning ----------------------------------------------------------------
    @abstractmethod
    def fit(self, data: TrainingData, *, seed: int = 0, progress: bool | str = False) -> "Generator":
        """Learn from a training split; returns self. `progress`: show a bar (a str is its label)."""

    @property
    def fitted(self) -> bool:
        """True once fitted or loaded."""
        return bool(self.state_dict())

    # -- sampling ----------------------------------------------------------------
    def sample(self, n: int, condition: Any = None, *, seed: int = 0) -> SampleSet:
        """n new materials, deterministic for a seed. n ≤ 0 and a set larger than the memory
        this machine has free are refused before anything is allocated."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ConfigError(f"{type(self).__name__}.sample: n={n!r} must be a positive integer")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ConfigError(f"{type(self).__name__}.sample: seed={seed!r} must be a non-negative integer")
        if condition is not None and "conditional" not in self.tags:
            raise ConfigError(f"{type(self).__name__} is unconditional: condition must be None")
        if not self.fitted:
            raise RuntimeError(f"{type(self).__name__}: fit() or load before sample()")
        need = self.sample_nbytes(int(n))
        free = available_memory()
        if need > MEMORY_SHARE * free:
            raise ResourceError(
                f"{type(self).__name__}.sample: n={n} samples need about {_size(need)}, more than "
                f"{MEMORY_SHARE:.0%} of the {_size(free)} this machine has free; sample fewer at a time"
            )
        return self._sample(int(n), condition, int(seed))

    @abstractmethod
    def _sample(self, n: int, condition: Any, seed: int) -> SampleSet:
        """n samples (n ≥ 1, memory already checked)."""

    @abstractmethod
    def sample_nbytes(self, n: int) -> int:
        """Estimated peak bytes that sampling n materials allocates (checked before sampling)."""

    def preflight(self) -> None:
        """Check what the parameters name outside this process (a file to start from) before
        any work, so a sweep's validation finds it; raise a BrdfbenchError naming the key."""

    # -- persistence ---------------------------------------------------------------
    @abstractmethod
    def state_dict(self) -> dict[str, torch.Tensor]:
        """Every tensor needed to rebuild the fitted generator (empty before a fit)."""

    def metadata(self) -> dict[str, Any]:
        """JSON-able extras saved beside the tensors; an iterative fit's curves under
        TRAINING_CURVE_KEY."""
        return {}

    @classmethod
    @abstractmethod
    def from_state(cls, params: dict[str, Any], tensors: dict[str, torch.Tensor], metadata: dict[str, Any]) -> "Generator":
        """Rebuild a fitted generator from `state_dict()` and `metadata()`; tensors that do
        not match the params are a ModelFileError naming the tensor."""

    # -- cost --------------------------------------------------------------------
    @property
    def nbytes(self) -> int:
        """Bytes of the fitted generator's parameters."""
        return sum(t.numel() * t.element_size() for t in self.state_dict().values())


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n} B"


def seeded_split(names: Sequence[str], test_fraction: float, seed: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(train, test): a seeded random `test_fraction` of `names` held out (at least one
    material on each side), each side in the names' order."""
    n = len(names)
    if n < 2:
        raise ConfigError(f"a train/test split needs at least 2 materials, got {n}")
    if not 0 < test_fraction < 1:
        raise ConfigError(f"test_fraction={test_fraction!r} must lie strictly between 0 and 1")
    n_test = min(n - 1, max(1, int(math.floor(test_fraction * n + 0.5))))
    order = torch.randperm(n, generator=torch.Generator().manual_seed(int(seed))).tolist()
    held = set(order[:n_test])
    return (tuple(m for i, m in enumerate(names) if i not in held), tuple(m for i, m in enumerate(names) if i in held))
