"""The ``sweep`` experiment kind: filters compared over a range of one filter parameter.

Sections (besides ``[experiment]``):

``[scenario]``, ``[[filters]]``
    As in the ``montecarlo`` kind.
``[sweep]``
    ``parameter`` (a filter parameter, e.g. ``particles`` or ``fraction``)
    and its ``values``; every filter whose type has that parameter is run
    once per value, the others (baselines such as the EKF) once.  Also
    ``label`` (column name, default the parameter), ``component`` and
    ``metric`` of the headline RMSE, and ``pairs`` of filters to compare
    run by run.
``[[variants]]``
    Optional scenario variants: a ``label`` and any ``[scenario]`` keys to
    override; the whole sweep runs once per variant.
``[figures]``
    Which figures to draw (see ``FIGURE_PARAMS``).
``[[paper]]``
    The paper's numbers: ``filter``, ``metric`` (a summary column), ``value``,
    ``at`` (the swept value), ``variant`` and ``note``; printed beside ours in
    a ``Table(kind="paper")``.

Every value and variant uses the same root seed, so all filters at all
values see the same truth and measurements (common random numbers) and the
paired differences are run by run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import metrics, registry
from ..config.build import build_filters, build_scenario, resolve_paper, resolve_section
from ..engine.montecarlo import FILTER_STREAM, SCENARIO_STREAM, monte_carlo
from ..engine.snapshots import particle_snapshots
from ..registry import Param, register
from ..report.figures import consistency_over_time, labelled, rmse_over_time, trajectory
from ..report.sweep_figures import (
    abs_error_over_time,
    metric_against_value,
    particle_clouds,
)
from ..results import MonteCarloResult
from ..rng import run_streams
from ..tables import ExperimentOutput, Table
from .montecarlo import check_run_exists, run_index

__all__ = ["SweepPlan", "run_metric", "paired_difference"]


def _values(field_name: str, v: Any) -> list:
    if not isinstance(v, list) or not v:
        raise ValueError(f"{field_name}: expected a non-empty list of numbers")
    for x in v:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise ValueError(f"{field_name}: expected numbers, got {x!r}")
        if not math.isfinite(x):
            raise ValueError(f"{field_name}: expected finite numbers, got {x!r}")
    return list(v)


def _pairs(field_name: str, v: Any) -> list[tuple[str, str]]:
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) for s in p) for p in v):
        raise ValueError(f'{field_name}: expected a list of filter-name pairs, e.g. [["ICS-PF", "PF"]]')
    return [(a, b) for a, b in v]


def _values_or_empty(field_name: str, v: Any) -> list:
    return [] if v == [] else _values(field_name, v)


def _int_list(field_name: str, v: Any) -> list[int]:
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 1 for x in v):
        raise ValueError(f"{field_name}: expected a list of positive integers")
    return list(v)


def _str_list(field_name: str, v: Any) -> list[str]:
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ValueError(f"{field_name}: expected a list of strings")
    return list(v)


SWEEP_PARAMS = (
    Param("parameter", "str", doc="filter parameter to sweep (e.g. particles, fraction)"),
    Param("values", "any", doc="the values to run", check=_values),
    Param("label", "str", "", "column label for the value (default: the parameter name)"),
    Param("component", "str", "state", "component of the headline RMSE: position, velocity, state or a state label"),
    Param("metric", "str", "per-run", "headline RMSE: mean of per-run RMSEs (as Wei & Guo report) or pooled", choices=("per-run", "pooled")),
    Param("pairs", "any", [], "filter pairs [A, B] compared run by run (A − B, 95 % CI)", check=_pairs),
)

FIGURE_PARAMS = (
    Param("run", "int", 0, "which run the one-run figures show (0 .. runs-1)", check=run_index),
    Param("values", "any", [], "swept values that get one-run and RMSE-over-time figures", check=_values_or_empty),
    Param("log_rmse", "bool", True, "logarithmic RMSE-over-time axes"),
    Param("components", "any", [], "state labels that get their own RMSE-over-time figure", check=_str_list),
    Param("snapshot_steps", "any", [], "steps whose particle clouds are drawn", check=_int_list),
    Param("snapshot_value", "float", None, "swept value whose particle clouds are drawn (default: the last)"),
    Param("axis_label", "str", "", "name of the swept value on figure axes (default: 'PARAMETER LABEL', e.g. 'particles N')"),
)

PAPER_PARAMS = (
    Param("filter", "str", doc="filter name as in [[filters]]"),
    Param("metric", "str", doc="a summary column, e.g. rmse, rms_x, wall_time_s"),
    Param("value", "float", doc="the paper's number"),
    Param("at", "float", None, "the swept value the number belongs to"),
    Param("variant", "str", "", "the scenario variant (label) it belongs to"),
    Param("note", "str", "", "where the number comes from, caveats"),
)


def run_metric(result: MonteCarloResult, name: str, component: str, metric: str) -> tuple[np.ndarray, float, float]:
    """Per-run RMSEs ``(M,)``, the headline RMSE and its 95 % confidence half-width.

    ``metric="per-run"``: the mean of the per-run RMSEs (paper P1's UNGM
    metric), CI from their spread.  ``"pooled"``: RMSE over runs and steps,
    CI by the delta method on the per-run mean squared errors.
    """
    sq = result.squared_error(name, component)
    per_run = metrics.rmse_per_run(sq)
    M = per_run.size
    if metric == "per-run":
        sd = float(np.std(per_run, ddof=1)) if M > 1 else float("nan")
        return per_run, float(np.mean(per_run)), 1.96 * sd / np.sqrt(M)
    mse = per_run**2
    pooled = float(np.sqrt(np.mean(mse)))
    sd = float(np.std(mse, ddof=1)) if M > 1 else float("nan")
    half = 1.96 * sd / np.sqrt(M) / (2.0 * pooled) if pooled > 0 else float("nan")
    return per_run, pooled, half


def paired_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float, str]:
    """Mean of a − b over runs, its 95 % half-width, and a verdict."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    mean = float(np.mean(d))
    half = 1.96 * float(np.std(d, ddof=1)) / np.sqrt(d.size) if d.size > 1 else float("nan")
    if mean + half < 0:
        verdict = "A < B"
    elif mean - half > 0:
        verdict = "A > B"
    else:
        verdict = "no difference shown"
    return mean, half, verdict


def _fmt_value(v: float) -> str:
    return f"{v:g}"


def _slug(text: str) -> str:
    """A file-name-safe version of a label."""
    out = "".join(c.lower() if c.isalnum() else "-" for c in text)
    return "-".join(p for p in out.split("-") if p)


@dataclass
class SweepPlan:
    """A validated ``sweep`` experiment."""

    name: str
    sections: dict[str, Any] = field(repr=False)
    sweep: dict[str, Any]
    figure_opts: dict[str, Any]
    paper: list[dict[str, Any]]
    variants: list[dict[str, Any]]
    swept: list[bool]

    @property
    def label(self) -> str:
        return self.sweep["label"] or self.sweep["parameter"]

    def _scenario(self, variant: dict[str, Any] | None) -> Any:
        sections = dict(self.sections)
        if variant:
            table = dict(sections["scenario"])
            table.update({k: v for k, v in variant.items() if k != "label"})
            sections["scenario"] = table
        return build_scenario(sections)

    def _filters(self, scenario: Any, value: Any, baselines: bool) -> list[Any]:
        return [f for f, _ in self._filters_swept(scenario, value, baselines)]

    def _filters_swept(self, scenario: Any, value: Any, baselines: bool) -> list[tuple[Any, bool]]:
        """Filters at ``value`` (baselines too if asked), each with whether it takes the value."""
        entries, flags = [], []
        for entry, swept in zip(self.sections["filters"], self.swept):
            if swept:
                entries.append({**entry, self.sweep["parameter"]: value})
            elif baselines:
                entries.append(entry)
            else:
                continue
            flags.append(swept)
        if not entries:
            return []
        return list(zip(build_filters({"filters": entries}, scenario), flags))

    def validate(self) -> None:
        """Build every scenario variant and every filter at every value (nothing runs)."""
        for variant in self.variants or [None]:
            scenario = self._scenario(variant)
            for i, value in enumerate(self.sweep["values"]):
                self._filters(scenario, value, baselines=i == 0)

    # -- running -------------------------------------------------------------------
    def check_runs(self, runs: int) -> None:
        """Raise ``ValueError`` (naming the field) when an option refers to a run beyond ``runs``."""
        check_run_exists("figures.run", self.figure_opts["run"], runs)

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Run every variant and value; assemble tables and figures."""
        self.check_runs(runs)
        sw = self.sweep
        rows: list[dict[str, Any]] = []
        per_run: dict[tuple[str, Any, str], np.ndarray] = {}
        results: dict[str, MonteCarloResult] = {}
        first_results: dict[Any, tuple[Any, MonteCarloResult]] = {}
        for variant in self.variants or [None]:
            vlabel = variant["label"] if variant else ""
            scenario = self._scenario(variant)
            for i, value in enumerate(sw["values"]):
                built = self._filters_swept(scenario, value, baselines=i == 0)
                filters = [f for f, _ in built]
                result = monte_carlo(
                    scenario, filters, runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
                    store="full",  # per-run RMSEs, paired comparisons and one-run figures need every run
                    label=" ".join(filter(None, (self.name, vlabel, f"{self.label}={_fmt_value(value)}"))),
                )
                key = f"{vlabel}|{self.label}={_fmt_value(value)}" if vlabel else f"{self.label}={_fmt_value(value)}"
                results[key] = result
                if variant is None or variant is self.variants[0]:
                    first_results[value] = (scenario, result)
                for filt, swept in built:
                    e, head, half = run_metric(result, filt.name, sw["component"], sw["metric"])
                    at = value if swept else None
                    per_run[(vlabel, at, filt.name)] = e
                    if not swept:  # baselines are compared at every value
                        for v in sw["values"]:
                            per_run[(vlabel, v, filt.name)] = e
                    rows.append(self._row(result, filt.name, vlabel, at, head, half))
        tables = [self._summary_table(rows)]
        if self.paper:
            tables.append(self._paper_table(rows))
        if sw["pairs"]:
            tables.append(self._pairs_table(per_run))
        figures = self._figures(rows, first_results, seed)
        return ExperimentOutput(self.name, "", "", tables, figures, results=results)

    def _row(self, result: MonteCarloResult, name: str, variant: str, at: Any, head: float, half: float) -> dict[str, Any]:
        fr = result.filters[name]
        row: dict[str, Any] = {}
        if self.variants:
            row["variant"] = variant
        row[self.label] = at
        row["filter"] = name
        row["rmse"] = head
        row["ci95"] = half
        for i, lbl in enumerate(result.state_labels):
            row[f"rms_{lbl}"] = result.rmse(name, (i,))
        if result.position_indices:
            row["rmse_position"] = result.rmse(name, "position")
        if result.velocity_indices:
            row["rmse_velocity"] = result.rmse(name, "velocity")
        row.update(result.divergence(name) or {})  # diverged runs beside the RMSE (pursuit.divergence)
        nis = fr.info.get("nis")
        if nis is not None and np.isfinite(nis).any():
            row["nis_mean"] = float(np.nanmean(nis))
        if "ess" in fr.info:
            row["ess_mean"] = float(np.mean(fr.info["ess"]))
        if "resampled" in fr.info:
            row["resample_rate"] = float(np.mean(fr.info["resampled"]))
        row["wall_time_s"] = fr.wall_time
        row["runs"] = result.runs
        return row

    def _summary_table(self, rows: list[dict[str, Any]]) -> Table:
        cols: list[str] = []
        for r in rows:
            for k in r:
                if k not in cols:
                    cols.append(k)
        sw = self.sweep
        what = "mean of per-run RMSEs" if sw["metric"] == "per-run" else "RMSE pooled over runs and steps"
        notes = (
            f"rmse: {what} of the {sw['component']} component, ci95 its 95 % confidence half-width; "
            f"rms_*: pooled per state component; an empty {self.label} marks a filter without that parameter "
            "(run once). diverged: runs flagged diverged (docs/concepts.md, diverged runs), counted in the RMSEs; diverged_from_step: "
            "the earliest step flagged. wall_time_s: filtering time of the whole Monte Carlo run on this machine."
        )
        return Table("summary", f"{self.name}: swept {self.label}", cols, [[r.get(c) for c in cols] for r in rows], notes)

    def _lookup(self, rows, filt: str, at: Any, variant: str) -> dict[str, Any] | None:
        for r in rows:
            if r["filter"] != filt or (self.variants and r.get("variant") != variant):
                continue
            if at is None or r[self.label] is None or float(r[self.label]) == float(at):
                return r
        return None

    def _paper_table(self, rows: list[dict[str, Any]]) -> Table:
        out = []
        for p in self.paper:
            r = self._lookup(rows, p["filter"], p["at"], p["variant"])
            measured = None if r is None else r.get(p["metric"])
            ratio = measured / p["value"] if isinstance(measured, float) and p["value"] else None
            line = [p["variant"]] if self.variants else []
            at = p["at"] if r is None or r[self.label] is None else r[self.label]  # as written in [sweep]
            out.append(line + [at, p["filter"], p["metric"], p["value"], measured, ratio, p["note"]])
        cols = (["variant"] if self.variants else []) + [self.label, "filter", "metric", "paper", "measured", "measured/paper", "note"]
        return Table(
            "paper_vs_measured",
            "Paper's values (source: paper) beside ours (source: measured)",
            cols,
            out,
            "paper: the reference paper's number; measured: this run of pursuit. They are not expected to agree "
            "where the paper's set-up is unreadable (see docs/papers.md).",
            kind="paper",
        )

    def _pairs_table(self, per_run: dict[tuple[str, Any, str], np.ndarray]) -> Table:
        out = []
        for variant in [v["label"] for v in self.variants] or [""]:
            for value in self.sweep["values"]:
                for a, b in self.sweep["pairs"]:
                    ea, eb = per_run.get((variant, value, a)), per_run.get((variant, value, b))
                    if ea is None or eb is None:
                        continue
                    mean, half, verdict = paired_difference(ea, eb)
                    line = [variant] if self.variants else []
                    out.append(line + [value, a, b, float(np.mean(ea)), float(np.mean(eb)), mean, half, verdict])
        cols = (["variant"] if self.variants else []) + [self.label, "A", "B", "rmse_A", "rmse_B", "mean(A-B)", "ci95", "verdict"]
        return Table(
            "paired",
            "Run-by-run comparison of per-run RMSEs (same truth and measurements for A and B)",
            cols,
            out,
            "verdict 'A < B' when the whole 95 % interval of the mean difference is below 0 (A is more accurate).",
        )

    # -- figures -------------------------------------------------------------------
    def _figures(self, rows, first_results, seed: int) -> dict[str, Any]:
        figs: dict[str, Any] = {}
        opts = self.figure_opts
        sw = self.sweep
        label = self.label
        # the axis names the quantity, not only its symbol ("fraction l", not "l")
        xname = opts["axis_label"] or (sw["parameter"] if label == sw["parameter"] else f"{sw['parameter']} {label}")
        if len(sw["values"]) > 1:
            # the unit of the headline component, from the scenario (the variants share the state)
            unit = next(iter(first_results.values()))[1].component_unit(sw["component"]) if first_results else None
            # one RMSE figure per scenario variant: their scales can differ by orders of magnitude
            for variant in [v["label"] for v in self.variants] or [None]:
                sub = [r for r in rows if variant is None or r.get("variant") == variant]
                name = f"rmse_vs_{label}" if variant is None else f"rmse_vs_{label}_{_slug(variant)}"
                figs[name] = metric_against_value(
                    sub,
                    label,
                    "rmse",
                    error_key="ci95",
                    xlabel=xname,
                    ylabel=labelled(f"{sw['component']} RMSE", unit),
                    title=f"RMSE against {label}" + ("" if variant is None else f", {variant}"),
                )
            figs[f"time_vs_{label}"] = metric_against_value(
                rows, label, "wall_time_s", xlabel=xname, ylabel="filter wall time, all runs (s)", title=f"Run time against {label}"
            )
        for value in opts["values"]:
            if value not in first_results:
                continue
            scenario, result = first_results[value]
            run = opts["run"]  # checked against the runs by check_runs
            tag = f"{label}{_fmt_value(value)}"
            anchors = getattr(getattr(scenario, "measurement", None), "anchors", None)
            figs[f"{tag}_estimates"] = trajectory(result, run, landmarks=anchors, title=f"Truth and estimates, run {run}, {label} = {value:g}")
            if result.truth.shape[-1] == 1:
                figs[f"{tag}_abs_error"] = abs_error_over_time(result, run, 0)
            figs[f"{tag}_rmse"] = rmse_over_time(
                result, sw["component"], log=opts["log_rmse"], title=f"{sw['component']} RMSE over {result.runs} runs, {label} = {value:g}"
            )
            consistency = consistency_over_time(result, title=f"Consistency over {result.runs} runs, {label} = {value:g}")
            if consistency is not None:
                figs[f"{tag}_consistency"] = consistency
            for comp in opts["components"]:
                figs[f"{tag}_rmse_{comp}"] = rmse_over_time(
                    result, comp, log=opts["log_rmse"], title=f"{comp} RMSE over {result.runs} runs, {label} = {value:g}"
                )
        if opts["snapshot_steps"]:
            value = opts["snapshot_value"] if opts["snapshot_value"] is not None else sw["values"][-1]
            match = [v for v in first_results if float(v) == float(value)]
            if match:
                figs[f"{label}{_fmt_value(value)}_particles"] = self._clouds(match[0], first_results[match[0]], seed, opts)
        return figs

    def _clouds(self, value, scen_result, seed: int, opts) -> Any:
        scenario, result = scen_result
        run = opts["run"]
        sim = scenario.simulate(run_streams(seed, [run], SCENARIO_STREAM), 1)
        snaps = {}
        for filt in self._filters(scenario, value, baselines=True):
            if not hasattr(filt, "particles"):
                continue
            snaps[filt.name] = particle_snapshots(
                filt, sim.measurements, sim.prior, run_streams(seed, [run], FILTER_STREAM), opts["snapshot_steps"]
            )
        return particle_clouds(
            snaps, sim.truth[:, 0, :], 0, label=labelled(scenario.state_labels[0], result.unit(0)), title=f"Particles of run {run} after the step"
        )


_KNOWN_SECTIONS = {"scenario", "filters", "sweep", "variants", "figures", "paper"}


def _is_swept(value: float, values: list) -> bool:
    return any(float(value) == float(v) for v in values)


def _check_swept_values(values: list, figure_opts: dict[str, Any]) -> None:
    """``figures.values`` and ``figures.snapshot_value`` must name swept values (else no figure, silently)."""
    for i, v in enumerate(figure_opts["values"]):
        if not _is_swept(v, values):
            raise ValueError(f"figures.values[{i}]: {v:g} is not a swept value (sweep.values = {values})")
    snap = figure_opts["snapshot_value"]
    if snap is not None and not (math.isfinite(snap) and _is_swept(snap, values)):
        raise ValueError(f"figures.snapshot_value: {snap:g} is not a swept value (sweep.values = {values})")


def _summary_columns(scenario: Any) -> list[str]:
    """The columns of the sweep's summary rows (see ``SweepPlan._row``) a ``[[paper]]`` metric may name."""
    cols = ["rmse", "ci95", *[f"rms_{lbl}" for lbl in scenario.state_labels]]
    if scenario.position_indices:
        cols.append("rmse_position")
    if scenario.velocity_indices:
        cols.append("rmse_velocity")
    return [*cols, "nis_mean", "ess_mean", "resample_rate", "wall_time_s", "runs"]


@register(
    "experiment",
    "sweep",
    "Compare filters over values of one filter parameter (e.g. particles); sections [scenario], [[filters]], "
    "[sweep], [[variants]], [figures], [[paper]]",
)
def _sweep(sections: dict[str, Any], path: Path, name: str) -> SweepPlan:
    for key in sections:
        if key not in _KNOWN_SECTIONS:
            raise ValueError(f"{key}: unknown section (known: experiment, {', '.join(sorted(_KNOWN_SECTIONS))})")
    if "sweep" not in sections:
        raise ValueError("sweep: required section is missing")
    sweep = resolve_section(sections, "sweep", SWEEP_PARAMS)
    figure_opts = resolve_section(sections, "figures", FIGURE_PARAMS)
    variants = sections.get("variants", [])
    if not isinstance(variants, list) or not all(isinstance(v, dict) for v in variants):
        raise ValueError("variants: expected [[variants]] tables")
    for i, v in enumerate(variants):
        if not isinstance(v.get("label"), str) or not v["label"]:
            raise ValueError(f"variants[{i}].label: required (a short name for the scenario variant)")
    labels = [v["label"] for v in variants]
    if len(set(labels)) != len(labels):
        raise ValueError("variants: labels must be unique")
    entries = sections.get("filters")
    scenario = build_scenario(sections)
    build_filters(sections, scenario)  # validates every entry as written
    swept = [registry.get("filter", e["type"], f"filters[{i}].type").param(sweep["parameter"]) is not None for i, e in enumerate(entries)]
    if not any(swept):
        raise ValueError(f"sweep.parameter: no filter has a parameter {sweep['parameter']!r}")
    for i, (entry, takes) in enumerate(zip(entries, swept)):
        if takes and sweep["parameter"] in entry:  # it would be replaced by every swept value, unseen
            raise ValueError(
                f"filters[{i}].{sweep['parameter']}: set here but swept by [sweep] (values {sweep['values']}); "
                "remove it from the filter"
            )
    plan = SweepPlan(name, sections, sweep, figure_opts, [], variants, swept)
    try:
        plan.validate()
    except ValueError as e:
        raise ValueError(f"sweep.values: {e}") from None
    _check_swept_values(sweep["values"], figure_opts)
    names = set()
    for variant in variants or [None]:
        names.update(f.name for f in plan._filters(plan._scenario(variant), sweep["values"][0], True))
    paper = resolve_paper(sections, names, PAPER_PARAMS)
    columns = _summary_columns(scenario)
    for i, vals in enumerate(paper):
        if variants and vals["variant"] not in labels:
            raise ValueError(f"paper[{i}].variant: no variant labelled {vals['variant']!r}")
        if vals["metric"] not in columns:
            raise ValueError(f"paper[{i}].metric: no summary column {vals['metric']!r} (have {', '.join(columns)})")
        if vals["at"] is not None and not _is_swept(vals["at"], sweep["values"]):
            raise ValueError(f"paper[{i}].at: {vals['at']:g} is not a swept value (sweep.values = {sweep['values']})")
    plan.paper = paper
    for i, (a, b) in enumerate(sweep["pairs"]):
        for n in (a, b):
            if n not in names:
                raise ValueError(f"sweep.pairs[{i}]: no filter named {n!r} (have {', '.join(sorted(names))})")
    return plan
