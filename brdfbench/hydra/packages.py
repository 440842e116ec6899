"""The packages that hold brdfbench's Hydra config groups: its own, then those a third party
names in the `brdfbench.conf` entry-point group, in Hydra's search-path order.

One list for both readers: the search-path plugin (`hydra_plugins/brdfbench_searchpath`),
which appends them to Hydra's search path, and `pipeline.harness_defaults`, which reads a
harness option without composing Hydra; both must find the same option first.
"""

from __future__ import annotations

import importlib.util
from importlib.metadata import entry_points
from pathlib import Path

ENTRY_POINT_GROUP = "brdfbench.conf"
PRIMARY = "brdfbench_conf"


def config_packages() -> list[tuple[str, str]]:
    """(entry-point name, package) for every `brdfbench.conf` entry point, in a stable
    order (by name), without duplicates and without brdfbench's own primary package."""
    seen: set[str] = {PRIMARY}
    found: list[tuple[str, str]] = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: (e.name, e.value)):
        package = ep.value.split(":", 1)[0].strip()
        if package in seen:
            continue
        seen.add(package)
        found.append((ep.name, package))
    return found


def package_dir(package: str) -> Path | None:
    """The folder of an importable regular or namespace package, found without importing
    it; None where there is none."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):  # a parent package that does not import, an empty name
        return None
    if spec is None or spec.submodule_search_locations is None:
        return None
    return next((Path(p) for p in spec.submodule_search_locations), None)


def search_path() -> list[Path]:
    """The folders of brdfbench's config package and of every importable third-party one,
    first to last."""
    dirs = [package_dir(PRIMARY), *(package_dir(package) for _, package in config_packages())]
    return [d for d in dirs if d is not None]
