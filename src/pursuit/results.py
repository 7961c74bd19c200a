"""Result objects of Monte Carlo comparisons, with their metrics and file output."""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import metrics
from ._json import json_default
from ._repr import array_text, html_table, keys_text
from .reduction import (
    FilterStatistics,
    component_groups,
    filter_statistics,
    group_key,
    merge_statistics,
    run_sum,
)
from .tables import write_csv

__all__ = ["FilterResult", "MonteCarloResult", "STORE_MODES"]

STORE_MODES = ("full", "summary")
"""``full``: every run's arrays are kept; ``summary``: each chunk is reduced to
:class:`pursuit.reduction.FilterStatistics` and dropped, keeping a few example runs."""

Component = str | Sequence[int]


@dataclass
class FilterResult:
    """One filter's output over all runs.

    Attributes
    ----------
    name
        The filter's label.
    estimates
        ``(K, M, n)`` filtered means (``None`` for a summary-mode result).
    covariances
        ``(K, M, n, n)`` filtered covariances, or ``None`` if not kept.
    info
        Step info ``{key: (K, M, ...)}`` (NIS, log-likelihood, fading
        factor, ESS, ...); empty for a summary-mode result.
    wall_time
        Seconds spent filtering, summed over chunks.
    """

    name: str
    estimates: np.ndarray | None
    covariances: np.ndarray | None
    info: dict[str, np.ndarray] = field(default_factory=dict)
    wall_time: float = 0.0

    def __repr__(self) -> str:
        # shapes, not values: the arrays hold every run and step
        return (
            f"FilterResult({self.name!r}, estimates={array_text(self.estimates)}, "
            f"covariances={array_text(self.covariances)}, info={keys_text(self.info)}, wall_time={self.wall_time:.3g})"
        )


@dataclass
class MonteCarloResult:
    """Truth, measurements and every filter's estimates from one comparison.

    Run i of every filter saw the same truth and measurements (common random
    numbers), drawn from the seed of run i under the root ``seed``.

    Two storage modes (``store``):

    * ``"full"``: ``truth``, ``measurements`` and each filter's estimates,
      covariances and info hold every run;
    * ``"summary"``: each chunk of runs was reduced to the statistics the
      summaries need (``statistics``) and then dropped, so memory does not
      grow with the number of runs.  ``truth``, ``measurements`` and the
      filters' arrays are ``None``; the first few runs are kept whole in
      ``examples`` (a full-mode result) for trajectory figures and the
      tidy error table.

    The summaries (RMSE per step, pooled and per run, ANEES, ANIS, their χ²
    bounds, step-info means) are computed from the same reduced statistics in
    both modes, with sums over runs in a fixed order (:mod:`pursuit.reduction`),
    so they are bit-identical whatever the mode, chunk size or workers.
    """

    scenario: str
    seed: int
    times: np.ndarray
    truth: np.ndarray | None
    measurements: np.ndarray | None
    state_labels: tuple[str, ...]
    position_indices: tuple[int, ...]
    velocity_indices: tuple[int, ...]
    filters: dict[str, FilterResult]
    config: dict[str, Any] | None = None
    statistics: dict[str, FilterStatistics] | None = None
    total_runs: int | None = None
    examples: "MonteCarloResult | None" = None
    state_units: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if self.truth is None and (self.statistics is None or self.total_runs is None):
            raise ValueError("a summary-mode result needs statistics and total_runs")

    # -- display ------------------------------------------------------------
    _REPR_FILTERS = 8  # filters listed by repr; the rest are counted

    def __repr__(self) -> str:
        # A few lines whatever the size: the arrays, statistics and config are described, not printed.
        lines = [
            f"MonteCarloResult(scenario={self.scenario!r}, seed={self.seed}, runs={self.runs}, steps={self.steps}, "
            f"store={self.store!r}" + (f", example_runs={self.examples.runs}," if self.examples is not None else ","),
            f"  state=[{', '.join(self.state_labels)}],",
            "  filters={",
        ]
        names = self.filter_names
        for name in names[: self._REPR_FILTERS]:
            lines.append(f"    {name!r}: {self.filters[name]!r},")
        if len(names) > self._REPR_FILTERS:
            lines.append(f"    ... +{len(names) - self._REPR_FILTERS} more")
        lines.append("  })")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        """The summary table, for notebooks (computes the summary, like :meth:`summary`)."""
        import html

        rows = self.summary()
        wanted = ("filter", "rmse_position", "rmse_velocity", "diverged", "anees", "anis", "wall_time_s")
        columns = [c for c in wanted if any(c in r for r in rows)]
        caption = (
            f"<p><b>MonteCarloResult</b> {html.escape(self.scenario)}: {len(rows)} filters, {self.runs} runs, "
            f"{self.steps} steps, seed {self.seed}, store {html.escape(self.store)}</p>"
        )
        return caption + html_table(columns, rows)

    def to_dataframe(self) -> "pandas.DataFrame":  # noqa: F821 - pandas is optional
        """:meth:`summary` as a pandas DataFrame, one row per filter, indexed by filter.

        Returns
        -------
        pandas.DataFrame
            The columns of :meth:`summary` (RMSEs, per-component RMS,
            consistency, wall time, runs).

        Raises
        ------
        ImportError
            If pandas is not installed (``pip install 'pursuit[pandas]'``).
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("MonteCarloResult.to_dataframe needs pandas: pip install 'pursuit[pandas]'") from None
        return pd.DataFrame(self.summary()).set_index("filter")

    # -- shape --------------------------------------------------------------
    @property
    def store(self) -> str:
        """``"full"`` or ``"summary"`` (see the class docstring)."""
        return "full" if self.truth is not None else "summary"

    @property
    def runs(self) -> int:
        """Number of Monte Carlo runs M."""
        if self.total_runs is not None:
            return int(self.total_runs)
        return self.truth.shape[1]

    @property
    def steps(self) -> int:
        """Number of time steps K."""
        return len(self.times)

    @property
    def state_dim(self) -> int:
        """State dimension n."""
        return len(self.state_labels)

    @property
    def filter_names(self) -> list[str]:
        """Filter labels in the order they were run."""
        return list(self.filters)

    def stored(self) -> "MonteCarloResult":
        """The full-mode result of the runs whose arrays are kept.

        Itself in full mode; the example runs ``0 .. R-1`` in summary mode.
        """
        if self.truth is not None:
            return self
        if self.examples is None:
            raise ValueError("this summary-mode result kept no example runs")
        return self.examples

    def unit(self, index: int) -> str | None:
        """Unit of state component ``index`` as the scenario declared it (``state_units``).

        ``""`` for a dimensionless component; ``None`` when the scenario
        declared no units (figures then show none rather than guess one).
        """
        if self.state_units is None:
            return None
        return self.state_units[index]

    def component_unit(self, component: Component) -> str | None:
        """The common unit of a component's indices (``"position"`` -> ``"m"``); None if unknown or mixed."""
        units = {self.unit(i) for i in self.indices(component)}
        return units.pop() if len(units) == 1 else None

    def _filter(self, name: str) -> FilterResult:
        try:
            return self.filters[name]
        except KeyError:
            raise KeyError(f"no filter named {name!r}; have {', '.join(self.filters)}") from None

    def _full(self, what: str) -> None:
        if self.truth is None:
            raise ValueError(
                f"{what} needs every run's arrays, but this result was stored as a summary "
                f"(store='summary'); use the per-step summaries (rmse_per_step, anees, anis) "
                f"or run with store='full'"
            )

    def indices(self, component: Component) -> tuple[int, ...]:
        """State indices of ``"position"``, ``"velocity"``, ``"state"``, a label, or explicit indices."""
        if isinstance(component, str):
            if component == "position":
                return tuple(self.position_indices)
            if component == "velocity":
                return tuple(self.velocity_indices)
            if component == "state":
                return tuple(range(self.state_dim))
            if component in self.state_labels:
                return (self.state_labels.index(component),)
            raise KeyError(f"unknown component {component!r}; use position, velocity, state or one of {self.state_labels}")
        return tuple(int(i) for i in component)

    # -- reduced statistics -------------------------------------------------
    def groups(self) -> list[tuple[int, ...]]:
        """The index groups whose errors are reduced (see :func:`pursuit.reduction.component_groups`)."""
        return component_groups(self.state_dim, self.position_indices, self.velocity_indices)

    def filter_statistics(self, name: str) -> FilterStatistics:
        """One filter's reduced statistics (computed from the arrays once, in full mode)."""
        self._filter(name)
        if self.statistics is None:
            self.statistics = {}
        stats = self.statistics.get(name)
        if stats is None:
            fr = self.filters[name]
            part = filter_statistics(self.truth, fr.estimates, fr.covariances, fr.info, 0, self.groups())
            stats = self.statistics[name] = merge_statistics([part], self.runs, self.steps)
        return stats

    def _sse(self, name: str, component: Component) -> tuple[np.ndarray, np.ndarray]:
        """Per-step summed squared error over runs ``(K,)`` and per-run mean squared error ``(M,)``."""
        idx = self.indices(component)
        key = group_key(idx)
        stats = self.filter_statistics(name)
        if f"sse:{key}" in stats.sums:
            return stats.sums[f"sse:{key}"], stats.per_run[f"mse:{key}"]
        self._full(f"the error of components {idx}")
        fr = self.filters[name]
        part = filter_statistics(self.truth, fr.estimates, None, {}, 0, [idx])
        full = merge_statistics([part], self.runs, self.steps)
        return full.sums[f"sse:{key}"], full.per_run[f"mse:{key}"]

    # -- errors -------------------------------------------------------------
    def squared_error(self, name: str, component: Component = "position") -> np.ndarray:
        """``(K, M)`` squared error summed over the component's indices (full mode only)."""
        self._full("squared_error")
        idx = self.indices(component)
        return metrics.squared_error(self._filter(name).estimates, self.truth, idx)

    def rmse_per_step(self, name: str, component: Component = "position") -> np.ndarray:
        """``(K,)`` RMSE over runs at each step."""
        sse, _ = self._sse(name, component)
        return np.sqrt(sse / self.runs)

    def rmse_per_run(self, name: str, component: Component = "position") -> np.ndarray:
        """``(M,)`` each run's RMSE over time."""
        _, mse = self._sse(name, component)
        return np.sqrt(mse)

    def rmse(self, name: str, component: Component = "position", average: str = "pooled") -> float:
        """Overall RMSE: ``"pooled"`` over runs and steps, or ``"per-run"`` (mean of per-run RMSEs)."""
        if average == "pooled":
            sse, _ = self._sse(name, component)
            return float(np.sqrt(run_sum(sse) / (self.runs * self.steps)))
        if average == "per-run":
            return float(run_sum(self.rmse_per_run(name, component)) / self.runs)
        raise ValueError(f"average: must be 'pooled' or 'per-run', got {average!r}")

    # -- divergence -------------------------------------------------------------
    def diverged_step(self, name: str) -> np.ndarray | None:
        """``(M,)`` the 1-based step at which each run was flagged diverged (NaN: never); None if not tested.

        See :mod:`pursuit.divergence` for the tests.  Available in both
        storage modes.
        """
        return self.filter_statistics(name).per_run.get("diverged_step")

    def divergence(self, name: str) -> dict[str, Any] | None:
        """The diverged runs of a filter: ``{"diverged": count, "diverged_from_step": first step}``.

        ``diverged_from_step`` is the earliest step at which any run was
        flagged (None when no run diverged).  None when the runs were not
        tested (``divergence=None``).
        """
        steps = self.diverged_step(name)
        if steps is None:
            return None
        hit = np.isfinite(steps)
        return {
            "diverged": int(np.count_nonzero(hit)),
            "diverged_from_step": int(np.min(steps[hit])) if hit.any() else None,
        }

    # -- consistency ----------------------------------------------------------
    def nees(self, name: str) -> np.ndarray:
        """``(K, M)`` NEES of the full state (needs covariances; full mode only)."""
        self._full("nees")
        fr = self._filter(name)
        if fr.covariances is None:
            raise ValueError(f"{name}: covariances were not kept; NEES needs them")
        return metrics.nees(fr.estimates, fr.covariances, self.truth)

    def _average(self, name: str, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-step average of NEES or NIS over the runs where it is finite, mean dof, count."""
        stats = self.filter_statistics(name)
        if what not in stats.sums:
            if what == "nees":
                raise ValueError(f"{name}: covariances were not kept; NEES needs them")
            raise ValueError(f"{name}: the filter reported no NIS")
        count = stats.sums[f"{what}_count"]
        safe = np.maximum(count, 1.0)
        avg = np.where(count > 0, stats.sums[what] / safe, np.nan)
        return avg, stats.sums[f"{what}_dof"] / safe, count

    def anees(self, name: str) -> np.ndarray:
        """``(K,)`` average NEES over runs."""
        return self._average(name, "nees")[0]

    def anis(self, name: str) -> np.ndarray:
        """``(K,)`` average NIS over runs (steps with no measurement left out)."""
        return self._average(name, "nis")[0]

    def info_keys(self, name: str) -> list[str]:
        """Scalar step-info keys whose per-step means are available (e.g. ``fading``, ``ess``)."""
        stats = self.filter_statistics(name)
        return [k[5:] for k in stats.sums if k.startswith("info:") and f"{k}_count" in stats.sums]

    def info_mean(self, name: str, key: str) -> np.ndarray:
        """``(K,)`` mean over runs of a scalar step-info value (where finite)."""
        stats = self.filter_statistics(name)
        total = stats.require(f"info:{key}")
        count = stats.sums[f"info:{key}_count"]
        return np.where(count > 0, total / np.maximum(count, 1.0), np.nan)

    def consistency_bounds(self, name: str, what: str = "nees", level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """``(K,)`` two-sided χ² bounds of the per-step ANEES (``what="nees"``) or ANIS (``"nis"``).

        At step k the average of the ``c_k`` values over runs (independent
        across runs) of total χ² degrees of freedom ``D_k`` lies, on a matched
        model, inside ``chi2.ppf([α/2, 1 − α/2], D_k) / c_k`` with probability
        ``level`` (Bar-Shalom's per-step test; ``c_k = M`` and ``D_k = M·n``
        when every run has a value).  NaN at steps with no value.

        Parameters
        ----------
        name
            The filter's label.
        what
            ``"nees"`` or ``"nis"``.
        level
            Coverage of the two-sided bounds, in (0, 1).

        Returns
        -------
        (low, high)
            The bounds at each step.
        """
        if what not in ("nees", "nis"):
            raise ValueError(f"what: must be 'nees' or 'nis', got {what!r}")
        if not 0.0 < level < 1.0:
            raise ValueError(f"level: must be in (0, 1), got {level!r}")
        _, dof, count = self._average(name, what)
        ok = count > 0
        lo = np.full(count.shape, np.nan)
        hi = np.full(count.shape, np.nan)
        lo[ok], hi[ok] = metrics.chi2_bounds(dof[ok], count[ok], level)
        return lo, hi

    def consistency(self, name: str, level: float = 0.95) -> dict[str, float]:
        """ANEES and ANIS over all runs and steps, the per-step χ² bounds, and the share of steps inside them.

        Keys (``anis_*`` likewise, when the filter reports NIS):

        * ``anees``: the average NEES over all runs and steps;
        * ``anees_low``, ``anees_high``: the per-step bounds of
          :meth:`consistency_bounds` (``chi2.ppf([α/2, 1 − α/2], M·n) / M``
          for M runs and n states), which one step's ANEES over the runs
          lies inside with probability ``level`` on a matched model.  Where
          steps differ in how many runs had a value (NIS at steps with missing
          measurements), the widest of them;
        * ``anees_inside``: the share of steps whose ANEES lies inside its
          own step's bounds (near ``level`` on a matched model).

        The bounds are *per step*.  No bound for the overall ``anees`` is
        given: NEES is correlated over time, so treating the K·M values as
        independent gives bounds that are far too narrow (a matched KF fell
        outside such "95 %" bounds in about 30 % of seeds).  The overall value
        is the mean of the per-step values, which spreads no more than one
        step's value, so an overall ``anees`` outside the per-step bounds is a
        clear sign of inconsistency.

        Parameters
        ----------
        name
            The filter's label.
        level
            Coverage of the two-sided bounds, in (0, 1).

        Returns
        -------
        dict
            The keys above, as floats (NaN where nothing was averaged).
        """
        out: dict[str, float] = {}
        stats = self.filter_statistics(name)
        for what, prefix in (("nees", "anees"), ("nis", "anis")):
            if what in stats.sums:
                out.update(self._consistency_of(prefix, name, stats, what, level))
        return out

    def _consistency_of(self, prefix: str, name: str, stats: FilterStatistics, what: str, level: float) -> dict[str, float]:
        total, count = stats.sums[what], stats.sums[f"{what}_count"]
        ok = count > 0
        avg = total[ok] / count[ok]
        lo, hi = self.consistency_bounds(name, what, level)
        lo, hi = lo[ok], hi[ok]
        n_all = float(run_sum(count))
        if ok.any():
            inside = float(np.mean((avg >= lo) & (avg <= hi)))
            overall = float(run_sum(total) / n_all)
            lo_w, hi_w = float(np.min(lo)), float(np.max(hi))
        else:
            inside, overall, lo_w, hi_w = (float("nan"),) * 4
        return {
            prefix: overall,
            f"{prefix}_low": lo_w,
            f"{prefix}_high": hi_w,
            f"{prefix}_inside": inside,
        }

    # -- tables and files -----------------------------------------------------
    def summarised(self, keep_runs: int = 10) -> "MonteCarloResult":
        """This result in summary mode: the reduced statistics and runs ``0 .. keep_runs-1`` kept whole.

        What ``store="summary"`` would have given for the same runs: the
        summaries (RMSE per step, pooled and per run, ANEES, ANIS, their
        bounds, step-info means) are the same bits, the other runs' arrays
        are dropped.  A summary-mode result, or one with no more than
        ``keep_runs`` runs, is returned as it is.  Used to write light output
        folders (:func:`pursuit.report.output.write_output`).
        """
        if isinstance(keep_runs, bool) or not isinstance(keep_runs, (int, np.integer)) or keep_runs < 0:
            raise ValueError(f"keep_runs: must be a non-negative integer, got {keep_runs!r}")
        if self.truth is None or self.runs <= keep_runs:
            return self
        stats = {name: self.filter_statistics(name) for name in self.filter_names}
        examples = None
        if keep_runs:
            r = int(keep_runs)
            examples = replace(
                self,
                truth=self.truth[:, :r].copy(),
                measurements=self.measurements[:, :r].copy(),
                filters={
                    name: FilterResult(
                        name,
                        fr.estimates[:, :r].copy(),
                        None if fr.covariances is None else fr.covariances[:, :r].copy(),
                        {k: np.asarray(v)[:, :r].copy() for k, v in fr.info.items()},
                        fr.wall_time,
                    )
                    for name, fr in self.filters.items()
                },
                config=None,
                statistics=None,
            )
        return replace(
            self,
            truth=None,
            measurements=None,
            filters={name: FilterResult(name, None, None, {}, fr.wall_time) for name, fr in self.filters.items()},
            statistics=stats,
            total_runs=self.runs,
            examples=examples,
        )

    def summary(self) -> list[dict[str, Any]]:
        """One row per filter: RMSEs, diverged runs, per-component RMS, consistency, wall time.

        The RMSEs include every run, diverged or not; ``diverged`` (how many
        runs were flagged, :mod:`pursuit.divergence`) and
        ``diverged_from_step`` (the earliest step flagged) stand beside them.
        """
        rows = []
        for name, fr in self.filters.items():
            row: dict[str, Any] = {"filter": name}
            if self.position_indices:
                row["rmse_position"] = self.rmse(name, "position")
            if self.velocity_indices:
                row["rmse_velocity"] = self.rmse(name, "velocity")
            div = self.divergence(name)
            if div is not None:  # beside the RMSE, which includes the diverged runs
                row.update(div)
            for i, label in enumerate(self.state_labels):
                row[f"rms_{label}"] = self.rmse(name, (i,))
            try:
                row.update(self.consistency(name))
            except ValueError:
                pass
            row["wall_time_s"] = fr.wall_time
            row["runs"] = self.runs
            rows.append(row)
        return rows

    def to_csv(self, path: str | Path) -> Path:
        """Write :meth:`summary` as CSV; returns the path."""
        rows = self.summary()
        fields: list[str] = []
        for r in rows:
            for key in r:
                if key not in fields:
                    fields.append(key)
        write_csv(path, fields, ([r.get(k) for k in fields] for r in rows))
        return Path(path)

    def to_json(self, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
        """Write the summary, seed, config and ``extra`` as JSON; returns the path."""
        doc = {
            "scenario": self.scenario,
            "seed": self.seed,
            "runs": self.runs,
            "steps": self.steps,
            "filters": self.filter_names,
            "summary": self.summary(),
            "config": self.config,
        }
        if extra:
            doc.update(extra)
        path = Path(path)
        path.write_text(json.dumps(doc, indent=2, default=json_default) + "\n")
        return path

