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

import sys

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin

from brdfbench.hydra.packages import ENTRY_POINT_GROUP, PRIMARY, config_packages, package_dir

__all__ = ["ENTRY_POINT_GROUP", "PRIMARY", "PROVIDER", "BrdfbenchSearchPathPlugin", "config_packages"]

PROVIDER = "brdfbench-searchpath-plugin"


def _normal(path: str) -> str:
    return path.rstrip("/")


def _warn(message: str) -> None:
    print(f"brdfbench: warning: {message}", file=sys.stderr)


class BrdfbenchSearchPathPlugin(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        paths = {_normal(element.path) for element in search_path.get_path()}
        if f"pkg://{PRIMARY}" not in paths:
            return  # another Hydra app: leave its search path alone
        for name, package in config_packages():
            path = f"pkg://{package}"
            if path in paths:
                continue
            if package_dir(package) is None:
                _warn(f"entry point {ENTRY_POINT_GROUP}:{name} names {package!r}, which is not an "
                      "importable package; its configs are skipped")
                continue
            search_path.append(provider=f"{PROVIDER}:{name}", path=path)
            paths.add(path)
