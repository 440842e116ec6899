"""Hydra search-path plugin: config groups shipped by installed third-party packages.

A distribution adds its own `representation/*.yaml` (or `dataset/`, `harness/`, `scene/`,
any group) to `brdfbench GROUP=OPTION` by naming the package that holds those folders in
the `brdfbench.conf` entry-point group:

    [project.entry-points."brdfbench.conf"]
    acme = "acme_brdf_conf"          # an importable package: acme_brdf_conf/representation/x.yaml

Each such package is appended to Hydra's search path as `pkg://<package>`, after
brdfbench's own `pkg://brdfbench_conf`: a third party adds options but cannot replace a
built-in one of the same name (the first path that has `GROUP/OPTION.yaml` wins).
Editable installs work as regular ones do (the package is found by import).

`hydra_plugins` is a namespace package shared by every Hydra plugin: it has no
`__init__.py`; this module is found by Hydra's plugin scan. The paths are added only to
brdfbench's own app (a search path whose primary config is `pkg://brdfbench_conf`), never
to another Hydra application installed in the same environment.
"""

from __future__ import annotations

import importlib.util
import sys
from importlib.metadata import entry_points

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin

ENTRY_POINT_GROUP = "brdfbench.conf"
PRIMARY = "brdfbench_conf"
PROVIDER = "brdfbench-searchpath-plugin"


def _normal(path: str) -> str:
    return path.rstrip("/")


def _warn(message: str) -> None:
    print(f"brdfbench: warning: {message}", file=sys.stderr)


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


def _importable(package: str) -> bool:
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):  # a parent package that does not import, an empty name
        return False
    return spec is not None and spec.submodule_search_locations is not None


class BrdfbenchSearchPathPlugin(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        paths = {_normal(element.path) for element in search_path.get_path()}
        if f"pkg://{PRIMARY}" not in paths:
            return  # another Hydra app: leave its search path alone
        for name, package in config_packages():
            path = f"pkg://{package}"
            if path in paths:
                continue
            if not _importable(package):
                _warn(f"entry point {ENTRY_POINT_GROUP}:{name} names {package!r}, which is not an "
                      "importable package; its configs are skipped")
                continue
            search_path.append(provider=f"{PROVIDER}:{name}", path=path)
            paths.add(path)
