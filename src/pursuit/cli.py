"""The ``pursuit`` command line.

``pursuit list``                      models, filters, scenarios, experiments
``pursuit run CONFIG.toml``           run one experiment file
``pursuit reproduce NAME|all``        run bundled experiments (``experiments/NAME.toml``)
``pursuit report DIR``                rebuild report.html (and the index) from saved results
``pursuit track DATA --config M.toml`` run a configured filter on recorded or live measurements
``pursuit track --multi DETS --config M.toml`` track several targets in recorded or live detections

``run`` and ``reproduce`` take ``--workers N`` (local processes; ``auto``: one
per core) or ``--scheduler tcp://HOST:PORT`` (a Dask cluster) to spread the
chunks of runs; ``reproduce`` with several experiments and ``--workers N``
runs the experiments side by side instead, one per process.

``pursuit`` alone prints this list of commands; ``pursuit --version`` the
version; ``python -m pursuit`` is the same command.

Exit codes: 0 success, 2 bad input (config, arguments), 3 the computation
failed for want of workers (they kept dying, or a Dask cluster had none left),
130 interrupted (Ctrl-C), 143 terminated (SIGTERM), 129 hung up (SIGHUP), 1
unexpected failure.  On a signal the command stops its worker processes,
removes its temporary folder and prints one line; an output folder is never
left half-written.
"""

from __future__ import annotations

import argparse
import contextlib
import shlex
import signal
import sys
import warnings
from pathlib import Path
from typing import Sequence

# Imports of pursuit's own modules stay inside the commands: `pursuit list` and `--version` must not
# pay for NumPy, SciPy, matplotlib and every filter (3.3 s measured, most of it imports).

__all__ = ["main"]

COMMANDS = ("list", "run", "reproduce", "report", "track")

EXIT_BAD_INPUT = 2
EXIT_NO_WORKERS = 3
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports it


class Terminated(BaseException):
    """SIGTERM or SIGHUP reached the command: unwind (closing workers, removing temp folders) and exit 128 + signum.

    A ``BaseException``, like ``KeyboardInterrupt``, so that no ``except
    Exception`` on the way swallows it.
    """

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


@contextlib.contextmanager
def _signals_unwind():
    """Turn SIGINT, SIGTERM and SIGHUP into exceptions (the first one only) while the command runs.

    Raising unwinds every ``with`` and ``finally`` on the way: local workers
    are stopped, a temporary output folder is removed.  Further signals
    during that clean-up are ignored, so it is not cut short (it is bounded:
    workers get 2 s to stop before they are killed).  A signal that was
    ignored when the command started (``nohup`` ignores SIGHUP, a shell's
    background job SIGINT) stays ignored.
    """
    names = [n for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)]
    names = [n for n in names if signal.getsignal(getattr(signal, n)) is not signal.SIG_IGN]
    fired = False

    def handler(signum, frame):
        nonlocal fired
        if fired:
            return
        fired = True
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Terminated(signum)

    try:
        previous = {n: signal.signal(getattr(signal, n), handler) for n in names}
    except ValueError:  # not the main thread (main() called from a thread): leave signals alone
        yield
        return
    try:
        yield
    finally:
        for n, h in previous.items():
            signal.signal(getattr(signal, n), h)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings from the engine as one line (``pursuit: warning: ...``), not with a source line."""
    print(f"pursuit: warning: {message}", file=sys.stderr if file is None else file)


def _command(argv: Sequence[str]) -> str | None:
    """The sub-command named on the command line (its first word that is no option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word
    return None


def _parser(track: bool = True) -> argparse.ArgumentParser:
    """The argument parser; ``track=False`` gives a stand-in for ``track``'s (its options import the io stack)."""
    from . import __version__

    p = argparse.ArgumentParser(prog="pursuit", description="Tracking and positioning filters, compared fairly.")
    p.add_argument("-V", "--version", action="version", version=f"pursuit {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    ls = sub.add_parser("list", help="list models, filters, scenarios, fading strategies and experiments")
    ls.add_argument("kind", nargs="?", choices=["models", "filters", "scenarios", "fading", "trackers", "experiments"], help="only this kind")
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

    if track:
        from .io.command import add_track_parser

        add_track_parser(sub)
    else:  # never parses: main builds the full parser when the command is track
        sub.add_parser("track", help="run a configured filter on recorded or live measurements")
    return p


def _add_engine_arguments(sp: argparse.ArgumentParser) -> None:
    g = sp.add_argument_group("where the runs are computed")
    where = g.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_workers,
        metavar="N",
        help="N local processes (or auto: one per core this process may use): reproduce with several experiments "
        "runs them side by side, one per process; otherwise the chunks of runs are spread over them",
    )
    where.add_argument(
        "--scheduler", metavar="tcp://HOST:PORT", help="run the chunks on a Dask cluster (needs pursuit[distributed])"
    )
    g.add_argument(
        "--worker-timeout",
        type=float,
        metavar="SECONDS",
        help="with --scheduler: give up (exit 3) when the cluster has had no worker for this long (default 60)",
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


def _workers(text: str) -> int:
    """``--workers`` for argparse: a whole number or ``auto`` (the number is checked later, naming the flag)."""
    from .engine.tasks import parse_workers  # light: no NumPy

    try:
        return parse_workers(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e).removeprefix("--workers: ")) from None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _command(argv)
    parser = _parser(track=command not in COMMANDS or command == "track")
    args = parser.parse_args(argv)
    from .experiment import ConfigError

    if args.command is None:  # a bare `pursuit`: what it can do, not an argparse complaint
        parser.print_help()
        return 0
    args.argv = argv
    if getattr(args, "compute_backend", None):
        from .compute import set_default_backend

        set_default_backend(args.compute_backend)
    try:
        with _signals_unwind(), warnings.catch_warnings():
            warnings.showwarning = _show_warning  # restored by catch_warnings
            return _dispatch(args)
    except ConfigError as e:
        print(f"pursuit: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # output piped into head and closed
        return 0
    except KeyboardInterrupt:
        print("pursuit: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated as e:
        print(f"pursuit: stopped by {signal.Signals(e.signum).name}", file=sys.stderr)
        return 128 + e.signum
    except Exception as e:
        if not _workers_lost(e):
            raise
        print(f"pursuit: error: {e}", file=sys.stderr)
        return EXIT_NO_WORKERS


def _memory_limit_problem() -> str | None:
    """What is wrong with ``$PURSUIT_MEMORY_LIMIT``, if set and not a size (checked before anything runs)."""
    from .engine.memory import available_bytes

    try:
        available_bytes()
    except ValueError as e:
        return str(e)
    return None


def _workers_lost(e: Exception) -> bool:
    """Whether ``e`` is the engine's ``WorkerLost``, without importing the engine (and NumPy) to ask.

    A command that never loaded the engine cannot have lost a worker; this keeps
    ``pursuit list`` and ``--version`` free of the numerical libraries.
    """
    backends = sys.modules.get("pursuit.engine.backends")
    return backends is not None and isinstance(e, backends.WorkerLost)


def _dispatch(args) -> int:
    if args.command in ("run", "reproduce"):
        problem = _memory_limit_problem()
        if problem:
            print(f"pursuit: error: {problem}", file=sys.stderr)
            return EXIT_BAD_INPUT
    if args.command == "list":
        return _cmd_list(args)
    if args.command == "run":
        return _cmd_run(args)
    if args.command == "reproduce":
        return _cmd_reproduce(args)
    if args.command == "report":
        return _cmd_report(args)
    if args.command == "track" and args.multi:
        from .io.multi import run_track_multi

        return run_track_multi(args)
    if args.command == "track":
        from .io.command import run_track

        return run_track(args)
    return 1  # pragma: no cover - argparse guarantees a command


def _cmd_list(args) -> int:
    """Print the components and experiments.

    Names and summaries come from :mod:`pursuit._catalog` (a test keeps it
    equal to the registry), so listing imports no component module;
    ``--verbose`` needs every parameter and imports them.  Experiments show
    their title as read from the file (``pursuit run`` validates the rest).
    """
    from .experiment import ConfigError, find_experiment, list_experiments, read_toml

    kinds = {"models": "model", "filters": "filter", "scenarios": "scenario", "fading": "fading", "trackers": "tracker"}
    wanted = [args.kind] if args.kind else ["models", "filters", "fading", "scenarios", "trackers", "experiments"]
    for plural in wanted:
        print(f"{plural}:")
        if plural == "experiments":
            for name in list_experiments():
                try:
                    _, doc = read_toml(find_experiment(name))
                    table = doc.get("experiment")
                    table = table if isinstance(table, dict) else {}
                    title, reference = str(table.get("title", "")), str(table.get("reference", ""))
                except ConfigError as e:
                    title, reference = f"(invalid: {e.message})", ""
                print(f"  {name:<22} {title}")
                if args.verbose and reference:
                    print(f"      after: {reference}")
            continue
        if args.verbose:
            from . import registry

            for comp in registry.components(kinds[plural]):
                print(f"  {comp.name:<22} {comp.summary}")
                for p in comp.params:
                    default = "" if p.default is registry.REQUIRED else f" = {p.default!r}"
                    print(f"      {p.name} ({p.type}){default}: {p.doc}")
        else:
            from ._catalog import CATALOG

            for name, summary in CATALOG[kinds[plural]]:
                print(f"  {name:<22} {summary}")
        print()
    return 0


def _check_overrides(args, source: str) -> None:
    from .experiment import ConfigError

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
    from .experiment import ConfigError

    try:
        return make_backend(workers=args.workers, scheduler=args.scheduler, worker_timeout=args.worker_timeout)
    except (ImportError, ConnectionError, OSError, ValueError) as e:
        raise ConfigError(source, str(e)) from None


def _execute(exp, out_dir: Path, args, backend, side_by_side: int = 1) -> None:
    from .engine.backends import engine_options
    from .engine.montecarlo import DEFAULT_CHUNK, DEFAULT_KEEP_RUNS
    from .report.output import format_table, write_output

    # the header first, so that it stands above the experiment's progress bars
    print(f"== {exp.name}: {exp.title or exp.name}", flush=True)
    with engine_options(backend=backend, store=args.store, keep_runs=args.keep_runs):
        output = exp.run(runs=args.runs, seed=args.seed, progress=not args.no_progress, chunk_size=args.chunk_size)
    for table in output.tables:
        print()
        print(format_table(table))
    formats = ("png",) if args.no_pdf else ("png", "pdf")
    engine = {
        "backend": backend.describe(),
        "chunk_size": output.sidecar.get("chunk_size") or DEFAULT_CHUNK,
        "store": args.store or "auto",
    }
    if side_by_side > 1:  # reproduce --workers: this experiment computed whole in one of these processes
        engine["experiments_side_by_side"] = side_by_side
    command = shlex.join(["pursuit", *args.argv])
    keep = DEFAULT_KEEP_RUNS if args.keep_runs is None else args.keep_runs
    write_output(output, out_dir, formats=formats, engine=engine, command=command, full_data=args.full_data, keep_runs=keep)
    print(f"\nwrote {out_dir} (report: {out_dir / 'report.html'})")


def _cmd_run(args) -> int:
    from .experiment import load_experiment

    _check_overrides(args, args.config)
    exp = load_experiment(args.config)
    if args.runs is not None:
        exp.check_runs(args.runs)
    out = Path(args.out) if args.out else Path("results") / exp.name
    with _backend(args, args.config) as backend:
        _execute(exp, out, args, backend)
    return 0


def _cmd_reproduce(args) -> int:
    from .experiment import ConfigError, find_experiment, list_experiments, load_experiment
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
    if len(exps) > 1 and args.scheduler is None and (args.workers or 1) > 1:
        _reproduce_side_by_side(exps, root, args)
    else:
        with _backend(args, args.name) as backend:
            for exp in exps:
                _execute(exp, root / exp.name, args, backend)
                print()
    if args.name == "all":
        index = write_index(root, [root / exp.name for exp in exps])
        print(f"wrote {index}")
    return 0


def _reproduce_side_by_side(exps, root: Path, args) -> None:
    """Every experiment whole in one of ``args.workers`` processes, the costliest (``cpu_s``) first.

    Each experiment computes its runs serially in its process, as
    ``--workers 1`` would, so its files are the same bits; its console output
    is printed here, whole, when it ends (no progress bars).
    """
    from .engine.tasks import run_tasks

    order = sorted(range(len(exps)), key=lambda i: -exps[i].cpu_s)  # stable: ties keep the file order
    jobs = [(str(exp.path), str(root / exp.name), args) for exp in exps]
    workers = min(args.workers, len(exps))
    print(f"pursuit: {len(exps)} experiments side by side in {workers} processes", flush=True)

    def show(i: int, text: str) -> None:
        print(text, end="" if text.endswith("\n") else "\n")
        print(flush=True)

    run_tasks(_reproduce_one, jobs, workers, show, first=order)


def _reproduce_one(path: str, out: str, args) -> str:
    """One experiment of :func:`_reproduce_side_by_side`, in a worker: run, write, return what it printed."""
    import io

    from .engine.backends import Serial
    from .experiment import load_experiment

    if getattr(args, "compute_backend", None):
        from .compute import set_default_backend

        set_default_backend(args.compute_backend)
    args = argparse.Namespace(**{**vars(args), "no_progress": True})
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer), warnings.catch_warnings():
        warnings.showwarning = _show_warning
        _execute(load_experiment(path), Path(out), args, Serial(), side_by_side=args.workers)
    return buffer.getvalue()


def _cmd_report(args) -> int:
    from .experiment import ConfigError
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
