"""The command line checked before Hydra runs, so a typo is one line with a suggestion and
exit 2 (as brdfbench's own errors are) instead of Hydra's multi-line report and exit 1:

- a word that is neither a subcommand nor KEY=VALUE (`reprot`);
- an override Hydra's grammar cannot parse (`limit=[1`);
- a config-group choice no config source provides (`representation=lambrt`);
- a key the composed config does not have (`limt=1`, `dataset.params.sise=small`).

The options come from Hydra's own config search path (the packaged conf, third-party
config packages, a `hydra.searchpath` override), so a choice Hydra would find passes.
Keys are checked by composing the config with the command line's plain overrides, as
Hydra composes its primary config (sweeps are checked per job by the sweep's validation).
"""

from __future__ import annotations

import difflib
import re

from ..errors import ConfigError


def _suggest(value: str, options, what: str = "") -> str:
    """"; did you mean X?" for the closest of `options`, or ""."""
    close = difflib.get_close_matches(value, list(options), n=1, cutoff=0.6)
    return f"; did you mean {what}{close[0]}?" if close else ""


def check_words(argv: list[str], subcommands: tuple[str, ...], keys: tuple[str, ...]) -> None:
    """Refuse a word that is not an override (KEY=VALUE, ~KEY) or a flag, suggesting the
    subcommand or key it was probably meant to be."""
    for word in argv:
        if word.startswith("-") or "=" in word or word.startswith("~"):
            continue
        if word in keys:
            raise ConfigError(f"{word!r} is a config key without a value: write {word}=VALUE")
        hint = _suggest(word, subcommands) or (_suggest(word, keys) and _suggest(word, keys)[:-1] + "=VALUE?")
        raise ConfigError(f"{word!r} is neither a subcommand ({', '.join(subcommands)}) nor an override KEY=VALUE{hint}")


def _parse_error(overrides: list[str]) -> str:
    """The first override Hydra's grammar refuses, with its reason, in one line."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    parser = OverridesParser.create()
    for text in overrides:
        try:
            parser.parse_overrides([text])
        except HydraException as exc:
            reason = next((line.strip() for line in str(exc).splitlines()[1:] if line.strip() and "hydra.cc" not in line), "")
            return f"cannot read the override {text!r}" + (f": {reason}" if reason else "") + \
                " (overrides are KEY=VALUE in Hydra's override grammar; quote lists and brackets for the shell)"
    return "cannot read the overrides"


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
        raise ConfigError(_parse_error(overrides)) from None
    if any(o.key_or_group == "hydra.searchpath" for o in parsed):
        return  # a user's extra config folders: Hydra resolves them
    groups = [o for o in parsed if not o.is_delete() and o.package is None and not o.key_or_group.startswith("hydra")]
    if not groups or GlobalHydra.instance().is_initialized():
        return  # nothing to check, or inside a caller's Hydra context: leave it to Hydra
    from hydra import compose
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
                    raise ConfigError(f"{group}={value!r}: no such {group} config{_suggest(value, options, f'{group}=')} "
                                      f"(expected one of {', '.join(options)})")
        plain = [o for o in parsed if not o.is_sweep_override() and not o.key_or_group.startswith("hydra")]
        _check_keys(compose, [o.input_line for o in plain if o.input_line])


def _chain_text(exc: BaseException) -> str:
    """The text of an exception and of its causes (Hydra puts the key in the cause)."""
    text, cause = str(exc), exc.__cause__ or exc.__context__
    while cause is not None:
        text += "\n" + str(cause)
        cause = cause.__cause__ or cause.__context__
    return text


def missing_key(exc: BaseException) -> str | None:
    """The full key a Hydra composition error says the config lacks, or None."""
    found = re.search(r"full_key: (\S+)", _chain_text(exc)) or re.search(r"Key '([^']+)' is not in struct", _chain_text(exc))
    return found.group(1) if found else None


def compose_error_line(exc: BaseException) -> str:
    """One line for a Hydra composition error."""
    full = missing_key(exc)
    if full:
        parent, _, leaf = full.rpartition(".")
        return f"{full}: {parent or 'the config'} has no key {leaf!r}"
    return next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)


def _check_keys(compose, overrides: list[str]) -> None:
    """Compose the config with `overrides`; a key it lacks is one line naming it, the closest
    key at that level, and the keys there."""
    from omegaconf import DictConfig

    try:
        compose("config", overrides=overrides)
        return
    except Exception as exc:  # Hydra's composition errors: several lines, the key among them (or in their cause)
        full = missing_key(exc)
        if not full:
            raise ConfigError(compose_error_line(exc)) from None
    parent, _, leaf = full.rpartition(".")
    rest = [o for o in overrides if o.split("=", 1)[0].lstrip("+~") != full]
    try:
        node = compose("config", overrides=rest)
        for part in filter(None, parent.split(".")):
            node = node[part]
        keys = sorted(node.keys()) if isinstance(node, DictConfig) else []
    except Exception:  # the rest does not compose either: name the key alone
        keys = []
    where = f"{parent}" if parent else "the config"
    hint = _suggest(leaf, keys, f"{parent}." if parent else "")
    listed = f" ({where} has: {', '.join(map(str, keys))})" if keys else ""
    new = f"; a plugin parameter the config does not list is added with +{full}=VALUE" if parent.endswith("params") else ""
    raise ConfigError(f"{full}: {where} has no key {leaf!r}{hint}{listed}{new}")
