"""Imports inside functions are deliberate and say why (issue 31).

A project module imported inside a function instead of at the top hides a coupling from
the reader. Each one that stays is marked on its line:

- `# lazy: torch, drjit`: the heavy packages that importing it at the top would add to
  this module's import (what `brdfbench --help`, `brdfbench list`, `import brdfbench`, the
  reports and the representations' import stay free of);
- `# lazy: attribute`: a package attribute resolved on first use (PEP 562), in `__init__.py`.

Read statically with `ast`: the packages a module's import pulls in are those its
module-level statements import, followed through the project's modules (and the packages
above them, which Python initialises first). A mark names only packages the target's import
brings and this module's import does not.
"""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

import pytest

from test_imports import CORE, PLUGINS, ROOT, modules_under  # tests/unit is on sys.path

MARK = "# lazy:"
PROJECT = (CORE, *PLUGINS)


def _all_modules() -> dict[str, Path]:
    modules = modules_under(ROOT / "brdfbench", CORE)
    for package, folder in PLUGINS.items():
        modules.update(modules_under(ROOT / folder, package))
    return modules


MODULES = _all_modules()


def _absolute(module: str, path: Path, node: ast.ImportFrom | ast.Import) -> list[str]:
    """The dotted names an import statement imports (for `from X import a`: X and X.a)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        parts = package.split(".")
        base = ".".join(parts[:len(parts) - (node.level - 1)] + ([node.module] if node.module else []))
    else:
        base = node.module or ""
    return [base, *(f"{base}.{a.name}" for a in node.names if a.name != "*")]


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _module_level_imports(node: ast.AST):
    """Import statements run when the module is imported: not inside a function, not under
    `if TYPE_CHECKING:`."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        if isinstance(child, ast.If) and _is_type_checking(child):
            yield from (n for s in child.orelse for n in _module_level_imports_of(s))
            continue
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            yield child
        else:
            yield from _module_level_imports(child)


def _module_level_imports_of(stmt: ast.AST):
    if isinstance(stmt, (ast.Import, ast.ImportFrom)):
        yield stmt
    elif not isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef)):
        yield from _module_level_imports(stmt)


@lru_cache(maxsize=None)
def _tree(module: str) -> ast.Module:
    return ast.parse(MODULES[module].read_text(encoding="utf-8"))


def _project_targets(names: list[str]) -> set[str]:
    """The project modules importing `names` runs: each name's module and its packages."""
    out = set()
    for name in names:
        parts = name.split(".")
        out |= {".".join(parts[:i]) for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in MODULES}
    return out


@lru_cache(maxsize=None)
def third_party_closure(module: str) -> frozenset[str]:
    """Top-level names of the non-project packages that `import module` imports."""
    seen: set[str] = set()
    found: set[str] = set()
    parts = module.split(".")
    todo = [".".join(parts[:i]) for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in MODULES]
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen.add(current)
        for node in _module_level_imports(_tree(current)):
            names = _absolute(current, MODULES[current], node)
            top = names[0].split(".")[0]
            if top in PROJECT:
                todo += sorted(_project_targets(names) - seen)
            elif top and top != "__future__":
                found.add(top)
    return frozenset(found)


def deferred_imports(module: str):
    """(line, statement, imported names, its mark or None) of every function-level import of a
    project module in `module`."""
    path = MODULES[module]
    lines = path.read_text(encoding="utf-8").splitlines()
    for fn in ast.walk(_tree(module)):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = _absolute(module, path, node)
                if names[0].split(".")[0] in PROJECT:
                    line = lines[node.lineno - 1]
                    mark = line.split(MARK, 1)[1].split(";")[0].strip() if MARK in line else None
                    yield node.lineno, ast.unparse(node), names, mark


def _where(module: str, line: int) -> str:
    path = MODULES[module]
    return f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:{line}"


def problems(module: str) -> list[str]:
    out = []
    mine = third_party_closure(module)
    for line, stmt, names, mark in deferred_imports(module):
        if mark is None:
            out.append(f"{_where(module, line)}: `{stmt}` inside a function has no `{MARK} …` mark: "
                       "import it at the top, or name the heavy packages it keeps out")
            continue
        if mark == "attribute":
            if MODULES[module].name != "__init__.py":
                out.append(f"{_where(module, line)}: `{MARK} attribute` belongs in a package's __init__.py")
            continue
        theirs = set().union(*(third_party_closure(t) for t in _project_targets(names)))
        for package in (p.strip() for p in mark.split(",")):
            if package not in theirs:
                out.append(f"{_where(module, line)}: `{stmt}` is marked lazy for {package}, which its import does not bring")
            elif package in mine:
                out.append(f"{_where(module, line)}: `{stmt}` is marked lazy for {package}, which {module} imports anyway")
    return out


def test_every_import_inside_a_function_says_why():
    found = [p for module in sorted(MODULES) for p in problems(module)]
    assert not found, "\n".join(found)


def test_the_deferred_imports_keep_the_light_entry_points_light():
    """What the marks protect, read from the same closure: the command line, the package and
    the reports import no torch, Hydra or renderer at the top."""
    for module in ("brdfbench", "brdfbench.cli", "brdfbench.api", "brdfbench.report", "brdfbench.plugins.registry"):
        assert not third_party_closure(module) & {"torch", "hydra", "drjit", "mitsuba", "pandas"}, module


# --------------------------------------------------------------------------- the reader itself


@pytest.fixture
def planted(tmp_path, monkeypatch):
    def plant(files: dict[str, str]) -> None:
        for rel, text in files.items():
            path = tmp_path / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
        modules = modules_under(tmp_path / "brdfbench", CORE)
        monkeypatch.setattr(f"{__name__}.MODULES", modules)
        _tree.cache_clear()
        third_party_closure.cache_clear()
    yield plant
    _tree.cache_clear()
    third_party_closure.cache_clear()


LIGHT = "def f():\n    from .heavy import g{mark}\n    return g\n"
FILES = {"brdfbench/__init__.py": "", "brdfbench/heavy.py": "import torch\nfrom .inner import h\n",
         "brdfbench/inner.py": "try:\n    import scipy\nexcept ImportError:\n    scipy = None\n"}


@pytest.mark.parametrize("mark, expected", [
    ("", "has no `# lazy: …` mark"),
    ("  # lazy: torch", None),
    ("  # lazy: scipy, torch", None),  # scipy arrives through heavy's own import of inner
    ("  # lazy: h5py", "marked lazy for h5py, which its import does not bring"),
    ("  # lazy: attribute", "belongs in a package's __init__.py"),
])
def test_the_reader_checks_each_mark(planted, mark, expected):
    planted({**FILES, "brdfbench/light.py": LIGHT.format(mark=mark)})
    found = problems("brdfbench.light")
    assert (found == []) if expected is None else (len(found) == 1 and expected in found[0]), found


def test_a_mark_for_a_package_the_module_imports_anyway_is_refused(planted):
    planted({**FILES, "brdfbench/light.py": "import torch\n\n" + LIGHT.format(mark="  # lazy: torch")})
    found = problems("brdfbench.light")
    assert len(found) == 1 and "which brdfbench.light imports anyway" in found[0]


def test_type_checking_imports_and_function_bodies_are_not_module_level(planted):
    planted({**FILES, "brdfbench/light.py": ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                              "    import pandas\n\ndef f():\n    import h5py\n")})
    assert third_party_closure("brdfbench.light") == {"typing"}
