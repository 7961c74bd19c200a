"""The ``conditions`` experiment kind: the same filters on several variants of one scenario.

Sections:

``[scenario]``
    The base scenario table, as for ``montecarlo``.
``[[conditions]]``
    One table per condition: ``name`` (a label), optional ``title``, and any
    scenario parameters that override the base table for this condition.
``[[filters]]``
    The filters, built against each condition's scenario.
``[compare]``
    ``filter``: the filter whose relative improvement over every other filter
    is tabulated (default: the last); ``average``: how the cumulative RMSE
    of a run set is formed.
``[figures]``
    ``log_rmse`` (logarithmic RMSE axes), ``fading`` (draw λ against time).
``[[paper]]``
    Reference values: ``condition``, ``filter``, ``metric`` and ``value``
    (and ``baseline`` for ``metric = "improvement_pct"``).

Every condition uses the same root seed, so run i of every condition and
every filter draws from the same streams.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from ..config.build import build_filters, build_scenario, resolve_paper, resolve_section
from ..engine.montecarlo import monte_carlo
from ..registry import Param, register
from ..report.figures import consistency_over_time, fading_over_time, rmse_over_time
from ..results import MonteCarloResult
from ..tables import ExperimentOutput, Table

__all__ = ["ConditionsPlan", "cumulative_rmse", "improvement"]

AVERAGES = ("per-run", "pooled")

COMPARE_PARAMS = (
    Param("filter", "str", None, "filter whose improvement over the others is reported (default: the last)"),
    Param(
        "average",
        "str",
        "per-run",
        "cumulative RMSE: mean over runs of each run's time-averaged RMSE, or pooled over runs and steps",
        choices=AVERAGES,
    ),
)

FIGURE_PARAMS = (
    Param("log_rmse", "bool", True, "logarithmic RMSE axes"),
    Param("fading", "bool", True, "draw the fading factor against time"),
)

METRICS = ("improvement_pct", "cumulative_rmse")

PAPER_PARAMS = (
    Param("condition", "str", doc="condition name as in [[conditions]]"),
    Param("filter", "str", doc="filter name as in [[filters]]"),
    Param("metric", "str", doc="improvement_pct (needs baseline), cumulative_rmse, or a summary column"),
    Param("value", "float", doc="the paper's number"),
    Param("baseline", "str", "", "the filter improved upon (metric = improvement_pct)"),
    Param("note", "str", "", "where the number comes from, caveats"),
)


# --------------------------------------------------------------------------
# metrics
# --------------------------------------------------------------------------
def cumulative_rmse(result: MonteCarloResult, name: str, average: str = "per-run") -> float:
    """Position RMSE over the whole run: mean of per-run values, or pooled over runs and steps."""
    return result.rmse(name, "position", average=average)


def improvement(result: MonteCarloResult, name: str, baseline: str, average: str = "per-run") -> dict[str, float]:
    """Relative improvement of ``name`` over ``baseline``: 100 (E_b − E)/E_b, with a paired comparison.

    Returns the improvement in percent, its 95 % interval from the paired
    per-run differences (the baseline's mean is treated as fixed), the
    paired t-test's two-sided p-value, and the share of runs in which
    ``name`` has the lower time-averaged RMSE.
    """
    from .. import metrics

    e = metrics.rmse_per_run(result.squared_error(name, "position"))
    eb = metrics.rmse_per_run(result.squared_error(baseline, "position"))
    E, Eb = cumulative_rmse(result, name, average), cumulative_rmse(result, baseline, average)
    d = eb - e
    n = d.size
    half = 1.96 * np.std(d, ddof=1) / np.sqrt(n) if n > 1 else np.nan
    base = np.mean(eb)
    if n > 1 and np.any(d != d[0]):
        p = float(stats.ttest_rel(eb, e).pvalue)
    else:
        p = float("nan")
    pct = 100.0 * (Eb - E) / Eb if Eb > 0 else float("nan")
    return {
        "improvement_pct": pct,
        "ci95_low": 100.0 * (np.mean(d) - half) / base if base > 0 else float("nan"),
        "ci95_high": 100.0 * (np.mean(d) + half) / base if base > 0 else float("nan"),
        "p_value": p,
        "runs_better": float(np.mean(e < eb)),
    }


# --------------------------------------------------------------------------
# the plan
# --------------------------------------------------------------------------
@dataclass
class Condition:
    """One validated condition: its name, title, scenario and filters."""

    name: str
    title: str
    scenario: Any
    filters: list[Any]


@dataclass
class ConditionsPlan:
    """A validated ``conditions`` experiment."""

    name: str
    conditions: list[Condition]
    focus: str
    average: str
    figure_opts: dict[str, Any]
    paper: list[dict[str, Any]]
    sections: dict[str, Any] = field(repr=False)

    @property
    def filter_names(self) -> list[str]:
        """Filter names, in config order."""
        return [f.name for f in self.conditions[0].filters]

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Run every condition and assemble tables and figures."""
        results: dict[str, MonteCarloResult] = {}
        for cond in self.conditions:
            results[cond.name] = monte_carlo(
                cond.scenario, cond.filters, runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
                store="full",  # the paired per-run statistics need every run's errors
                label=f"{self.name} {cond.name}",
            )
        tables = [self._rmse_table(results), self._improvement_table(results)]
        if self.paper:
            tables.append(self._paper_table(results))
        tables.append(self._fading_table(results))
        tables.append(self._details_table(results))
        return ExperimentOutput(self.name, "", "", tables, self._figures(results), results=results)

    # -- tables ---------------------------------------------------------------
    def _rmse_table(self, results: dict[str, MonteCarloResult]) -> Table:
        cols = ["filter"] + [f"{c}_m" for c in results] + [f"{c}_diverged" for c in results]
        rows = [
            [name]
            + [cumulative_rmse(r, name, self.average) for r in results.values()]
            + [(r.divergence(name) or {}).get("diverged") for r in results.values()]
            for name in self.filter_names
        ]
        runs = next(iter(results.values())).runs
        return Table(
            "cumulative_rmse",
            f"Cumulative position RMSE (m, {self.average} average over {runs} runs) per filter and condition",
            cols,
            rows,
            notes="*_diverged: runs flagged diverged in that condition (docs/concepts.md, diverged runs); their errors are in the RMSE.",
        )

    def _improvement_table(self, results: dict[str, MonteCarloResult]) -> Table:
        rows = []
        for cond, r in results.items():
            for base in self.filter_names:
                if base == self.focus:
                    continue
                imp = improvement(r, self.focus, base, self.average)
                rows.append(
                    [cond, self.focus, base, imp["improvement_pct"], imp["ci95_low"], imp["ci95_high"], imp["p_value"], imp["runs_better"]]
                )
        return Table(
            "improvement",
            f"Relative improvement of {self.focus}: 100 (E_baseline - E_{self.focus}) / E_baseline, measured",
            ["condition", "filter", "baseline", "improvement_pct", "ci95_low", "ci95_high", "paired_p", "runs_better"],
            rows,
            notes=(
                "ci95: paired per-run differences, baseline mean held fixed; paired_p: two-sided paired t-test; "
                "runs_better: share of runs where the filter's time-averaged RMSE is lower."
            ),
        )

    def _paper_table(self, results: dict[str, MonteCarloResult]) -> Table:
        rows = []
        for p in self.paper:
            r = results[p["condition"]]
            if p["metric"] == "improvement_pct":
                measured = improvement(r, p["filter"], p["baseline"], self.average)["improvement_pct"]
            elif p["metric"] == "cumulative_rmse":
                measured = cumulative_rmse(r, p["filter"], self.average)
            else:
                measured = {row["filter"]: row for row in r.summary()}[p["filter"]].get(p["metric"])
            rows.append([p["condition"], p["filter"], p["baseline"], p["metric"], p["value"], measured, p["note"]])
        return Table(
            "paper_vs_measured",
            "Paper's values (source: paper) beside ours (source: measured)",
            ["condition", "filter", "baseline", "metric", "paper", "measured", "note"],
            rows,
            kind="paper",
        )

    def _fading_table(self, results: dict[str, MonteCarloResult]) -> Table:
        rows = []
        for cond, r in results.items():
            for name in self.filter_names:
                info = r.filters[name].info
                lam = info.get("fading")
                if lam is None:
                    continue
                flag = lambda key: 100.0 * float(np.mean(info[key])) if key in info else None  # noqa: E731
                gated = int(np.sum(info["gated"])) if "gated" in info else None
                rows.append([cond, name, float(np.mean(lam)), float(np.max(lam)), 100.0 * float(np.mean(lam > 1.0)), flag("diverging"), gated])
        return Table(
            "fading",
            "Fading factor over all runs and steps, measured",
            ["condition", "filter", "mean_lambda", "max_lambda", "faded_pct", "diverging_pct", "gated_steps"],
            rows,
        )

    def _details_table(self, results: dict[str, MonteCarloResult]) -> Table:
        keys = ("rmse_position", "rmse_velocity", "diverged", "diverged_from_step", "anees", "anis", "wall_time_s")
        rows = []
        for cond, r in results.items():
            for row in r.summary():
                rows.append([cond, row["filter"]] + [row.get(k) for k in keys])
        return Table("details", "Pooled RMSE, consistency (ANEES, ANIS) and filter time per condition, measured", ["condition", "filter", *keys], rows)

    # -- figures --------------------------------------------------------------
    def _figures(self, results: dict[str, MonteCarloResult]) -> dict[str, Any]:
        figs: dict[str, Any] = {}
        events = {c.title: tuple(getattr(c.scenario, "events", ())) for c in self.conditions}
        for c in self.conditions:
            r = results[c.name]
            figs[f"rmse_position_{c.name}"] = rmse_over_time(
                r,
                "position",
                log=self.figure_opts["log_rmse"],
                events=events[c.title],
                title=f"Position RMSE over {r.runs} runs\n{c.title}",
            )
            consistency = consistency_over_time(r, events=events[c.title], title=f"Consistency over {r.runs} runs\n{c.title}")
            if consistency is not None:
                figs[f"consistency_{c.name}"] = consistency
        if self.figure_opts["fading"]:
            # The median, not the mean: a few runs at λ_max dominate the mean of IFMKF's λ.
            figs["fading_factor"] = fading_over_time(
                {c.title: results[c.name] for c in self.conditions},
                statistic="median",
                share=True,
                events=events,
                title="Fading factor λ: median over runs (left), share of runs that faded (right)",
            )
        return figs


# --------------------------------------------------------------------------
# building from TOML
# --------------------------------------------------------------------------
_KNOWN_SECTIONS = {"scenario", "conditions", "filters", "compare", "figures", "paper"}


def _conditions(sections: dict[str, Any]) -> list[Condition]:
    entries = sections.get("conditions")
    if entries is None:
        raise ValueError("conditions: required section is missing (add [[conditions]] tables with a name)")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError("conditions: expected one or more [[conditions]] tables")
    base = sections.get("scenario")
    if not isinstance(base, dict):
        raise ValueError("scenario: required table is missing")
    out: list[Condition] = []
    seen: set[str] = set()
    for i, entry in enumerate(entries):
        where = f"conditions[{i}]"
        values = dict(entry)
        name = values.pop("name", None)
        if not isinstance(name, str) or not name:
            raise ValueError(f"{where}.name: required (a label such as 'ideal')")
        if name in seen:
            raise ValueError(f"{where}.name: repeated condition {name!r}")
        seen.add(name)
        title = values.pop("title", name)
        if not isinstance(title, str):
            raise ValueError(f"{where}.title: expected a string")
        if "type" in values:
            raise ValueError(f"{where}.type: a condition overrides parameters of [scenario]; it cannot change its type")
        merged = {**base, **values}
        try:
            scenario = build_scenario({"scenario": merged})
        except ValueError as e:
            msg = str(e)
            key = msg.split(":", 1)[0].split(".", 1)[-1].split(".")[0]
            if key in values:  # the override is at fault: name the condition's field
                msg = f"{where}." + msg.split(".", 1)[1]
            raise ValueError(msg) from None
        filters = build_filters(sections, scenario)
        out.append(Condition(name, title, scenario, filters))
    return out


def _paper(sections: dict[str, Any], conditions: list[str], filters: list[str]) -> list[dict[str, Any]]:
    out = resolve_paper(sections, filters, PAPER_PARAMS)
    for i, vals in enumerate(out):
        where = f"paper[{i}]"
        if vals["condition"] not in conditions:
            raise ValueError(f"{where}.condition: no condition named {vals['condition']!r} (have {', '.join(conditions)})")
        if vals["metric"] == "improvement_pct":
            if vals["baseline"] not in filters:
                raise ValueError(f"{where}.baseline: metric improvement_pct needs a baseline filter (have {', '.join(filters)})")
        elif vals["metric"] != "cumulative_rmse" and vals["baseline"]:
            raise ValueError(f"{where}.baseline: only used with metric = 'improvement_pct'")
    return out


@register(
    "experiment",
    "conditions",
    "Compare filters on several variants (conditions) of one scenario; sections [scenario], [[conditions]], "
    "[[filters]], [compare], [figures], [[paper]]",
)
def _conditions_kind(sections: dict[str, Any], path: Path, name: str) -> ConditionsPlan:
    for key in sections:
        if key not in _KNOWN_SECTIONS:
            raise ValueError(f"{key}: unknown section (known: experiment, {', '.join(sorted(_KNOWN_SECTIONS))})")
    conditions = _conditions(sections)
    names = [f.name for f in conditions[0].filters]
    compare = resolve_section(sections, "compare", COMPARE_PARAMS)
    focus = compare["filter"] or names[-1]
    if focus not in names:
        raise ValueError(f"compare.filter: no filter named {focus!r} (have {', '.join(names)})")
    if len(names) < 2:
        raise ValueError("filters: a comparison needs at least two filters")
    figure_opts = resolve_section(sections, "figures", FIGURE_PARAMS)
    paper = _paper(sections, [c.name for c in conditions], names)
    return ConditionsPlan(name, conditions, focus, compare["average"], figure_opts, paper, sections)
