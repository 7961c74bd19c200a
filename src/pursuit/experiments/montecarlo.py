"""The ``montecarlo`` experiment kind: one scenario, several filters, many runs."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config.build import build_filters, build_scenario, resolve_paper, resolve_section
from ..engine.backends import current_options
from ..engine.montecarlo import DEFAULT_KEEP_RUNS, monte_carlo
from ..registry import Param, register
from ..report.figures import consistency_over_time, rmse_over_time, trajectory
from ..results import MonteCarloResult
from ..tables import ExperimentOutput, Table

__all__ = [
    "MonteCarloPlan",
    "summary_table",
    "consistency_table",
    "paper_table",
    "standard_figures",
]


def run_index(field_name: str, v: int) -> int:
    """A ``Param`` check: a run number is a non-negative integer (runs are numbered from 0)."""
    if v < 0:
        raise ValueError(f"{field_name}: must be a non-negative integer (runs are numbered from 0), got {v}")
    return v


def check_run_exists(field_name: str, index: int, runs: int) -> None:
    """Raise ``ValueError`` naming ``field_name`` when run ``index`` does not exist among ``runs`` runs."""
    if index >= runs:
        raise ValueError(
            f"{field_name}: run {index} does not exist with {runs} run{'s' if runs != 1 else ''} "
            f"(runs are numbered 0..{runs - 1})"
        )


FIGURE_PARAMS = (
    Param("trajectory_run", "int", 0, "which run's trajectory to draw (0 .. runs-1)", check=run_index),
    Param("log_rmse", "bool", False, "logarithmic RMSE axes"),
)

CONSISTENCY_COLUMNS = ("anees", "anees_low", "anees_high", "anees_inside", "anis", "anis_low", "anis_high", "anis_inside")


def summary_columns(scenario: Any) -> list[str]:
    """The columns of :meth:`MonteCarloResult.summary` for this scenario (what a ``[[paper]]`` metric may name)."""
    cols = []
    if scenario.position_indices:
        cols.append("rmse_position")
    if scenario.velocity_indices:
        cols.append("rmse_velocity")
    cols += [f"rms_{label}" for label in scenario.state_labels]
    return [*cols, *CONSISTENCY_COLUMNS, "wall_time_s", "runs"]


def summary_table(result: MonteCarloResult, name: str = "summary", title: str = "") -> Table:
    """Errors and run time per filter as a :class:`Table` (consistency is in :func:`consistency_table`)."""
    rows = result.summary()
    cols: list[str] = []
    for r in rows:
        for key in r:
            if key not in cols and key not in CONSISTENCY_COLUMNS:
                cols.append(key)
    return Table(name, title or f"{result.scenario}: {result.runs} runs, seed {result.seed}", cols, [[r.get(c) for c in cols] for r in rows])


def consistency_table(result: MonteCarloResult, name: str = "consistency") -> Table | None:
    """ANEES and ANIS per filter with the per-step chi-square 95 % bounds (None if no filter reports them)."""
    rows = result.summary()
    cols = [c for c in CONSISTENCY_COLUMNS if any(c in r for r in rows)]
    if not cols:
        return None
    return Table(
        name,
        "Consistency: anees / anis = average NEES / NIS over all runs and steps; *_low, *_high = chi-square 95 % "
        "bounds for one step's average over the runs (chi2.ppf(0.025 / 0.975, M d) / M for M runs, d dof; "
        "not bounds for the all-step average, whose values are correlated in time); "
        "*_inside = share of steps whose average lies inside them",
        ["filter", *cols],
        [[r["filter"], *[r.get(c) for c in cols]] for r in rows],
    )


def paper_table(result: MonteCarloResult, paper: list[dict[str, Any]], name: str = "paper_vs_measured") -> Table:
    """Paper values beside ours, with the ratio measured / paper."""
    summary = {r["filter"]: r for r in result.summary()}
    rows = []
    for p in paper:
        measured = summary[p["filter"]].get(p["metric"])
        ratio = measured / p["value"] if isinstance(measured, float) and p["value"] else None
        rows.append([p["filter"], p["metric"], p["value"], measured, ratio, p["note"]])
    return Table(
        name,
        "Paper's values (source: paper) beside ours (source: measured)",
        ["filter", "metric", "paper", "measured", "measured/paper", "note"],
        rows,
        kind="paper",
    )


def standard_figures(result: MonteCarloResult, scenario: Any, figure_opts: dict[str, Any]) -> dict[str, Any]:
    """RMSE against time for position and velocity, ANEES/ANIS with their χ² band, and one run's trajectory."""
    figs: dict[str, Any] = {}
    log = figure_opts.get("log_rmse", False)
    if result.position_indices:
        figs["rmse_position"] = rmse_over_time(result, "position", log=log)
    if result.velocity_indices:
        figs["rmse_velocity"] = rmse_over_time(result, "velocity", log=log)
    if not result.position_indices and not result.velocity_indices:
        figs["rmse_state"] = rmse_over_time(result, "state", log=log)
    consistency = consistency_over_time(result)
    if consistency is not None:
        figs["consistency"] = consistency
    run = run_index("figures.trajectory_run", figure_opts.get("trajectory_run", 0))
    check_run_exists("figures.trajectory_run", run, result.runs)
    # a summary-mode result keeps only its first runs whole; the title names the run drawn
    run = min(run, result.stored().runs - 1)
    anchors = getattr(getattr(scenario, "measurement", None), "anchors", None)
    figs["trajectory"] = trajectory(result, run, landmarks=anchors)
    return figs


@dataclass
class MonteCarloPlan:
    """A validated ``montecarlo`` experiment."""

    name: str
    scenario: Any
    filters: list[Any]
    figure_opts: dict[str, Any]
    paper: list[dict[str, Any]]
    sections: dict[str, Any] = field(repr=False)

    def check_runs(self, runs: int) -> None:
        """Raise ``ValueError`` (naming the field) when an option refers to a run beyond ``runs``."""
        check_run_exists("figures.trajectory_run", self.figure_opts["trajectory_run"], runs)

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Run the comparison and assemble tables and figures."""
        self.check_runs(runs)
        # in summary mode, keep the run whose trajectory is drawn among the runs kept whole
        keep = current_options().keep_runs
        keep = max(DEFAULT_KEEP_RUNS if keep is None else keep, self.figure_opts["trajectory_run"] + 1)
        result = monte_carlo(
            self.scenario, self.filters, runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
            keep_runs=keep, label=self.name,
        )
        tables = [summary_table(result)]
        consistency = consistency_table(result)
        if consistency is not None:
            tables.append(consistency)
        if self.paper:
            tables.append(paper_table(result, self.paper))
        figs = standard_figures(result, self.scenario, self.figure_opts)
        return ExperimentOutput(self.name, "", "", tables, figs, results={"result": result})


_KNOWN_SECTIONS = {"scenario", "filters", "figures", "paper"}


@register(
    "experiment",
    "montecarlo",
    "Compare filters on one scenario over many runs; sections [scenario], [[filters]], [figures], [[paper]]",
)
def _montecarlo(sections: dict[str, Any], path: Path, name: str) -> MonteCarloPlan:
    for key in sections:
        if key not in _KNOWN_SECTIONS:
            raise ValueError(f"{key}: unknown section (known: experiment, {', '.join(sorted(_KNOWN_SECTIONS))})")
    scenario = build_scenario(sections)
    filters = build_filters(sections, scenario)
    figure_opts = resolve_section(sections, "figures", FIGURE_PARAMS)
    paper = resolve_paper(sections, [f.name for f in filters])
    columns = summary_columns(scenario)
    for i, vals in enumerate(paper):
        if vals["metric"] not in columns:
            raise ValueError(f"paper[{i}].metric: no summary column {vals['metric']!r} (have {', '.join(columns)})")
    return MonteCarloPlan(name, scenario, filters, figure_opts, paper, sections)
