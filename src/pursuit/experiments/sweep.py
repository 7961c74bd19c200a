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
``[limit]``
    Optional: a reference filter (``filter``, a filter table such as
    ``{ type = "pf", particles = 20000 }``) run once per variant with
    ``runs_factor`` times the runs, whose headline RMSE approximates the
    MMSE limit, the lowest mean error any filter can reach.  Its row is in
    the summary and the paper table, and a line in the RMSE figures.
``[[claim]]``
    Optional: the paper's claims, each given a verdict line from the
    measured numbers (see :func:`order_verdict`, :func:`value_verdict`):
    an ordering (``order = ["ICS-PF", "CS-PF", "PF"]``: each more accurate
    than the next, by paired 95 % intervals, at ``at`` or every swept value)
    or a value (``filter``, ``metric``, ``at``, ``value``; the value may be
    left to the matching ``[[paper]]`` entry).

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
from ..compute import numba_available
from ..config.build import build_filter, build_filters, build_scenario, resolve_paper, resolve_section, resolve_section_list
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

__all__ = ["SweepPlan", "run_metric", "paired_difference", "order_verdict", "value_verdict"]


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


def _at_least_one(field_name: str, v: Any) -> int:
    if v < 1:
        raise ValueError(f"{field_name}: must be at least 1, got {v}")
    return v


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
    Param("variants", "any", [], "scenario variants (labels) that get one-run figures (default: the first)", check=_str_list),
    Param("paper_label", "str", "paper", "legend name of the paper's values marked in the RMSE figures, e.g. 'paper (Table 1)'"),
    Param("paper_on_every_variant", "bool", False, "mark the paper's values in every variant's RMSE figure, named with their own variant"),
)

LIMIT_PARAMS = (
    Param("filter", "any", doc='the reference filter\'s table, e.g. { type = "pf", particles = 20000 }'),
    Param("runs_factor", "int", 2, "its runs: this many times the experiment's runs (2: 200 runs with the file's 100)", check=_at_least_one),
    Param("backend", "str", "auto", "its compute backend; auto: numba when installed, else the process default", choices=("auto", "numpy", "numba")),
    Param("label", "str", "", "its row's name (default: 'MMSE limit (PF, N = 20 000, 200 runs)')"),
)

CLAIM_PARAMS = (
    Param("order", "any", [], 'an ordering claim: filters from most to least accurate, e.g. ["ICS-PF", "CS-PF", "PF"]', check=_str_list),
    Param("filter", "str", "", "a value claim: the filter whose number the paper gives"),
    Param("metric", "str", "rmse", "the value claim's summary column (rmse, rms_<state>, rmse_position, rmse_velocity)"),
    Param("value", "float", None, "the paper's number (default: the matching [[paper]] entry's)"),
    Param("at", "float", None, "the swept value (an ordering: default every swept value)"),
    Param("variant", "str", "", "the scenario variant (label) the claim is checked on"),
    Param("source", "str", "", "where the claim is made (default: the matching [[paper]] note)"),
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


def _num(v: float, sign: bool = False) -> str:
    """Three significant digits, a true minus sign; ``sign``: always a sign."""
    text = f"{v:+.3g}" if sign else f"{v:.3g}"
    return text.replace("-", "\u2212")


def order_verdict(diffs: list[tuple[str, str, str, float, float]]) -> tuple[str, str]:
    """The verdict on "each filter is more accurate than the next" from paired differences.

    Parameters
    ----------
    diffs
        One ``(where, A, B, mean, half)`` per asserted ``A < B`` (``where``
        names the swept value, e.g. ``"N = 100"``): the mean over runs of
        A's error minus B's, and its 95 % half-width.

    Returns
    -------
    verdict, because
        ``"reproduced"`` when every interval lies below 0 (``because``: the
        weakest of them); ``"not reproduced"`` when some interval lies above 0
        (the largest such difference); else ``"not shown"`` (an interval
        holds 0; the one reaching highest, or a difference or half-width
        is not finite).
    """
    if not diffs:
        raise ValueError("diffs: no paired differences to judge")

    def line(d: tuple[str, str, str, float, float]) -> str:
        where, a, b, mean, half = d
        return f"{a} \u2212 {b} = {_num(mean, True)} [{_num(mean - half)}, {_num(mean + half)}] at {where}"

    broken = [d for d in diffs if not (math.isfinite(d[3]) and math.isfinite(d[4]))]
    if broken:
        # a non-finite per-run error (a diverged filter) fails every comparison: judge nothing from it
        return "not shown", line(broken[0]) + " (not finite)"
    against = [d for d in diffs if d[3] - d[4] > 0]
    if against:
        return "not reproduced", line(max(against, key=lambda d: d[3]))
    weakest = max(diffs, key=lambda d: d[3] + d[4])
    if weakest[3] + weakest[4] < 0:
        return "reproduced", "weakest: " + line(weakest)
    return "not shown", line(weakest) + " (the interval holds 0)"


def value_verdict(
    value: float, measured: float, half: float, limit: float | None = None, limit_half: float | None = None
) -> tuple[str, str]:
    """The verdict on a paper's error value against ours and, if given, the MMSE limit.

    ``"not reachable"`` when ``value`` lies below the limit's interval
    ``limit − limit_half`` (no filter has a lower mean error); else
    ``"not shown"`` when our interval ``measured ± √2·half`` reaches 0 (too
    wide to tell any error from none, e.g. a diverging filter); else
    ``"reproduced"`` when ``|measured − value| ≤ √2·half`` (the 95 % interval
    of the difference of two Monte Carlo means, the paper's as noisy as
    ours); else ``"not reproduced"``.  ``because`` gives the numbers.
    """
    if limit is not None and value < limit - (limit_half or 0.0):
        return "not reachable", f"below the MMSE limit {_num(limit)} [{_num(limit - (limit_half or 0.0))}, {_num(limit + (limit_half or 0.0))}]"
    ours = f"measured {_num(measured)} \u00b1 {_num(half)}"
    if not math.isfinite(half) or measured - math.sqrt(2.0) * half <= 0:
        return "not shown", ours + " (the interval is too wide to judge)"
    if abs(measured - value) <= math.sqrt(2.0) * half:
        return "reproduced", ours
    return "not reproduced", ours + (" (the paper's is lower)" if value < measured else " (the paper's is higher)")


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
    limit: dict[str, Any] | None = None
    claims: list[dict[str, Any]] = field(default_factory=list)

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

    def _limit_filter(self, scenario: Any, runs: int) -> Any:
        """The ``[limit]`` filter, named by its label (which says its N and runs)."""
        lim = self.limit
        table = dict(lim["filter"])
        backend = lim["backend"]
        if backend == "auto":  # the limit is the costly row: compiled whenever numba is there
            backend = "numba" if numba_available() else None
        if backend is not None:
            table["backend"] = backend
        name = lim["label"]
        if not name:
            filt = build_filter(table, scenario, "limit.filter")
            n = getattr(filt, "particles", None)
            size = "" if n is None else ", N = " + f"{n:,}".replace(",", " ")
            name = f"MMSE limit ({filt.name}{size}, {runs} runs)"
        return build_filter({**table, "name": name}, scenario, "limit.filter")

    def _figure_variants(self) -> list[str]:
        """Labels of the variants that get one-run figures (``""`` without variants)."""
        if not self.variants:
            return [""]
        return self.figure_opts["variants"] or [self.variants[0]["label"]]

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
        measured_in: dict[tuple[str, Any, str], MonteCarloResult] = {}  # (variant, value or None, filter) -> result
        limits: dict[str, tuple[str, MonteCarloResult]] = {}
        drawn = self._figure_variants()
        fig_results: dict[str, dict[Any, tuple[Any, MonteCarloResult]]] = {v: {} for v in drawn}
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
                if vlabel in fig_results:
                    fig_results[vlabel][value] = (scenario, result)
                for filt, swept in built:
                    e, head, half = run_metric(result, filt.name, sw["component"], sw["metric"])
                    at = value if swept else None
                    per_run[(vlabel, at, filt.name)] = e
                    measured_in[(vlabel, at, filt.name)] = result
                    if not swept:  # baselines are compared at every value
                        for v in sw["values"]:
                            per_run[(vlabel, v, filt.name)] = e
                    rows.append(self._row(result, filt.name, vlabel, at, head, half))
            if self.limit is not None:
                limit_runs = runs * self.limit["runs_factor"]
                filt = self._limit_filter(scenario, limit_runs)
                # the same root seed: its first runs see the very truths the filters above saw
                result = monte_carlo(
                    scenario, [filt], limit_runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
                    store="full", label=" ".join(filter(None, (self.name, vlabel, "MMSE limit"))),
                )
                results[f"{vlabel}|limit" if vlabel else "limit"] = result
                limits[vlabel] = (filt.name, result)
                _, head, half = run_metric(result, filt.name, sw["component"], sw["metric"])
                rows.append(self._row(result, filt.name, vlabel, None, head, half))
        tables = [self._summary_table(rows)]
        if self.paper or limits:
            tables.append(self._paper_table(rows, limits))
        if self.claims:
            tables.append(self._claims_table(rows, per_run, measured_in, limits, runs))
        if sw["pairs"]:
            tables.append(self._pairs_table(per_run))
        limit_names = {name for name, _ in limits.values()}
        figures = self._figures(rows, fig_results, seed, limit_names)
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

    def _paper_table(self, rows: list[dict[str, Any]], limits: dict[str, tuple[str, MonteCarloResult]]) -> Table:
        out = []
        for p in self.paper:
            r = self._lookup(rows, p["filter"], p["at"], p["variant"])
            measured = None if r is None else r.get(p["metric"])
            ratio = measured / p["value"] if isinstance(measured, float) and p["value"] else None
            line = [p["variant"]] if self.variants else []
            at = p["at"] if r is None or r[self.label] is None else r[self.label]  # as written in [sweep]
            out.append(line + [at, p["filter"], p["metric"], p["value"], measured, ratio, p["note"]])
        for variant, (name, _) in limits.items():
            r = self._lookup(rows, name, None, variant)
            line = [variant] if self.variants else []
            out.append(line + [None, name, "rmse", None, r["rmse"], None,
                               "the lowest mean error any filter can reach here (a PF with many particles approximates "
                               f"the MMSE estimator); rmse \u00b1 {r['ci95']:.2g} (95 %)"])
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

    def _claims_table(self, rows, per_run, measured_in, limits, runs: int) -> Table:
        """One verdict line per ``[[claim]]``, from the measured numbers (see :func:`order_verdict`, :func:`value_verdict`)."""
        sw = self.sweep
        out = []
        for c in self.claims:
            v = c["variant"]
            if c["order"]:
                values = [x for x in sw["values"] if c["at"] is None or float(x) == float(c["at"])]
                diffs = []
                for at in values:
                    for a, b in zip(c["order"], c["order"][1:]):
                        mean, half, _ = paired_difference(per_run[(v, at, a)], per_run[(v, at, b)])
                        diffs.append((f"{self.label} = {_fmt_value(at)}", a, b, mean, half))
                where = f"at every {self.label}" if len(values) > 1 else f"at {self.label} = {_fmt_value(values[0])}"
                text = f"{' < '.join(c['order'])} in {sw['component']} RMSE {where}"
                verdict, because = order_verdict(diffs)
            else:
                measured, half = self._claim_measure(rows, measured_in, c["filter"], c["at"], v, c["metric"])
                limit = limit_half = None
                if v in limits:
                    name, res = limits[v]
                    limit, lh = self._claim_measure(rows, {(v, None, name): res}, name, None, v, c["metric"])
                    # the paper's own mean has Monte Carlo noise too (as many runs as ours)
                    limit_half = lh * math.sqrt(1.0 + res.runs / runs)
                at = "" if c["at"] is None else f" at {self.label} = {_fmt_value(c['at'])}"
                metric = "" if c["metric"] == "rmse" else f" {c['metric']}"
                text = f"{c['filter']}'s{metric} {c['value']:g}{at}" + (f" ({c['source']})" if c["source"] else "")
                verdict, because = value_verdict(c["value"], measured, half, limit, limit_half)
            out.append(([v] if self.variants else []) + [text, verdict, because])
        cols = (["variant"] if self.variants else []) + ["claim", "verdict", "because"]
        return Table(
            "claims",
            "The paper's claims, judged from the measured numbers",
            cols,
            out,
            "An ordering A < B < ... is reproduced when every paired 95 % interval of A − B (per-run RMSEs, same runs) lies "
            "below 0, not reproduced when one lies above 0, else not shown. A value is reproduced when it lies within "
            "\u221a2 \u00d7 our 95 % half-width of our mean (both means carry Monte Carlo noise), not reachable when it lies "
            "below the MMSE limit's interval, not shown when our interval reaches 0.",
            kind="paper",
        )

    def _claim_measure(self, rows, measured_in, filt: str, at: Any, variant: str, metric: str) -> tuple[float, float]:
        """A claim's measured value and its 95 % half-width: the headline ``rmse``, or a pooled RMS column."""
        if metric == "rmse":
            r = self._lookup(rows, filt, at, variant)
            return r["rmse"], r["ci95"]
        result = next(res for (v, x, f), res in measured_in.items()
                      if v == variant and f == filt and (x is None or at is None or float(x) == float(at)))
        component = metric[len("rmse_"):] if metric.startswith("rmse_") else metric[len("rms_"):]
        _, value, half = run_metric(result, filt, component, "pooled")
        return value, half

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
    def _figures(self, rows, fig_results, seed: int, limit_names: set[str]) -> dict[str, Any]:
        figs: dict[str, Any] = {}
        opts = self.figure_opts
        sw = self.sweep
        label = self.label
        # the axis names the quantity, not only its symbol ("fraction l", not "l")
        xname = opts["axis_label"] or (sw["parameter"] if label == sw["parameter"] else f"{sw['parameter']} {label}")
        measured = [r for r in rows if r["filter"] not in limit_names]
        if len(sw["values"]) > 1:
            # the unit of the headline component, from the scenario (the variants share the state)
            some = next((res for by in fig_results.values() for res in by.values()), None)
            unit = some[1].component_unit(sw["component"]) if some else None
            # one RMSE figure per scenario variant: their scales can differ by orders of magnitude
            for variant in [v["label"] for v in self.variants] or [None]:
                sub = [r for r in measured if variant is None or r.get("variant") == variant]
                name = f"rmse_vs_{label}" if variant is None else f"rmse_vs_{label}_{_slug(variant)}"
                limits = [(r["filter"], float(r["rmse"])) for r in rows
                          if r["filter"] in limit_names and (variant is None or r.get("variant") == variant)]
                figs[name] = metric_against_value(
                    sub,
                    label,
                    "rmse",
                    error_key="ci95",
                    xlabel=xname,
                    ylabel=labelled(f"{sw['component']} RMSE", unit),
                    title=f"RMSE against {label}" + ("" if variant is None else f", {variant}"),
                    paper=self._paper_points(variant),
                    references=limits,
                )
            figs[f"time_vs_{label}"] = metric_against_value(
                measured, label, "wall_time_s", xlabel=xname, ylabel="filter wall time, all runs (s)", title=f"Run time against {label}"
            )
        several = len(fig_results) > 1
        for vlabel, by_value in fig_results.items():
            suffix = f"_{_slug(vlabel)}" if several else ""
            of = f", {vlabel}" if vlabel else ""
            for value in opts["values"]:
                if value not in by_value:
                    continue
                scenario, result = by_value[value]
                run = opts["run"]  # checked against the runs by check_runs
                tag = f"{label}{_fmt_value(value)}"
                anchors = getattr(getattr(scenario, "measurement", None), "anchors", None)
                figs[f"{tag}_estimates{suffix}"] = trajectory(
                    result, run, landmarks=anchors, title=f"Truth and estimates, run {run}, {label} = {value:g}{of}"
                )
                if result.truth.shape[-1] == 1:
                    figs[f"{tag}_abs_error{suffix}"] = abs_error_over_time(
                        result, run, 0, title=f"Absolute error of {result.state_labels[0]}, run {run}{of}"
                    )
                figs[f"{tag}_rmse{suffix}"] = rmse_over_time(
                    result, sw["component"], log=opts["log_rmse"],
                    title=f"{sw['component']} RMSE over {result.runs} runs, {label} = {value:g}{of}",
                )
                consistency = consistency_over_time(result, title=f"Consistency over {result.runs} runs, {label} = {value:g}{of}")
                if consistency is not None:
                    figs[f"{tag}_consistency{suffix}"] = consistency
                for comp in opts["components"]:
                    figs[f"{tag}_rmse_{comp}{suffix}"] = rmse_over_time(
                        result, comp, log=opts["log_rmse"], title=f"{comp} RMSE over {result.runs} runs, {label} = {value:g}{of}"
                    )
            if opts["snapshot_steps"]:
                value = opts["snapshot_value"] if opts["snapshot_value"] is not None else sw["values"][-1]
                match = [v for v in by_value if float(v) == float(value)]
                if match:
                    figs[f"{label}{_fmt_value(value)}_particles{suffix}"] = self._clouds(match[0], by_value[match[0]], seed, opts, of)
        return figs

    def _paper_points(self, variant: str | None) -> list[tuple[str, float, float, str]]:
        """The paper's headline values to mark in a variant's RMSE figure: ``(filter, at, value, legend)``."""
        out = []
        for p in self.paper:
            if p["metric"] != "rmse" or p["at"] is None:
                continue
            own = variant is None or not p["variant"] or p["variant"] == variant
            if not own and not self.figure_opts["paper_on_every_variant"]:
                continue
            legend = f"{p['filter']}, {self.figure_opts['paper_label']}" + ("" if own else f" for {p['variant']}")
            out.append((p["filter"], float(p["at"]), p["value"], legend))
        return out

    def _clouds(self, value, scen_result, seed: int, opts, of: str = "") -> Any:
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
            snaps, sim.truth[:, 0, :], 0, label=labelled(scenario.state_labels[0], result.unit(0)), title=f"Particles of run {run} after the step{of}"
        )


_KNOWN_SECTIONS = {"scenario", "filters", "sweep", "variants", "figures", "paper", "limit", "claim"}


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
    "[sweep], [[variants]], [figures], [[paper]], [limit], [[claim]]",
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
    names, swept_names = set(), set()
    for variant in variants or [None]:
        for f, takes in plan._filters_swept(plan._scenario(variant), sweep["values"][0], True):
            names.add(f.name)
            if takes:
                swept_names.add(f.name)
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
    for i, lbl in enumerate(figure_opts["variants"]):
        if lbl not in labels:
            raise ValueError(f"figures.variants[{i}]: no variant labelled {lbl!r} (have {', '.join(labels) or 'none'})")
    if "limit" in sections:
        plan.limit = _resolve_limit(sections, scenario)
        plan._limit_filter(scenario, 1)  # builds it (and its label), so a bad table fails here
    plan.claims = _resolve_claims(sections, plan, names, labels, columns, swept_names)
    return plan


def _resolve_limit(sections: dict[str, Any], scenario: Any) -> dict[str, Any]:
    limit = resolve_section(sections, "limit", LIMIT_PARAMS)
    table = limit["filter"]
    if not isinstance(table, dict) or "type" not in table:
        raise ValueError('limit.filter: expected a filter table, e.g. { type = "pf", particles = 20000 }')
    if "backend" in table:
        raise ValueError("limit.filter.backend: set limit.backend instead (auto: numba when installed)")
    return limit


def _resolve_claims(
    sections: dict[str, Any], plan: SweepPlan, names: set[str], labels: list[str], columns: list[str], swept_names: set[str]
) -> list[dict[str, Any]]:
    """Check the ``[[claim]]`` tables; a value claim without ``value`` takes the matching ``[[paper]]`` entry's."""
    values = plan.sweep["values"]
    out = []
    for where, c in resolve_section_list(sections, "claim", CLAIM_PARAMS):
        if labels and c["variant"] not in labels:
            raise ValueError(f"{where}.variant: expected one of the variants ({', '.join(labels)}), got {c['variant']!r}")
        if c["at"] is not None and not _is_swept(c["at"], values):
            raise ValueError(f"{where}.at: {c['at']:g} is not a swept value (sweep.values = {values})")
        if bool(c["order"]) == bool(c["filter"]):
            raise ValueError(f"{where}: give either order (an ordering) or filter (a value), not both or neither")
        for n in c["order"] or [c["filter"]]:
            if n not in names:
                raise ValueError(f"{where}: no filter named {n!r} (have {', '.join(sorted(names))})")
        if c["order"]:
            if len(c["order"]) < 2:
                raise ValueError(f"{where}.order: name at least two filters")
            out.append(c)
            continue
        if c["at"] is None and c["filter"] in swept_names and len(values) > 1:
            # which swept value the paper's number belongs to is not guessable
            raise ValueError(f"{where}.at: required, {c['filter']} is run at every swept value ({values})")
        metric = c["metric"]
        if metric not in columns or not (metric == "rmse" or metric.startswith(("rms_", "rmse_position", "rmse_velocity"))):
            have = ", ".join(m for m in columns if m == "rmse" or m.startswith(("rms_", "rmse_")))
            raise ValueError(f"{where}.metric: no error column {metric!r} with an interval (have {have})")
        if c["value"] is None or not c["source"]:
            match = [p for p in plan.paper if p["filter"] == c["filter"] and p["metric"] == metric and p["variant"] == c["variant"]
                     and (p["at"] is None) == (c["at"] is None) and (c["at"] is None or float(p["at"]) == float(c["at"]))]
            if c["value"] is None and not match:
                raise ValueError(f"{where}.value: required (no [[paper]] entry for {c['filter']} {metric} here)")
            if match:
                c["value"] = match[0]["value"] if c["value"] is None else c["value"]
                c["source"] = c["source"] or match[0]["note"]
        out.append(c)
    return out
