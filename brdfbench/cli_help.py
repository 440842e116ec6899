"""The text of `brdfbench --help`: how to run the benchmark, and the packaged config groups.

The groups and their options are read from the packaged configs (`brdfbench_conf`), so
the help lists what `brdfbench GROUP=OPTION` accepts without composing a config or
importing Hydra.
"""

from __future__ import annotations

import textwrap
from importlib import resources
from typing import Any

#: The subcommands of `brdfbench` (anything else is a benchmark run's overrides).
SUBCOMMANDS = ("list", "report", "merge", "check", "inspect", "convert", "synthesize")

CONF_PACKAGE = "brdfbench_conf"
GROUPS = ("representation", "dataset", "harness", "scene")
WIDTH = 100

USAGE = """\
brdfbench [-m] [GROUP=OPTION | KEY=VALUE ...]   run the benchmark (Hydra overrides)
       brdfbench SUBCOMMAND [ARGS]                    a utility (brdfbench SUBCOMMAND --help)
       brdfbench --version | --help | --hydra-help"""

EXAMPLES = """\
running the benchmark:
  brdfbench                                         {default_run}
  brdfbench representation=lambert                  one representation, on the default dataset
  brdfbench -m representation=merl,lambert          a sweep (Hydra multirun)
  brdfbench dataset=merl_folder dataset.params.path=/data/merl
                                                    your MERL .binary files
  brdfbench dataset.params.size=small harness=quick limit=3
                                                    a smoke run
  Rows go to RESULTS_DIR/brdfbench.sqlite and RESULTS_DIR/leaderboard.md (results_dir=results);
  cells already in the store are skipped."""

FOOTER = """\
other keys: {keys}
  A group's own keys are set as GROUP.KEY=VALUE (e.g. dataset.params.size=small).
  Hydra's own help: brdfbench --hydra-help; the composed config: brdfbench --cfg job."""


def _load_yaml(resource) -> Any:
    import yaml  # PyYAML, a dependency of omegaconf

    try:
        return yaml.safe_load(resource.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return None


def _summary(resource) -> str:
    """The first comment line of a config file: its one-line description."""
    try:
        lines = resource.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return ""
    for line in lines:
        if line.startswith("# @package"):  # a Hydra directive, not a description
            continue
        if line.startswith("#"):
            return line.lstrip("#").strip()
        if line.strip():
            break
    return ""


def _defaults(root: dict) -> dict[str, str]:
    """group -> default option, from the `defaults` list of config.yaml."""
    chosen = {}
    for item in root.get("defaults") or []:
        if isinstance(item, dict):
            for group, option in item.items():
                if isinstance(group, str) and isinstance(option, str):
                    chosen[group] = option
    return chosen


def _default_sweep(root: dict) -> str:
    params = ((root.get("hydra") or {}).get("sweeper") or {}).get("params") or {}
    sweep = " ".join(f"{k}={v}" for k, v in params.items())
    return f"the default benchmark, a sweep of\n      {sweep}" if sweep else "the default benchmark"


def _group_lines(conf, group: str, default: str | None) -> list[str]:
    folder = conf / group
    if not folder.is_dir():
        return []
    options = sorted((r for r in folder.iterdir() if r.name.endswith(".yaml")), key=lambda r: r.name)
    lines = [f"  {group}=OPTION" + (f" (default {default})" if default else "")]
    for resource in options:
        name = resource.name[: -len(".yaml")]
        summary = _summary(resource)
        head = f"    {name:20s}" if len(name) < 20 else f"    {name}  "
        lines.append(head + textwrap.shorten(summary, WIDTH - len(head), placeholder=" ...") if summary else head.rstrip())
    return lines


def config_help() -> str:
    """Everything below the subcommands: running the benchmark, then the config groups."""
    conf = resources.files(CONF_PACKAGE)
    root = _load_yaml(conf / "config.yaml")
    root = root if isinstance(root, dict) else {}
    defaults = _defaults(root)
    parts = [EXAMPLES.format(default_run=_default_sweep(root)), "", "config groups (GROUP=OPTION):"]
    for group in GROUPS:
        parts.extend(_group_lines(conf, group, defaults.get(group)))
    keys = [k for k in root if k not in ("defaults", "hydra")]
    parts += ["", FOOTER.format(keys=", ".join(keys) or "none")]
    return "\n".join(parts)
