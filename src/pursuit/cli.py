"""The ``pursuit`` command line.

``pursuit list``                      models, filters, scenarios, experiments
``pursuit run CONFIG.toml``           run one experiment file
``pursuit reproduce NAME|all``        run bundled experiments (``experiments/NAME.toml``)

Exit codes: 0 success, 2 bad input (config, arguments), 1 unexpected failure.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from . import registry
from .experiment import ConfigError, find_experiment, list_experiments, load_experiment

__all__ = ["main"]

EXIT_BAD_INPUT = 2


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pursuit", description="Tracking and positioning filters, compared fairly.")
    sub = p.add_subparsers(dest="command", required=True)

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
        sp.add_argument("--pdf", action="store_true", help="also write figures as PDF")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "list":
            return _cmd_list(args)
        if args.command == "run":
            return _cmd_run(args)
        if args.command == "reproduce":
            return _cmd_reproduce(args)
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
    for flag, value in (("--runs", args.runs), ("--chunk-size", args.chunk_size)):
        if value is not None and value < 1:
            raise ConfigError(source, f"{flag}: must be at least 1, got {value}")
    if args.seed is not None and args.seed < 0:
        raise ConfigError(source, f"--seed: must be a non-negative integer, got {args.seed}")


def _execute(exp, out_dir: Path, args) -> None:
    from .report.output import format_table, write_output

    output = exp.run(runs=args.runs, seed=args.seed, progress=not args.no_progress, chunk_size=args.chunk_size)
    header = exp.title or exp.name
    print(f"== {exp.name}: {header}")
    for table in output.tables:
        print()
        print(format_table(table))
    formats = ("png", "pdf") if args.pdf else ("png",)
    write_output(output, out_dir, formats=formats)
    print(f"\nwrote {out_dir}")


def _cmd_run(args) -> int:
    _check_overrides(args, args.config)
    exp = load_experiment(args.config)
    out = Path(args.out) if args.out else Path("results") / exp.name
    _execute(exp, out, args)
    return 0


def _cmd_reproduce(args) -> int:
    _check_overrides(args, args.name)
    names = list_experiments() if args.name == "all" else [args.name]
    if not names:
        raise ConfigError(args.name, "no bundled experiments found")
    # Validate every file before running any, so a bad one stops the batch early.
    exps = [load_experiment(find_experiment(n)) for n in names]
    root = Path(args.out) if args.out else Path("results")
    for exp in exps:
        _execute(exp, root / exp.name, args)
        print()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
