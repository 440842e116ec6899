"""The core names no built-in plugin: no string in `brdfbench/` (docstrings aside) is the name of
a plugin that a built-in plugin package registers, so the core depends on plugins only through
protocols, spec fields and configuration, as `test_imports` makes sure it never imports one.

Read statically with `ast`. A name the core itself registers in some group (the core's own
samplers share names with analytic representations: `ggx`, `phong`, …) is the core's own and
may be written. Strings that merely spell like a plugin but mean something else are listed in
`NOT_PLUGINS`, each with what it means; an entry that no longer matches fails too.
"""

from __future__ import annotations

import ast
from importlib.metadata import entry_points
from pathlib import Path

from brdfbench.plugins.registry import GROUPS

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "brdfbench"

#: (core module, string) -> what the string means there
NOT_PLUGINS = {
    ("data/merl_folder.py", "merl"): "the category of materials read from a MERL folder",
    ("data/nbrdf_release.py", "merl"): "the subset of the published NBRDF networks fitted to MERL",
    ("data/synthetic.py", "sgd"): "the lobe shape of a synthetic material (Bagher et al.'s SGD distribution)",
    ("protocols/generator.py", "nbrdf"): "what a generator learns from: aligned NBRDF weight vectors",
    ("distances/brdf.py", "l1"): "a kind of BRDF-space distance between two sets (Zhou et al. eq. 6), not the metric",
    ("distances/brdf.py", "l1_log"): "a kind of BRDF-space distance between two sets, not the metric",
    ("distances/brdf.py", "l1_log_cos"): "a kind of BRDF-space distance between two sets (Hu 2026 eq. 4.12), not the metric",
}


def _registered() -> tuple[dict[str, set[str]], set[str]]:
    """(plugin name -> groups, from built-in plugin packages), names the core registers."""
    plugins: dict[str, set[str]] = {}
    core: set[str] = set()
    for group in GROUPS:
        for ep in entry_points(group=f"brdfbench.{group}"):
            module = ep.value.split(":", 1)[0]
            if module.startswith("brdfbench."):
                core.add(ep.name)
            elif module.startswith("brdfbench_"):
                plugins.setdefault(ep.name, set()).add(group)
    return plugins, core


def _docstrings(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def named_builtins() -> dict[tuple[str, str], list[int]]:
    """(core module, plugin name) -> lines, for every string naming a built-in plugin."""
    plugins, core = _registered()
    named = set(plugins) - core
    found: dict[tuple[str, str], list[int]] = {}
    for path in sorted(CORE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        skip = _docstrings(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip \
                    and node.value in named:
                found.setdefault((path.relative_to(CORE).as_posix(), node.value), []).append(node.lineno)
    return found


def test_the_scan_sees_the_built_in_plugins():
    plugins, core = _registered()
    assert {"representations", "generators", "metrics", "reports"} <= set().union(*plugins.values())
    assert core, "no plugin registered by the core itself"


def test_the_core_names_no_built_in_plugin():
    found = named_builtins()
    offending = {k: v for k, v in found.items() if k not in NOT_PLUGINS}
    assert not offending, "the core names built-in plugins (use a protocol, a spec field or the config): " + "; ".join(
        f"brdfbench/{module}:{lines[0]} {name!r}" for (module, name), lines in sorted(offending.items()))
    stale = set(NOT_PLUGINS) - set(found)
    assert not stale, f"NOT_PLUGINS entries that no longer match: {sorted(stale)}"
