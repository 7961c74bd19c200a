"""The ``pursuit`` command line.

``pursuit list``                      models, filters, scenarios, experiments
``pursuit run CONFIG.toml``           run one experiment file
``pursuit reproduce NAME|all``        run bundled experiments (``experiments/NAME.toml``)
``pursuit report DIR``                rebuild report.html (and the index) from saved results
``pursuit track DATA --config M.toml`` run a configured filter on recorded or live measurements

``run`` and ``reproduce`` take ``--workers N`` (local processes) or
``--scheduler tcp://HOST:PORT`` (a Dask cluster) to spread the chunks of runs.

``pursuit`` alone prints this list of commands; ``pursuit --version`` the
version; ``python -m pursuit`` is the same command.

Exit codes: 0 success, 2 bad input (config, arguments), 1 unexpected failure.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Sequence

from . import registry
from .experiment import ConfigError, find_experiment, list_experiments, load_experiment

__all__ = ["main"]

EXIT_BAD_INPUT = 2


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    p = argparse.ArgumentParser(prog="pursuit", description="Tracking and positioning filters, compared fairly.")
    p.add_argument("-V", "--version", action="version", version=f"pursuit {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    ls = sub.add_parser("list", help="list models, filters, scenarios, fading strategies and experiments")
    ls.add_argument("kind", nargs="?", choices=["models", "filters", "scenarios", "fading", "experiments"], help="only this kind")
    ls.add_argument("-v", "--verbose", action="store_true", help="show every parameter")

    for name, help_ in (("run", "run an experiment file"), ("reproduce", "run bundled experiments by name, or all")):
        sp = sub.add_parser(name, help=help_)
        if name == "run":
            sp.add_argument("config", help="experiment TOML file")
        else:
            sp.add_argument("name", help="experiment name (see `pursuit list experiments`) or 'all'")
        sp.add_argument("-o", "--out", help="output folder (default: results/NAME, or results/ for reproduce)")
        sp.add_argument("--runs", type=int, help="override the number of Monte Carlo runs")
        sp.add_argument("--seed", type=int, help="override the root seed")
        sp.add_argument("--chunk-size", type=int, help="runs per chunk (memory bound)")
        sp.add_argument("--no-progress", action="store_true", help="never show a progress bar")
        sp.add_argument("--no-pdf", action="store_true", help="write figures as PNG only (default: PNG and PDF)")
        sp.add_argument(
            "--full-data",
            action="store_true",
            help="save every run's errors and arrays (errors.csv, results/*.npz); default: per-step summaries "
            "of all runs and the first --keep-runs runs whole",
        )
        sp.add_argument("--pdf", action="store_true", help=argparse.SUPPRESS)  # PDF is now the default
        _add_engine_arguments(sp)

    rp = sub.add_parser("report", help="rebuild report.html from a saved output folder (or every folder under it)")
    rp.add_argument("dir", help="an output folder (with run.json), or a folder of them such as results/")

    from .io.command import add_track_parser

    add_track_parser(sub)
    return p


def _add_engine_arguments(sp: argparse.ArgumentParser) -> None:
    g = sp.add_argument_group("where the runs are computed")
    where = g.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N", help="spread chunks of runs over N local processes")
    where.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="run the chunks on a Dask cluster (needs pursuit[distributed])"
    )
    g.add_argument(
        "--store",
        choices=["auto", "full", "summary"],
        help="keep every run's arrays (full) or reduce each chunk (summary: memory bounded by the chunk size); "
        "default auto: full unless that would take more than 1 GiB",
    )
    g.add_argument("--keep-runs", type=int, metavar="R", help="runs kept whole in summary mode and in a folder written without --full-data (default 10)")
    c = sp.add_argument_group("how each filter step is computed")
    c.add_argument(
        "--compute-backend",
        choices=["numpy", "numba"],
        help="default compute backend of filters whose table sets no `backend` (numba needs pursuit[fast]; "
        "default: $PURSUIT_COMPUTE_BACKEND or numpy). Not the same as --workers/--scheduler.",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:  # a bare `pursuit`: what it can do, not an argparse complaint
        parser.print_help()
        return 0
    args.argv = argv
    if getattr(args, "compute_backend", None):
        from .compute import set_default_backend

        set_default_backend(args.compute_backend)
    try:
        if args.command == "list":
            return _cmd_list(args)
        if args.command == "run":
            return _cmd_run(args)
        if args.command == "reproduce":
            return _cmd_reproduce(args)
        if args.command == "report":
            return _cmd_report(args)
        if args.command == "track":
            from .io.command import run_track

            return run_track(args)
    except ConfigError as e:
        print(f"pursuit: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # output piped into head and closed
        return 0
    return 1  # pragma: no cover - argparse guarantees a command


def _cmd_list(args) -> int:
    kinds = {"models": "model", "filters": "filter", "scenarios": "scenario", "fading": "fading"}
    wanted = [args.kind] if args.kind else ["models", "filters", "fading", "scenarios", "experiments"]
    for plural in wanted:
        print(f"{plural}:")
        if plural == "experiments":
            for name in list_experiments():
                try:
                    exp = load_experiment(find_experiment(name))
                    title = exp.title
                except ConfigError as e:
                    title = f"(invalid: {e.message})"
                print(f"  {name:<22} {title}")
            continue
        for comp in registry.components(kinds[plural]):
            print(f"  {comp.name:<22} {comp.summary}")
            if args.verbose:
                for p in comp.params:
                    default = "" if p.default is registry.REQUIRED else f" = {p.default!r}"
                    print(f"      {p.name} ({p.type}){default}: {p.doc}")
        print()
    return 0


def _check_overrides(args, source: str) -> None:
    for flag, value in (("--runs", args.runs), ("--chunk-size", args.chunk_size), ("--workers", args.workers)):
        if value is not None and value < 1:
            raise ConfigError(source, f"{flag}: must be at least 1, got {value}")
    if args.keep_runs is not None and args.keep_runs < 0:
        raise ConfigError(source, f"--keep-runs: must be a non-negative integer, got {args.keep_runs}")
    if args.scheduler is not None and "://" not in args.scheduler:
        raise ConfigError(source, f"--scheduler: expected an address like tcp://HOST:PORT, got {args.scheduler!r}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(source, f"--seed: must be a non-negative integer, got {args.seed}")


def _backend(args, source: str):
    from .engine.backends import make_backend

    try:
        return make_backend(workers=args.workers, scheduler=args.scheduler)
    except (ImportError, ConnectionError, OSError, ValueError) as e:
        raise ConfigError(source, str(e)) from None


def _execute(exp, out_dir: Path, args, backend) -> None:
    from .engine.backends import engine_options
    from .engine.montecarlo import DEFAULT_CHUNK, DEFAULT_KEEP_RUNS
    from .report.output import format_table, write_output

    with engine_options(backend=backend, store=args.store, keep_runs=args.keep_runs):
        output = exp.run(runs=args.runs, seed=args.seed, progress=not args.no_progress, chunk_size=args.chunk_size)
    header = exp.title or exp.name
    print(f"== {exp.name}: {header}")
    for table in output.tables:
        print()
        print(format_table(table))
    formats = ("png",) if args.no_pdf else ("png", "pdf")
    engine = {
        "backend": backend.describe(),
        "chunk_size": output.sidecar.get("chunk_size") or DEFAULT_CHUNK,
        "store": args.store or "auto",
    }
    command = shlex.join(["pursuit", *args.argv])
    keep = DEFAULT_KEEP_RUNS if args.keep_runs is None else args.keep_runs
    write_output(output, out_dir, formats=formats, engine=engine, command=command, full_data=args.full_data, keep_runs=keep)
    print(f"\nwrote {out_dir} (report: {out_dir / 'report.html'})")


def _cmd_run(args) -> int:
    _check_overrides(args, args.config)
    exp = load_experiment(args.config)
    if args.runs is not None:
        exp.check_runs(args.runs)
    out = Path(args.out) if args.out else Path("results") / exp.name
    with _backend(args, args.config) as backend:
        _execute(exp, out, args, backend)
    return 0


def _cmd_reproduce(args) -> int:
    from .report.html import write_index

    _check_overrides(args, args.name)
    names = list_experiments() if args.name == "all" else [args.name]
    if not names:
        raise ConfigError(args.name, "no bundled experiments found")
    # Validate every file before running any, so a bad one stops the batch early.
    exps = [load_experiment(find_experiment(n)) for n in names]
    if args.runs is not None:
        for exp in exps:
            exp.check_runs(args.runs)
    root = Path(args.out) if args.out else Path("results")
    with _backend(args, args.name) as backend:
        for exp in exps:
            _execute(exp, root / exp.name, args, backend)
            print()
    if args.name == "all":
        index = write_index(root, [root / exp.name for exp in exps])
        print(f"wrote {index}")
    return 0


def _cmd_report(args) -> int:
    from .report.html import write_index, write_report
    from .storage import iter_output_folders

    folder = Path(args.dir)
    if not folder.is_dir():
        raise ConfigError(folder, "no such folder")
    try:
        if (folder / "run.json").is_file():
            print(f"wrote {write_report(folder)}")
            return 0
        subs = list(iter_output_folders(folder))
        if not subs:
            raise ConfigError(folder, "not a pursuit output folder: no run.json here or in its sub-folders")
        for sub in subs:
            print(f"wrote {write_report(sub)}")
        print(f"wrote {write_index(folder, subs)}")
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(folder, str(e)) from None
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
