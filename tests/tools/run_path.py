"""Follow one run from the command line to the report, as a newcomer reading the code would.

    python tests/tools/run_path.py [OVERRIDES...]    (default: one lambert job on one material)

Runs `brdfbench OVERRIDES` in a fresh interpreter with a profiler in every process it starts
(the cell worker included), recording each distinct chain of project files on the call
stack. The run's *spine* is the chains that lead from the command line to each plugin the
run uses (the representation, the harness, its metrics, the dataset, the store, the
reports), cut at that plugin: the files a reader must open to see how control gets there.
The spine is read as a tree, depth first; a file that sits at two places of the tree is a
return visit (the reader has to come back to a module already read).

The files are also read as a graph, each once: a call from one file into another is an
edge, taken from every chain of the run (helpers included). Where the graph has no cycle,
the spine's files can be read in an order in which every call leads on to a file not yet
read; a cycle (a file that calls back into one that called it, as a callback or a task
function does) is where a reader has to go back.

Prints the tree, the files in reading order, the counts and the cycles. Import-time frames
are left out (a module's top level runs once, when imported, not as part of following the
run).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import brdfbench

sys.path.insert(0, str(Path(__file__).resolve().parent))  # run as a script or imported by the tests

from graphs import cycles  # noqa: E402

ROOT = Path(brdfbench.__file__).resolve().parents[1]  # the checkout the installed brdfbench runs from
FOLDERS = ("brdfbench", "representations", "generators", "metrics", "leaderboard", "hydra_plugins")
ENTRIES = {("brdfbench/cli.py", "main"), ("brdfbench/pipeline/worker.py", "_worker_main")}
DEFAULT = ["representation=lambert", "dataset.params.size=small", "harness=quick", "limit=1", "progress=none"]

PROFILER = r'''
import os, sys
_LOG = os.environ.get("RUNPATH_LOG")
if _LOG:
    import atexit, json, threading
    _ROOTS = tuple(os.environ["RUNPATH_ROOTS"].split(os.pathsep))
    _seen = {}

    def _stack(frame):
        out = []
        while frame is not None:
            f = frame.f_code.co_filename
            if f.startswith(_ROOTS):
                if out and out[-1][0] == f:
                    out[-1] = (f, frame.f_code.co_name)
                else:
                    out.append((f, frame.f_code.co_name))
            frame = frame.f_back
        return tuple(reversed(out))

    def _profile(frame, event, arg):
        if event != "call" or not frame.f_code.co_filename.startswith(_ROOTS):
            return
        back = frame.f_back
        while back is not None and not back.f_code.co_filename.startswith(_ROOTS):
            back = back.f_back
        if back is not None and back.f_code.co_filename == frame.f_code.co_filename:
            return
        _seen.setdefault(_stack(frame), len(_seen))

    def _dump():
        with open(os.path.join(_LOG, f"{os.getpid()}.json"), "w") as fh:
            json.dump(sorted(_seen, key=_seen.get), fh)

    atexit.register(_dump)
    sys.setprofile(_profile)
    threading.setprofile(_profile)
'''


def plugin_files(run_dir: Path) -> set[str]:
    """The files of the plugins the run used, by their registered targets (as root-relative paths)."""
    from brdfbench.plugins import registry

    out = set()
    for group in registry.GROUPS:
        for name in registry.names(group):
            try:
                target = registry.get(group, name).target
            except Exception:
                continue
            module = target.split(":")[0]
            try:
                import importlib.util

                spec = importlib.util.find_spec(module)
            except Exception:
                continue
            if spec and spec.origin and spec.origin.startswith(str(ROOT)):
                out.add(str(Path(spec.origin).relative_to(ROOT)))
    return out


def trace(overrides: list[str]) -> list[list[tuple[str, str]]]:
    """Every distinct call chain of project files (file, outermost function in it) in every process."""
    with tempfile.TemporaryDirectory(prefix="run-path-") as tmp:
        tmp = Path(tmp)
        (tmp / "site").mkdir()
        (tmp / "log").mkdir()
        (tmp / "site" / "sitecustomize.py").write_text(PROFILER, encoding="utf-8")
        env = {**os.environ, "RUNPATH_LOG": str(tmp / "log"),
               "RUNPATH_ROOTS": os.pathsep.join(str(ROOT / f) for f in FOLDERS),
               "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp / "site"), os.environ.get("PYTHONPATH")]))}
        # called from a -c string, so that no project frame sits below main() (python -m would
        # put the module's top level there, which reads as import time)
        out = subprocess.run([sys.executable, "-c", "import sys; from brdfbench.cli import main; sys.exit(main())",
                              *overrides, f"results_dir={tmp / 'res'}"],
                             cwd=tmp, env=env, capture_output=True, text=True, timeout=600)
        if out.returncode != 0:
            raise SystemExit(f"the run failed:\n{out.stdout}\n{out.stderr}")
        chains = []
        for log in sorted((tmp / "log").glob("*.json")):
            for chain in json.loads(log.read_text(encoding="utf-8")):
                chain = [(str(Path(f).relative_to(ROOT)), fn) for f, fn in chain]
                # from a process's entry (the command, the cell worker), not import time, not a
                # thread or an exit hook
                if chain and chain[0] in ENTRIES and not any(fn == "<module>" for _, fn in chain):
                    chains.append(chain)
        return chains


def spine(chains: list[list[tuple[str, str]]], plugins: set[str]) -> list[list[tuple[str, str]]]:
    """The chains that reach a plugin's file, cut there; one per (plugin, way in)."""
    out, seen = [], set()
    for chain in chains:
        for i, (file, _) in enumerate(chain):
            if file in plugins:
                cut = chain[:i + 1]
                key = tuple(f for f, _ in cut)
                if key not in seen and not any(key == tuple(f for f, _ in c)[:len(key)] for c in out):
                    seen.add(key)
                    out.append(cut)
                break
    # drop chains that are a prefix of another (the longer one shows the same way in)
    keys = [tuple(f for f, _ in c) for c in out]
    return [c for c, k in zip(out, keys) if not any(o != k and o[:len(k)] == k for o in keys)]


def tree(chains: list[list[tuple[str, str]]]) -> dict:
    """file -> (functions entered there, {next file: ...}): a file read once at each place,
    whichever of its functions the chains pass through."""
    root: dict = {}
    for chain in chains:
        node = root
        for file, fn in chain:
            fns, node = node.setdefault(file, ([], {}))
            if fn not in fns:
                fns.append(fn)
    return root


def read(node: dict, depth: int = 0, order: list | None = None, lines: list | None = None,
         onward: list | None = None):
    """Depth first: (the files in reading order, one entry per place; printed lines; the
    returns from which the control goes on into other files, not only a look-up)."""
    order = [] if order is None else order
    lines = [] if lines is None else lines
    onward = [] if onward is None else onward
    for file, (fns, children) in node.items():
        again = file in order
        if again and children:
            onward.append(file)
        order.append(file)
        lines.append(f"{'  ' * depth}{file} ({', '.join(fns)}){'   <- again' if again else ''}")
        read(children, depth + 1, order, lines, onward)
    return order, lines, onward


def calls(chains: list[list[tuple[str, str]]], plugins: set[str] | None = None) -> dict[tuple[str, str], set[str]]:
    """(caller file, callee file) -> the calls it stands for ("caller fn -> callee fn"), for
    every step of the chains where control passes from one file into another; with
    `plugins`, each chain cut at its first plugin file (the way in, not a plugin's insides)."""
    out: dict[tuple[str, str], set[str]] = {}
    for chain in chains:
        if plugins is not None:
            first = next((i for i, (f, _) in enumerate(chain) if f in plugins), len(chain) - 1)
            chain = chain[:first + 1]
        for (a, fa), (b, fb) in zip(chain, chain[1:]):
            if a != b:
                out.setdefault((a, b), set()).add(f"{fa} -> {fb}")
    return out


def call_cycles(edges) -> list[list[str]]:
    """The groups of files that call each other round (`graphs.cycles` of the call graph)."""
    graph: dict[str, list[str]] = {}
    for a, b in edges:
        graph.setdefault(a, []).append(b)
    return cycles(graph)


def reading_order(files: list[str], edges) -> list[str] | None:
    """The spine's files in an order in which each comes after every spine file that calls
    it (ties in `files`' order), or None where a cycle leaves none."""
    rank = {f: i for i, f in enumerate(files)}
    callers = {f: {a for a, b in edges if b == f and a in rank and a != f} for f in files}
    order: list[str] = []
    while len(order) < len(files):
        ready = [f for f in files if f not in order and not callers[f] - set(order)]
        if not ready:
            return None
        order.append(min(ready, key=rank.get))
    return order


def measure(overrides: list[str]) -> dict:
    """One traced run: its chains, the plugin files, the spine's files (first-read order),
    its tree (reading order with repeats, printed lines, onward returns), the calls on the way
    in and their cycles."""
    chains = trace(overrides)
    plugins = plugin_files(ROOT)
    order, lines, onward = read(tree(spine(chains, plugins)))
    edges = calls(chains, plugins)
    return {"chains": chains, "plugins": plugins, "files": list(dict.fromkeys(order)), "order": order,
            "lines": lines, "onward": onward, "edges": edges, "cycles": call_cycles(edges)}


def main(argv: list[str]) -> int:
    overrides = argv or DEFAULT
    m = measure(overrides)
    chains, plugins, order, lines, onward, files = (m[k] for k in ("chains", "plugins", "order", "lines", "onward", "files"))
    returns = len(order) - len(files)
    core = [f for f in files if f not in plugins]
    print(f"brdfbench {' '.join(overrides)}\n")
    print("\n".join(lines))
    print(f"\n{len(files)} files on the way from the command line to the plugins, "
          f"{returns} return visit{'s' if returns != 1 else ''}:")
    for i, f in enumerate(files, 1):
        print(f"{i:3d}. {f}{'  (plugin)' if f in plugins else ''}")
    print(f"\n{len(core)} of them are not plugins; {len(onward)} of the return visits go on from there into "
          f"other files (the rest look up a function of a module already read): {', '.join(onward)}")
    edges, loops = m["edges"], m["cycles"]
    inside = [g for g in call_cycles(calls(chains)) if g not in loops]
    for title, groups, among in (("on the way from the command line to the plugins (a reader goes back to a file)", loops, edges),
                                 ("inside plugins and the helpers they call", inside, calls(chains))):
        print(f"\n{len(groups)} cycle{'s' if len(groups) != 1 else ''} {title}:")
        for group in groups:
            members = set(group)
            print("  " + " <-> ".join(group))
            for (a, b), how in sorted(among.items()):
                if a in members and b in members:
                    print(f"      {a} -> {b}: {'; '.join(sorted(how))}")
    order = reading_order(files, edges)
    if order is not None:
        print("\nthe spine read once, each file after every file that calls it:")
        for i, f in enumerate(order, 1):
            print(f"{i:3d}. {f}{'  (plugin)' if f in plugins else ''}")
    every = {f for c in chains for f, _ in c}
    print(f"\n{len(every)} project files run in all (helpers called along the way included)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
