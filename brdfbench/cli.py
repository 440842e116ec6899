"""The `brdfbench` command.

`brdfbench [hydra overrides]` runs the benchmark from the packaged Hydra configs (the
default sweeps the built-in representations over the embedded dataset and writes the
leaderboard). Subcommands that need no config:

    brdfbench list                      one line per registered plugin
    brdfbench report [--results DIR]    regenerate the leaderboard from the results store
    brdfbench merge SRC... --into DIR   copy the cells of other results folders into DIR's store
    brdfbench check NAME                run the conformance kit on a plugin (representation, generator,
                                        sampler, metric, harness or dataset)
    brdfbench inspect MODEL.safetensors describe a saved model or generator (loads no code)
    brdfbench convert SRC DEST          convert neural-BRDF weights between formats
                                        (.h5, .npy 675-vector, .pt state_dict, .safetensors)
    brdfbench synthesize GEN.safetensors --category C -n N --out DIR
                                        N samples of a saved generator in one material category
                                        (constrained synthesis, by rejection)

`brdfbench --help` lists these and the config groups; `--version` prints the version;
`--hydra-help` is Hydra's own help. Output cut short by a closed pipe (`brdfbench list |
head`) ends quietly, as other command-line tools do.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from .cli_help import config_help, SUBCOMMANDS, USAGE
from .errors import BrdfbenchError, os_error
from . import __version__
from .plugins import registry
from .report import write_reports
from .store.protocol import merge, open_store

EXIT_ERROR = 2
EXIT_BROKEN_PIPE = 128 + 13  # as a process killed by SIGPIPE


def _fail(message: str) -> int:
    print(f"brdfbench: error: {message}", file=sys.stderr)
    return EXIT_ERROR


def cmd_list(args) -> int:
    group = args.group
    if group and group not in registry.GROUPS and f"{group}s" in registry.GROUPS:
        group = f"{group}s"  # accept the singular, as in the config groups
    if group and group not in registry.GROUPS:
        raise BrdfbenchError(f"unknown plugin group {group!r}; groups are {', '.join(registry.GROUPS)}")
    groups = [group] if group else list(registry.GROUPS)
    broken = []
    for group in groups:
        for name in registry.names(group):
            try:
                spec = registry.get(group, name)
            except BrdfbenchError as exc:  # one broken third-party entry point: list the rest, name it
                broken.append(str(exc))
                continue
            print(f"{group:16s} {name:16s} {spec.description}")
    for message in broken:
        print(f"brdfbench: error: {message}", file=sys.stderr)
    return 1 if broken else 0


def cmd_report(args) -> int:
    for path in write_reports(Path(args.results), args.store):
        print(path)
    return 0


def cmd_merge(args) -> int:
    """Stores written apart (one per node) into one: every source is opened first (a missing
    one fails before anything is written), then merged cell by cell, each cell in one
    transaction (a finished cell is never replaced, so merging again is harmless), then the
    reports are rewritten."""
    into = Path(args.into).resolve()
    sources = [open_store(args.store, Path(src), {"create": False}) for src in args.sources]
    for src, store in zip(args.sources, sources):
        if Path(src).resolve() == into:
            raise BrdfbenchError(f"{src}: a results folder cannot be merged into itself")
    target = open_store(args.store, into)
    for store in sources:
        counts = merge(store, target)
        print(f"{store.location}: {counts['written']} cells merged, {counts['kept']} already in {target.location}")
    for path in write_reports(into, args.store):
        print(path)
    return 0


def cmd_check(args) -> int:
    """Each check runs in a worker process under `--timeout`: a plugin that crashes, ends
    the process or hangs fails that check (naming the cause) and the others still run."""
    import yaml

    from .testing.isolated import check_isolated  # lazy: safetensors, torch

    if args.timeout <= 0:
        return _fail(f"--timeout must be a positive number of seconds, not {args.timeout:g}")
    params = {}
    for item in args.param or ():
        key, eq, text = item.partition("=")
        if not eq or not key.strip():
            return _fail(f"--param {item!r} must look like KEY=VALUE (e.g. --param path=/data/merl)")
        try:
            params[key.strip()] = yaml.safe_load(text) if text else ""
        except yaml.YAMLError:
            return _fail(f"--param {item!r}: {text!r} is not a YAML value")
    groups = {"representation": "representations", "generator": "generators", "sampler": "samplers",
              "metric": "metrics", "harness": "harnesses", "dataset": "datasets"}
    kind = args.kind
    if kind is None:  # the first kind that has the name (a sampler may share a model's name: --kind)
        kind = next((k for k, group in groups.items() if args.name in registry.names(group)), "representation")
        also = [k for k, group in groups.items() if k != kind and args.name in registry.names(group)]
        if also:
            print(f"brdfbench check: {args.name!r} is also a {' and a '.join(also)}: checking the {kind} "
                  f"(--kind {also[0]} for the other)", file=sys.stderr)
    registry.get(groups[kind], args.name)  # an unknown name: one line, exit 2
    if params and kind == "metric":
        return _fail(f"--param {next(iter(params))}=…: a metric takes no parameters")

    def progress(check: str, outcome: str, seconds: float) -> None:
        print(f"brdfbench check: {outcome:8s} {check} ({seconds:.1f} s)", file=sys.stderr, flush=True)

    report = check_isolated(kind, args.name, n_pairs=args.pairs, full=args.full, params=params,
                            timeout_s=args.timeout, on_result=progress)
    print(report.summary())
    return 0 if report.passed else 1


def cmd_inspect(args) -> int:
    from . import modelio  # lazy: safetensors, torch

    if modelio.holds_generator(args.path):
        name, gen = modelio.load_generator(args.path)
        print(f"{args.path}: generator {name!r}, params {gen.params}, {gen.nbytes} bytes, learns from "
              f"{gen.learns_from}")
        for key, value in gen.metadata().items():
            text = str(value)
            print(f"  {key}: {text if len(text) <= 200 else text[:200] + '…'}")
        return 0
    name, model = modelio.load(args.path)
    print(f"{args.path}: representation {name!r}, params {model.params}, {model.nbytes} bytes"
          + (f" (+{model.shared_nbytes} shared)" if model.shared_nbytes else "")
          + (f", {model.flops_per_eval} FLOP/eval" if model.flops_per_eval else ""))
    for key, value in model.metadata().items():
        print(f"  {key}: {value}")
    return 0


def cmd_convert(args) -> int:
    try:
        from .nbrdf.formats import read_network, write_network  # lazy: h5py, safetensors, torch
    except ImportError as exc:  # the built-in plugins are part of the package, but say so if missing
        return _fail(f"convert needs the built-in representations ({exc})")

    network = read_network(args.src, hidden=args.hidden, raw_units=args.raw_units, features=args.features)
    path = write_network(network, args.dest)
    units = "raw MERL units (read back with --raw-units)" if network.raw_units else "1/sr"
    print(f"{path}: {network.features} network 6-{'-'.join(map(str, network.hidden))}-3, outputs in {units}")
    return 0


def cmd_synthesize(args) -> int:
    """N samples of one category from a saved generator, by rejection; written (as model
    files) only when all N were found, into a folder that did not exist."""
    import shutil
    import tempfile

    from . import modelio  # lazy: safetensors, torch
    from .synthesis import checked_category, constrained_samples  # lazy: torch

    category = checked_category(args.category)
    out = Path(args.out)
    if out.exists():
        raise BrdfbenchError(f"--out {out}: exists; give a new folder (samples are never mixed into old ones)")
    if not out.parent.is_dir():
        raise BrdfbenchError(f"--out {out}: its parent folder {out.parent} does not exist")
    if not modelio.holds_generator(args.path):
        raise BrdfbenchError(f"{args.path}: not a saved generator (brdfbench inspect says what it is)")
    name, generator = modelio.load_generator(args.path)

    def progress(draw) -> None:
        print(f"synthesize: {draw.accepted}/{draw.asked} {category} after {draw.drawn} draws "
              f"({draw.acceptance_rate:.1%}, {draw.seconds:.1f} s)", flush=True)

    try:
        draw = constrained_samples(generator, category, args.n, seed=args.seed, batch=args.batch,
                                   max_draws=args.max_draws, on_batch=progress)
    except RuntimeError as exc:  # e.g. a loaded training set, which holds names only
        raise BrdfbenchError(f"{args.path}: {exc}") from None
    rate = f"{draw.accepted} of {draw.drawn} draws ({draw.acceptance_rate:.2%}), {draw.non_finite} non-finite"
    if not draw.complete:
        print(f"brdfbench: error: found {rate}, not the {draw.asked} {category} samples asked; nothing written "
              f"(raise --max-draws, now {args.max_draws})", file=sys.stderr)
        return 1
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        for i, sample in enumerate(draw.samples):
            modelio.save(sample, draw.representation, tmp / f"{category}-{i:03d}.safetensors")
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    print(f"{out}: {draw.accepted} {category} samples of generator {name!r} ({draw.representation}); accepted {rate}; "
          f"{draw.seconds_per_accepted:.2f} s per accepted sample (drawing, building and classifying)")
    return 0


def _subcommand_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="brdfbench", description="BRDF benchmark utilities")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("list", help="list registered plugins")
    p.add_argument("group", nargs="?", help="only this group (representations, generators, metrics, datasets, scenes)")
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("report", help="regenerate the leaderboard from a results store")
    p.add_argument("--results", default="results", help="results folder holding brdfbench.sqlite (default: results)")
    p.add_argument("--store", default="sqlite", help="results store plugin (default: sqlite)")
    p.set_defaults(func=cmd_report)
    p = sub.add_parser("merge", help="copy the cells of other results folders into one store, then rewrite its reports")
    p.add_argument("sources", nargs="+", metavar="SRC", help="results folders to read (e.g. one per node)")
    p.add_argument("--into", required=True, metavar="DIR", help="results folder to merge into (created if new)")
    p.add_argument("--store", default="sqlite", help="results store plugin of all of them (default: sqlite)")
    p.set_defaults(func=cmd_merge)
    p = sub.add_parser("check", help="run the conformance kit on a registered representation, generator, sampler, "
                                     "metric, harness or dataset")
    p.add_argument("name")
    p.add_argument("--kind", choices=("representation", "generator", "sampler", "metric", "harness", "dataset"),
                   default=None, help="the plugin kind (default: the first of these that has the name)")
    p.add_argument("--pairs", type=int, default=10**6, help="adversarial direction pairs per dtype (default 1e6)")
    p.add_argument("--full", action="store_true",
                   help="a representation or generator with its default parameters, not its quick kit_params; "
                        "a sampler over the full chi-square sweep, not the quick one; an image-set metric scored; "
                        "a rendering harness measured, with its full sizes; a dataset's weight vectors read")
    p.add_argument("--timeout", type=float, default=600.0, metavar="SECONDS",
                   help="time limit of each check, run in a worker process (default 600)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE",
                   help="a constructor argument (a harness: a config key) over the kit's quick ones, the value "
                        "read as YAML; repeatable (e.g. a dataset's --param path=/data/merl)")
    p.set_defaults(func=cmd_check)
    p = sub.add_parser("inspect", help="describe a saved model or generator file")
    p.add_argument("path")
    p.set_defaults(func=cmd_inspect)
    p = sub.add_parser("convert", help="convert neural-BRDF weights (.h5 .npy .pt .safetensors) to .npy, .pt or .safetensors")
    p.add_argument("src", help="Keras .h5 (published NBRDF), flat .npy vector, torch .pt state_dict, or brdfbench .safetensors")
    p.add_argument("dest", help="output file; its suffix picks the format (.npy, .pt, .safetensors)")
    p.add_argument("--hidden", type=int, nargs="+", default=[21, 21], help="hidden widths of a .npy/.h5 source (default 21 21)")
    p.add_argument("--raw-units", action="store_true", help="the source outputs raw (unscaled) MERL values, not 1/sr")
    p.add_argument("--features", choices=("rusinkiewicz", "directions"), default="rusinkiewicz",
                   help="input encoding of a .npy/.pt/.h5 source: nbrdf (rusinkiewicz) or naive_mlp (directions)")
    p.set_defaults(func=cmd_convert)
    p = sub.add_parser("synthesize", help="samples of a saved generator in one material category (constrained "
                                          "synthesis, by rejection against the category rules)")
    p.add_argument("path", metavar="GENERATOR", help="a saved generator (.safetensors)")
    p.add_argument("--category", required=True,
                   help="diffuse, metallic, low-specular, mid-specular, high-specular, plastic or mirror")
    p.add_argument("-n", type=int, default=8, help="samples to find (default 8)")
    p.add_argument("--out", required=True, metavar="DIR", help="a new folder for the samples' model files")
    p.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    p.add_argument("--batch", type=int, default=32, help="samples drawn at a time (default 32)")
    p.add_argument("--max-draws", type=int, default=4096, help="give up after this many draws (default 4096)")
    p.set_defaults(func=cmd_synthesize)
    return parser


def _help_text() -> str:
    """The subcommand parser's help, with the benchmark usage and the config groups around it."""
    parser = _subcommand_parser()
    parser.usage = USAGE
    parser.description = "Benchmark BRDF representations: fit, measure accuracy and cost, write a leaderboard."
    parser.epilog = config_help()
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    return parser.format_help()


def _closed_pipe() -> int:
    """stdout's reader went away (`brdfbench list | head`): stop quietly, as CLI tools do."""
    try:  # Python flushes stdout again at exit; point it at /dev/null so that flush cannot fail
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return EXIT_BROKEN_PIPE


def _dispatch(argv: list[str]) -> int:
    if argv and argv[0] in SUBCOMMANDS:
        args = _subcommand_parser().parse_args(argv)
        try:
            return args.func(args)
        except BrdfbenchError as exc:
            return _fail(str(exc))
        except OSError as exc:  # a folder that cannot be read or written: one line, not a traceback
            if isinstance(exc, BrokenPipeError):
                raise

            return _fail(os_error(exc, f"brdfbench {args.command}"))
    if "--version" in argv:
        print(f"brdfbench {__version__}")
        return 0
    if "-h" in argv or "--help" in argv:
        print(_help_text(), end="")
        return 0
    return run_hydra(argv)


def run_hydra(argv: list[str]) -> int:
    """The benchmark itself: the command line checked, then Hydra's entry (brdfbench.hydra.app),
    which composes the jobs and hands them to the pipeline."""
    from .hydra import app  # lazy: hydra, pandas, safetensors, torch

    try:
        sys.argv = app.checked_argv(argv)
    except BrdfbenchError as exc:
        print(f"brdfbench: error: {exc}", file=sys.stderr, flush=True)
        return 2
    app.main()
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        status = _dispatch(argv)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's final flush
    except BrokenPipeError:
        return _closed_pipe()
    return status


if __name__ == "__main__":
    sys.exit(main())
