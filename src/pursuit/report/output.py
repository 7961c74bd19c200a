"""Writing an experiment's output folder, all or nothing, and formatting tables."""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from .._json import json_default
from ..engine.montecarlo import DEFAULT_KEEP_RUNS
from ..results import MonteCarloResult
from ..tables import ExperimentOutput, Table, cell, write_csv
from . import html

__all__ = ["write_output", "format_table", "versions", "cell", "FILES"]

FILES = {
    "run.json": "the sidecar: experiment, root seed, runs, configuration, package versions, tables, file manifest",
    "summary.csv": "one row per filter: RMSEs, per-component RMS, wall time",
    "errors.csv": "tidy errors: one row per (result, filter, run, step); estimate minus truth per component, NEES, NIS",
    "per_step.csv": "per (result, filter, step): RMSE of each component over all runs, ANEES, ANIS with the step's chi-square 95 % bounds, step-info means",
    "report.html": "this report (self-contained)",
}


def versions() -> dict[str, str]:
    """Versions of Python, the platform and pursuit's dependencies."""
    import matplotlib
    import scipy

    from .. import __version__

    out = {
        "pursuit": __version__,
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "matplotlib": matplotlib.__version__,
    }
    for optional in ("dask", "distributed"):
        try:
            out[optional] = metadata.version(optional)
        except metadata.PackageNotFoundError:
            pass
    out.update(platform=platform.platform(), machine=platform.machine(), processor=platform.processor() or "unknown")
    return out


def format_table(table: Table) -> str:
    """A table as aligned plain text, with its title and notes."""
    cells = [[cell(v) for v in row] for row in table.rows]
    widths = [max([len(c)] + [len(r[i]) for r in cells]) for i, c in enumerate(table.columns)]
    lines = [table.title] if table.title else []
    lines.append("  ".join(c.ljust(w) for c, w in zip(table.columns, widths)))
    lines.append("  ".join("-" * w for w in widths))
    for r in cells:
        lines.append("  ".join(v.rjust(w) if _numeric(v) else v.ljust(w) for v, w in zip(r, widths)))
    if table.notes:
        lines.append(table.notes)
    return "\n".join(lines)


def _numeric(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _runs_kept_whole(results: dict[str, Any]) -> int | None:
    """How many runs the saved results keep whole (the fewest over them); None when all are full-mode."""
    summary = [r for r in results.values() if r.store == "summary"]
    if not summary:
        return None
    return min(r.examples.runs if r.examples is not None else 0 for r in summary)


def _describe_kept(kept: int) -> str:
    return f"runs 0..{kept - 1} kept whole" if kept else "no run kept whole"


def save_figure(fig: Any, paths: list[Path], dpi: int = 150) -> None:
    """Save ``fig`` to each path (the format from its suffix), laying it out once, for the first.

    A constrained layout is made at every draw, and ``savefig`` draws twice
    when the figure has a layout engine (once to lay out, once to render):
    about 40 % of a figure's cost.  The first file (the PNG, which the
    report embeds) is drawn as before; the others are drawn once, with the
    layout it made: the figure's layout engine is taken away, not only
    switched off (matplotlib's placeholder for a switched-off engine still
    asks for the extra draw), and put back afterwards.  The PDFs are the
    same bytes either way.  Measured with ``benchmarks/_figure_cost.py``
    (CPU time against a PDF with its own layout): p4-bearings' PDFs 0.66x
    with the engine switched off, 0.50x removed; p1-ungm's 0.67x and 0.41x.
    """
    if not paths:
        return
    fig.savefig(paths[0], dpi=dpi)
    if len(paths) == 1:
        return
    engine = fig.get_layout_engine()
    if engine is not None:
        _remove_layout_engine(fig)  # keeps the axes where the first draw put them
    try:
        for path in paths[1:]:
            fig.savefig(path, dpi=dpi)
    finally:
        if engine is not None:
            fig.set_layout_engine(engine)


def _remove_layout_engine(fig: Any) -> None:
    """Leave ``fig`` without a layout engine (``set_layout_engine(None)`` reads rcParams, so they are held off)."""
    import matplotlib

    with matplotlib.rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)


def write_output(
    output: ExperimentOutput,
    out_dir: str | Path,
    *,
    formats: tuple[str, ...] = ("png", "pdf"),
    engine: dict[str, Any] | None = None,
    command: str | None = None,
    full_data: bool = False,
    keep_runs: int = DEFAULT_KEEP_RUNS,
) -> Path:
    """Write an experiment's output folder: tables, results, figures, sidecar and report.

    Writes one CSV per table, the tidy ``errors.csv`` and ``per_step.csv``
    of every result object, ``results/NAME.npz`` (read back by
    :func:`pursuit.load`), the figures in each of ``formats``, the
    ``run.json`` sidecar and ``report.html`` (see :mod:`pursuit.storage`).
    Everything is written into a temporary folder beside ``out_dir`` and
    moved into place only when complete, so an error leaves either the
    previous output or nothing, never a half-written folder; the swap is
    recoverable at every instant, and helper folders left by a killed
    earlier writer are cleaned up first (see :mod:`pursuit.output_folder`).

    Parameters
    ----------
    output
        What the experiment produced.
    out_dir
        The folder to (re)place.
    formats
        Figure formats (PNG is always written: the report embeds it).
    engine
        How the runs were computed (backend, chunk size, storage), for the sidecar.
    command
        The command line that produced it, for the sidecar.
    full_data
        Save every run: ``errors.csv`` with every (run, step) and each result
        object whole.  By default the folder is light: each Monte Carlo
        result is saved in summary mode (:meth:`MonteCarloResult.summarised`:
        the reduced statistics, from which every table, ``per_step.csv`` and
        the summaries are the same bits) with runs ``0 .. keep_runs-1`` kept
        whole, and ``errors.csv`` lists those runs only.
    keep_runs
        Runs kept whole in a light folder.
    """
    from ..output_folder import make_temp, recover, replace
    from ..storage import (
        monte_carlo_results,
        save_results,
        write_errors_csv,
        write_per_step_csv,
    )

    formats = tuple(dict.fromkeys(("png", *formats)))
    out_dir = Path(os.path.abspath(out_dir))  # "." has no name to put the helper folders beside
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    recover(out_dir)  # what a killed earlier writer of out_dir left behind
    tmp = make_temp(out_dir)
    try:
        files = {}
        for table in output.tables:
            write_csv(tmp / f"{table.name}.csv", table.columns, table.rows)
            files[f"{table.name}.csv"] = table.title or table.name
        # light by default: the per-step summaries of every run, the arrays of the first few
        saved = output.results if full_data else {
            k: v.summarised(keep_runs) if isinstance(v, MonteCarloResult) else v for k, v in output.results.items()
        }
        mc = monte_carlo_results(saved)
        if mc:
            write_errors_csv(tmp / "errors.csv", output.name, mc)
            write_per_step_csv(tmp / "per_step.csv", output.name, monte_carlo_results(output.results))
            kept = _runs_kept_whole(mc)
            files["errors.csv"] = FILES["errors.csv"] if kept is None else (
                FILES["errors.csv"] + f" (only runs kept whole: {_describe_kept(kept)}; --full-data lists every run)")
            files["per_step.csv"] = FILES["per_step.csv"]
        manifest = save_results(saved, tmp / "results")
        if output.figures:
            (tmp / "figures").mkdir()
            for name, fig in output.figures.items():
                save_figure(fig, [tmp / "figures" / f"{name}.{fmt}" for fmt in formats])
        sidecar = dict(output.sidecar)
        sidecar.setdefault("experiment", output.name)
        if output.title:
            sidecar.setdefault("title", output.title)
        if output.description:
            sidecar.setdefault("description", output.description)
        if engine:
            sidecar["engine"] = engine
        if command:
            sidecar["command"] = command
        if mc:
            # from what was saved, not from the flag: --full-data cannot bring back a summary-mode result's runs
            kept = _runs_kept_whole(mc)
            sidecar["data"] = "full" if kept is None else f"light: per-step summaries of every run, {_describe_kept(kept)}"
        sidecar["written"] = datetime.now(timezone.utc)
        sidecar["versions"] = versions()
        sidecar["tables"] = {
            t.name: {"title": t.title, "kind": t.kind, "notes": t.notes, "columns": t.columns, "rows": t.rows}
            for t in output.tables
        }
        sidecar["figures"] = list(output.figures)
        sidecar["figure_formats"] = list(formats)
        sidecar["results"] = manifest
        files["report.html"] = FILES["report.html"]
        sidecar["files"] = {"run.json": FILES["run.json"], **files}
        (tmp / "run.json").write_text(json.dumps(sidecar, indent=2, default=json_default) + "\n")
        html.write_report(tmp)  # looked up on the module at call time (tests replace it)
        replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir
