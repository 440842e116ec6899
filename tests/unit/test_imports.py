"""The import graph: the core imports no built-in plugin, and no module imports itself back.

Read statically with `ast` from every .py file, imports inside functions included (a lazy
import still couples two modules), and those under `if TYPE_CHECKING:` too. A plugin is
found through the registry's entry points; the core must never name one. A
cycle, even through a lazy import, means two modules share something that belongs in a
third module both import.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

from graphs import cycles  # noqa: E402  (tests/tools: one cycle finder for imports and calls)

ROOT = Path(__file__).resolve().parents[2]
CORE = "brdfbench"
#: The built-in plugin packages, by import name, and their folders (pyproject's package-dir).
PLUGINS = {"brdfbench_representations": "representations", "brdfbench_generators": "generators",
           "brdfbench_metrics": "metrics", "brdfbench_leaderboard": "leaderboard"}

#: Core modules allowed to import a built-in plugin, and import cycles allowed: none. Kept
#: as (empty) allow-lists so that a future exception is explicit and reviewed.
PENDING: set[str] = set()
PENDING_CYCLES: set[frozenset[str]] = set()


# --------------------------------------------------------------------------- the walker


def modules_under(folder: Path, package: str) -> dict[str, Path]:
    """Dotted module name -> file, for every .py file under `folder` (imported as `package`)."""
    out = {}
    for path in sorted(folder.rglob("*.py")):
        parts = list(path.relative_to(folder).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join([package, *parts])] = path
    return out


def _is_package(module: str, path: Path) -> bool:
    return path.name == "__init__.py"


def imported_names(module: str, path: Path) -> list[tuple[str, int]]:
    """(absolute dotted name, line) of everything `path` imports, wherever in the file; for
    `from X import a`, both X and X.a (X.a is a module or a name in X; the caller decides)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if _is_package(module, path) else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found.append((base, node.lineno))
            found += [(f"{base}.{alias.name}", node.lineno) for alias in node.names if alias.name != "*"]
    return found


def import_graph(modules: dict[str, Path]) -> dict[str, dict[str, int]]:
    """module -> {imported module among `modules`: first line}. Importing a.b.c runs the
    packages a and a.b first, so those count as imported too, except the importer's own
    ancestors: Python initialises them before the importer, so they close no cycle."""
    graph: dict[str, dict[str, int]] = {}
    for module, path in modules.items():
        parts = module.split(".")
        ancestors = {".".join(parts[:i]) for i in range(1, len(parts) + 1)}
        edges: dict[str, int] = {}
        for name, line in imported_names(module, path):
            parts = name.split(".")
            for i in range(1, len(parts) + 1):
                target = ".".join(parts[:i])
                if target in modules and target not in ancestors:
                    edges.setdefault(target, line)
        graph[module] = edges
    return graph


def plugin_imports(modules: dict[str, Path], plugins=tuple(PLUGINS)) -> dict[str, list[str]]:
    """module -> ['line N: plugin.module', ...] for every import of a plugin package."""
    out: dict[str, list[str]] = {}
    for module, path in modules.items():
        seen: list[tuple[str, int]] = []
        for name, line in imported_names(module, path):
            if name.split(".")[0] in plugins and not any(n2 == line and name.startswith(n1 + ".") for n1, n2 in seen):
                seen.append((name, line))
                out.setdefault(module, []).append(f"line {line}: {name}")
    return out


def describe(component: list[str], graph: dict[str, dict[str, int]], modules: dict[str, Path]) -> str:
    members = set(component)
    edges = [f"{a} -> {b} ({modules[a].relative_to(ROOT) if modules[a].is_relative_to(ROOT) else modules[a]}:{line})"
             for a in component for b, line in sorted(graph[a].items()) if b in members]
    return "\n  ".join(edges)


# --------------------------------------------------------------------------- the rules


def _core() -> dict[str, Path]:
    return modules_under(ROOT / "brdfbench", CORE)


def test_the_core_imports_no_builtin_plugin():
    found = plugin_imports(_core())
    stale = sorted(PENDING - set(found))
    unexpected = {m: hits for m, hits in found.items() if m not in PENDING}
    assert not unexpected, "core modules import built-in plugins (find them through the registry):\n" + "\n".join(
        f"  {m}: {', '.join(hits)}" for m, hits in sorted(unexpected.items()))
    assert not stale, f"PENDING lists modules that no longer import a plugin; remove them: {stale}"


def test_no_import_cycles_in_the_core_and_the_plugin_packages():
    modules = dict(_core())
    for package, folder in PLUGINS.items():
        modules.update(modules_under(ROOT / folder, package))
    graph = import_graph(modules)
    found = cycles(graph)
    unexpected = [c for c in found if frozenset(c) not in PENDING_CYCLES]
    stale = [sorted(c) for c in PENDING_CYCLES - {frozenset(c) for c in found}]
    assert not unexpected, "import cycles (module-level and lazy imports):\n" + "\n".join(
        f"- {' <-> '.join(c)}\n  {describe(c, graph, modules)}" for c in unexpected)
    assert not stale, f"PENDING_CYCLES lists cycles that are gone; remove them: {stale}"


def test_importing_a_representation_imports_no_renderer():
    """Each built-in's drjit kernel (a `*_kernel(s)` module) is imported inside its `drjit_kernel()` hook, so the
    representations (and the core's NBRDF network) load without drjit or mitsuba."""
    names = sorted(m for m in modules_under(ROOT / "representations", "brdfbench_representations")
                   if not m.rpartition(".")[2].endswith(("_kernels", "_kernel")))  # the drjit twins themselves
    code = ("import importlib, sys\n"
            f"for name in {[*names, 'brdfbench.nbrdf.formats', 'brdfbench.data.nbrdf_release']!r}:\n"
            "    importlib.import_module(name)\n"
            "print(sorted(m for m in ('drjit', 'mitsuba') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


# --------------------------------------------------------------------------- the walker itself


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path


def test_the_walker_finds_a_planted_plugin_import(tmp_path):
    root = _package(tmp_path, {
        "core/__init__.py": "",
        "core/clean.py": "import os\nfrom . import lazy\n",
        "core/lazy.py": "def f():\n    from brdfbench_metrics.image import rmse\n    return rmse\n",
        "core/sub/__init__.py": "",
        "core/sub/top.py": "import brdfbench_representations.merl as m\n",
        "core/sub/rel.py": "from ...core import clean\n",
    })
    found = plugin_imports(modules_under(root / "core", "core"))
    assert sorted(found) == ["core.lazy", "core.sub.top"]
    assert found["core.lazy"] == ["line 2: brdfbench_metrics.image"]
    assert found["core.sub.top"] == ["line 1: brdfbench_representations.merl"]


@pytest.mark.parametrize("where", ["module", "function", "type_checking", "package"])
def test_the_walker_finds_a_planted_cycle(tmp_path, where):
    back = {
        "module": "from .a import x\n",
        "function": "def g():\n    from . import a\n    return a\n",
        "type_checking": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import x\n",
        "package": "import pkg.sub\n",  # b imports the package pkg.sub, whose __init__ imports a, which imports b
    }[where]
    root = _package(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "from . import b\nx = 1\n",
        "pkg/b.py": back,
        "pkg/c.py": "from . import a\n",  # imports into the cycle, is not part of it
        "pkg/sub/__init__.py": "from ..a import x\n" if where == "package" else "",
    })
    modules = modules_under(root / "pkg", "pkg")
    graph = import_graph(modules)
    want = ["pkg.a", "pkg.b", "pkg.sub"] if where == "package" else ["pkg.a", "pkg.b"]
    assert cycles(graph) == [want]
    assert "pkg.a -> pkg.b" in describe(want, graph, modules)


def test_the_walker_passes_an_acyclic_package(tmp_path):
    root = _package(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/shared.py": "import math\n",
        "pkg/a.py": "from .shared import math\n",
        "pkg/b.py": "def f():\n    from . import a, shared\n",
    })
    graph = import_graph(modules_under(root / "pkg", "pkg"))
    assert cycles(graph) == []
    assert graph["pkg.b"] == {"pkg.a": 2, "pkg.shared": 2}
