"""Config-group choices checked before Hydra runs: `profile=nope` is one line naming the
group and what it offers, exit 2, instead of Hydra's multi-line report and exit 1.

The options come from Hydra's own config search path (the packaged conf, third-party
config packages, a `hydra.searchpath` override), so a choice Hydra would find passes.
Overrides Hydra cannot parse are left to Hydra, which names them itself.
"""

from __future__ import annotations

from .errors import ConfigError


def _values(override) -> list[str]:
    """The plain string choices of a group override (each element of a choice sweep)."""
    if override.is_sweep_override():
        if not override.is_choice_sweep():
            return []
        values = list(override.sweep_string_iterator())
    else:
        values = [override.get_value_string()]
    return [v for v in values if isinstance(v, str) and v not in ("null", "")]


def check_group_choices(overrides: list[str]) -> None:
    """Raise ConfigError naming the first group choice no config source provides."""
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException:
        return  # Hydra reports its own parse errors
    if any(o.key_or_group == "hydra.searchpath" for o in parsed):
        return  # a user's extra config folders: Hydra resolves them
    groups = [o for o in parsed if not o.is_delete() and o.package is None and not o.key_or_group.startswith("hydra")]
    if not groups or GlobalHydra.instance().is_initialized():
        return  # nothing to check, or inside a caller's Hydra context: leave it to Hydra
    from hydra._internal.config_repository import CachingConfigRepository, ConfigRepository

    with initialize_config_module("brdfbench_conf", version_base="1.3"):
        search_path = GlobalHydra.instance().config_loader().get_search_path()
        repo = CachingConfigRepository(ConfigRepository(config_search_path=search_path))
        for o in groups:
            group = o.key_or_group
            if not repo.group_exists(group):
                continue  # a config key, not a group
            options = sorted(set(repo.get_group_options(group)))
            for value in _values(o):
                if value not in options:
                    raise ConfigError(f"{group}={value!r}: no such {group} config; expected one of {', '.join(options)}")
