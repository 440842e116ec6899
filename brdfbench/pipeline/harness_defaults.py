"""A harness kind's shipped defaults, read from the Hydra config group without composing it.

`harness_config(kind)` (the Python API, a `RunConfig`'s default, tests) starts from the same
values as `brdfbench harness=<kind>`, so that defaults such as the metrics a harness scores
are written once, in the configuration, and the core names no metric. The option read is
`harness/<kind>.yaml` of brdfbench's config package, else of the first package of a
`brdfbench.conf` entry point that has it (Hydra's search-path order: `conf_packages`). Its
defaults list may name other options of the group (merged first, or where `_self_` says);
an option `# @package _global_` gives its `harness` mapping. A kind with no option takes its Config dataclass's defaults.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

from ..hydra.packages import search_path
from ..errors import ConfigError

GROUP = "harness"


def _config_dirs() -> list[Path]:
    """The `harness/` folders of the config packages, in the search path's order."""
    return [d / GROUP for d in search_path() if (d / GROUP).is_dir()]


def _find(option: str) -> Path | None:
    return next((d / f"{option}.yaml" for d in _config_dirs() if (d / f"{option}.yaml").is_file()), None)


def _read(path: Path, seen: tuple[str, ...]) -> dict[str, Any]:
    text = path.read_text(encoding="utf-8")
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a harness option must be a mapping, not {type(data).__name__}")
    defaults = data.pop("defaults", [])
    if any(line.strip() == "# @package _global_" for line in text.splitlines()[:5]):
        data = data.get(GROUP) or {}
    merged: dict[str, Any] = {}
    placed_self = False
    for entry in defaults:
        if entry == "_self_":
            merged.update(data)
            placed_self = True
        elif isinstance(entry, str) and "/" not in entry and ":" not in entry:
            if entry in seen:
                raise ConfigError(f"{path}: harness option {entry!r} includes itself through its defaults list")
            found = _find(entry)
            if found is None:
                raise ConfigError(f"{path}: defaults list names harness option {entry!r}, which is not shipped")
            merged.update(_read(found, (*seen, entry)))
        # entries for other groups (overrides of /dataset, …) set no harness key
    if not placed_self:  # Hydra's default: the option's own keys after its defaults list
        merged.update(data)
    return merged


@lru_cache(maxsize=None)
def _shipped(kind: str) -> tuple[tuple[str, Any], ...]:
    path = _find(kind)
    if path is None:
        return ()
    return tuple(_read(path, (kind,)).items())


def unset_nulls(harness: dict[str, Any]) -> dict[str, Any]:
    """`harness` with the null entries of its `sampler_params` left out: an option declares
    such keys (`sampler_params.alpha: null`) to show them, not to pass them. The CLI and
    `shipped_defaults` both read options through this."""
    if isinstance(harness.get("sampler_params"), dict):
        harness["sampler_params"] = {k: v for k, v in harness["sampler_params"].items() if v is not None}
    return harness


def shipped_defaults(kind: str) -> dict[str, Any]:
    """The keys and values `harness=<kind>` sets (without `kind`, nulls unset as the CLI
    unsets them); {} where none is shipped."""
    values = {k: (list(v) if isinstance(v, list) else dict(v) if isinstance(v, dict) else v)
              for k, v in _shipped(kind) if k != "kind"}
    return unset_nulls(values)
