"""What the pipeline and the reports need of a results store, whatever holds it.

The built-in backend is one SQLite file per results folder (`brdfbench.store.sqlite.ResultsStore`,
plugin `sqlite`). Another backend (a database server for many hosts writing at once, say)
registers a `StoreSpec` in the `brdfbench.stores` entry-point group whose target, called
as `target(results_dir, create=True, **params)`, returns a `Store` (with `create=False`
it must raise a DataError where no store exists yet: reports and merges only read); `store=<name>` and
`store_params.<key>=...` choose it. Its contract is the one `write_cell` states: a cell is
(config hash, dataset fingerprint, scope, material), written whole in one transaction, a
finished cell is never replaced (the first complete writer wins), a failed one is.

`merge` copies every configuration, environment and cell of one store into another under
that contract, so stores written apart (one per node of a cluster) combine into one
without duplicates, whichever order they are merged in.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator

from .schema import UNKNOWN_ENV
from ..errors import ConfigError
from ..plugins import registry

if TYPE_CHECKING:  # the protocol and its records import no pandas; a backend's frame() does
    import pandas as pd


@dataclass(frozen=True)
class Row:
    run_id: str
    config_hash: str
    dataset: str
    dataset_fingerprint: str
    material: str  # the material, or the set's name for scope="set"
    category: str  # the material's category; for a set's per-category count, the category counted
    metric: str
    value: float | None
    unit: str
    higher_is_better: bool
    status: str  # "ok" or "failed"
    message: str
    seed: int
    package_version: str
    git_sha: str
    timestamp: float
    scene: str = "brdf_space"  # the scene the metric was measured in (brdf_space: no rendering)
    sampler: str = ""  # the importance sampler of a Monte Carlo figure, else ""
    spp: int = 0  # samples per pixel of a per-rung figure (convergence), else 0
    scope: str = "material"  # "material": one material's figure; "set": a whole set's
    env_id: str = UNKNOWN_ENV
    concurrent_jobs: int = 1  # brdfbench cells running on this host while this one ran (itself included)
    distance: str = ""  # the distance a set-level figure is computed over (e.g. MMD over "l1"), else ""


@dataclass(frozen=True)
class ConfigRecord:
    config_hash: str
    label: str
    plugin: str
    plugin_version: str
    harness: str
    params: dict[str, Any]


@dataclass(frozen=True)
class Environment:
    env_id: str
    host: str
    cpu_model: str
    cpu_count: int
    threads: int
    launcher: str
    platform: str
    device: str = "cpu"  # where the figures were computed: "cpu" or "cuda:N"
    device_detail: str = "cpu"  # a GPU's model, memory, capability, driver, CUDA and torch versions


#: The columns of a cell's key.
CELL = ("config_hash", "dataset_fingerprint", "scope", "material")


class Store(ABC):
    """A results store: configurations, environments and cells, with the cell contract above."""

    #: Where the store is, for messages and reports (a file path, a server address).
    location: str

    @abstractmethod
    def write_config(self, record: ConfigRecord) -> None:
        """Record what a config hash stands for (the label follows the latest run)."""

    @abstractmethod
    def write_environment(self, env: Environment) -> None:
        """Record an environment once (its id is a hash of its fields)."""

    @abstractmethod
    def done_cells(self, config_hash: str, dataset_fingerprint: str, scope: str = "material") -> set[str]:
        """Materials (or sets) of this configuration and data that hold successful rows."""

    @abstractmethod
    def write_cell(self, rows: list[Row]) -> bool:
        """Write one cell's rows in one transaction; False when the cell was already done."""

    @abstractmethod
    def frame(self, **where: Any) -> pd.DataFrame:
        """All rows joined with their configuration and environment (see ResultsStore.frame)."""

    @abstractmethod
    def configs(self) -> list[ConfigRecord]:
        """Every configuration recorded."""

    @abstractmethod
    def environments(self) -> list[Environment]:
        """Every environment recorded."""

    @abstractmethod
    def cells(self) -> Iterator[list[Row]]:
        """Every cell's rows, one list per cell."""

    def has_cell(self, config_hash: str, dataset_fingerprint: str, material: str, scope: str = "material") -> bool:
        return material in self.done_cells(config_hash, dataset_fingerprint, scope)


def merge(source: Store, into: Store) -> dict[str, int]:
    """Copy `source` into `into`: configurations, environments, then every cell through
    `write_cell` (a cell finished in `into` stays; a failed one there is replaced by a
    finished one). Returns how many cells were written and kept."""
    for record in source.configs():
        into.write_config(record)
    for env in source.environments():
        into.write_environment(env)
    counts = {"written": 0, "kept": 0}
    for rows in source.cells():
        written = into.write_cell(rows)
        counts["written" if written else "kept"] += 1
    return counts


def open_store(name: str, results_dir: str | Path, params: dict[str, Any] | None = None) -> Store:
    """The store plugin `name` (group `stores`) opened for `results_dir`."""
    factory = registry.get("stores", name).load()
    try:
        store = factory(Path(results_dir), **(params or {}))
    except TypeError as exc:
        raise ConfigError(f"store={name}: bad store_params {params or {}} ({exc})") from None
    if not isinstance(store, Store):
        raise ConfigError(f"store plugin {name!r} returned a {type(store).__name__}, not a "
                          "brdfbench.store.protocol.Store")
    return store
