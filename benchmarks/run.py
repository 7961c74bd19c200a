"""Run every ``benchmarks/bench_*.py`` and write ``docs/benchmarks.md``.

Each benchmark module has a ``main(quick=False)`` that measures pursuit and
its peers *in the same run* and prints a markdown table.  This script runs
them in turn, captures the tables and writes them, with the machine's
description and the command, to ``docs/benchmarks.md``.

NumPy's BLAS and OpenMP run on one thread in every benchmark
(``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` set to 1
before NumPy is imported, :mod:`_one_core`), so "one core" rows are one core;
the numba rows set their own thread counts.

Usage::

    make bench                                   # peers installed in .bench-venv
    .venv/bin/python benchmarks/run.py --quick    # smoke run, small sizes, no file written
"""

from __future__ import annotations

import _one_core  # first: NumPy must load its BLAS with one thread (benchmarks/ is on sys.path)

_one_core.pin()

import argparse  # noqa: E402
import contextlib  # noqa: E402
import importlib.util  # noqa: E402
import io  # noqa: E402
import os  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
DOC = HERE.parent / "docs" / "benchmarks.md"


def machine() -> str:
    """One line describing the CPU, core count, Python and NumPy."""
    import numpy as np

    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, Python {platform.python_version()}, NumPy {np.__version__}, {platform.system()} {platform.machine()}"


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = mod
    spec.loader.exec_module(mod)
    return mod


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes; do not write docs/benchmarks.md")
    ap.add_argument("--only", help="run only bench_NAME.py")
    args = ap.parse_args(argv)
    sections = []
    for path in sorted(HERE.glob("bench_*.py")):
        if args.only and path.stem != f"bench_{args.only}":
            continue
        mod = _load(path)
        buf = io.StringIO()
        print(f"== {path.name}", flush=True)
        with contextlib.redirect_stdout(buf):
            mod.main(quick=args.quick)
        print(buf.getvalue(), flush=True)
        title = (mod.__doc__ or path.stem).strip().splitlines()[0]
        sections.append(f"## {title}\n\nSource: `benchmarks/{path.name}`\n\n{buf.getvalue().strip()}\n")
    if args.quick or args.only:
        return 0
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=HERE).stdout.strip()
    except OSError:
        rev = "unknown"
    head = (
        "# Benchmarks\n\n"
        "Measured by `make bench` (which runs `benchmarks/run.py` in `.bench-venv`, where the peer\n"
        "libraries are installed; pursuit itself never depends on them). Every table compares\n"
        "implementations measured in the same run on the same machine; times are medians of repeated\n"
        "runs. Ratios are what to compare across machines, not absolute rates.\n\n"
        f"* Machine: {machine()}\n"
        f"* Date: {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}, commit {rev}\n\n"
    )
    DOC.write_text(head + "\n".join(sections))
    print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
