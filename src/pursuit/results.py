"""Result objects of Monte Carlo comparisons, with their metrics and file output."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import metrics

__all__ = ["FilterResult", "MonteCarloResult"]

Component = str | Sequence[int]


@dataclass
class FilterResult:
    """One filter's output over all runs.

    Attributes
    ----------
    name
        The filter's label.
    estimates
        ``(K, M, n)`` filtered means.
    covariances
        ``(K, M, n, n)`` filtered covariances, or ``None`` if not kept.
    info
        Step info ``{key: (K, M, ...)}`` (NIS, log-likelihood, fading
        factor, ESS, ...).
    wall_time
        Seconds spent filtering, summed over chunks.
    """

    name: str
    estimates: np.ndarray
    covariances: np.ndarray | None
    info: dict[str, np.ndarray] = field(default_factory=dict)
    wall_time: float = 0.0


@dataclass
class MonteCarloResult:
    """Truth, measurements and every filter's estimates from one comparison.

    Run i of every filter saw the same truth and measurements (common random
    numbers), drawn from the seed of run i under the root ``seed``.
    """

    scenario: str
    seed: int
    times: np.ndarray
    truth: np.ndarray
    measurements: np.ndarray
    state_labels: tuple[str, ...]
    position_indices: tuple[int, ...]
    velocity_indices: tuple[int, ...]
    filters: dict[str, FilterResult]
    config: dict[str, Any] | None = None

    # -- shape --------------------------------------------------------------
    @property
    def runs(self) -> int:
        """Number of Monte Carlo runs M."""
        return self.truth.shape[1]

    @property
    def steps(self) -> int:
        """Number of time steps K."""
        return self.truth.shape[0]

    @property
    def filter_names(self) -> list[str]:
        """Filter labels in the order they were run."""
        return list(self.filters)

    def _filter(self, name: str) -> FilterResult:
        try:
            return self.filters[name]
        except KeyError:
            raise KeyError(f"no filter named {name!r}; have {', '.join(self.filters)}") from None

    def indices(self, component: Component) -> tuple[int, ...]:
        """State indices of ``"position"``, ``"velocity"``, ``"state"``, a label, or explicit indices."""
        if isinstance(component, str):
            if component == "position":
                return tuple(self.position_indices)
            if component == "velocity":
                return tuple(self.velocity_indices)
            if component == "state":
                return tuple(range(self.truth.shape[-1]))
            if component in self.state_labels:
                return (self.state_labels.index(component),)
            raise KeyError(f"unknown component {component!r}; use position, velocity, state or one of {self.state_labels}")
        return tuple(int(i) for i in component)

    # -- errors -------------------------------------------------------------
    def squared_error(self, name: str, component: Component = "position") -> np.ndarray:
        """``(K, M)`` squared error summed over the component's indices."""
        idx = self.indices(component)
        return metrics.squared_error(self._filter(name).estimates, self.truth, idx)

    def rmse_per_step(self, name: str, component: Component = "position") -> np.ndarray:
        """``(K,)`` RMSE over runs at each step."""
        return metrics.rmse_per_step(self.squared_error(name, component))

    def rmse(self, name: str, component: Component = "position", average: str = "pooled") -> float:
        """Overall RMSE: ``"pooled"`` over runs and steps, or ``"per-run"`` (mean of per-run RMSEs)."""
        sq = self.squared_error(name, component)
        if average == "pooled":
            return metrics.rmse_pooled(sq)
        if average == "per-run":
            return float(np.mean(metrics.rmse_per_run(sq)))
        raise ValueError(f"average: must be 'pooled' or 'per-run', got {average!r}")

    # -- consistency ----------------------------------------------------------
    def nees(self, name: str) -> np.ndarray:
        """``(K, M)`` NEES of the full state (needs covariances)."""
        fr = self._filter(name)
        if fr.covariances is None:
            raise ValueError(f"{name}: covariances were not kept; NEES needs them")
        return metrics.nees(fr.estimates, fr.covariances, self.truth)

    def anees(self, name: str) -> np.ndarray:
        """``(K,)`` average NEES over runs."""
        return metrics.average_consistency(self.nees(name), self.truth.shape[-1])[0]

    def anis(self, name: str) -> np.ndarray:
        """``(K,)`` average NIS over runs (steps with no measurement left out)."""
        info = self._filter(name).info
        if "nis" not in info:
            raise ValueError(f"{name}: the filter reported no NIS")
        return metrics.average_consistency(info["nis"], info.get("dof", 1))[0]

    def consistency(self, name: str, level: float = 0.95) -> dict[str, float]:
        """ANEES and ANIS over all runs and steps, with the share of steps inside the χ² bounds.

        The overall bounds treat the K·M values as independent, which they
        are across runs but not across time; the per-step share
        (``*_inside``) is exact and should be near ``level`` on a matched
        model.
        """
        out: dict[str, float] = {}
        fr = self._filter(name)
        if fr.covariances is not None:
            out.update(self._consistency_of("anees", self.nees(name), self.truth.shape[-1], level))
        if "nis" in fr.info:
            out.update(self._consistency_of("anis", fr.info["nis"], fr.info.get("dof", 1), level))
        return out

    @staticmethod
    def _consistency_of(prefix: str, values: np.ndarray, dof, level: float) -> dict[str, float]:
        avg, dof_k, count = metrics.average_consistency(values, dof)
        ok = count > 0
        lo, hi = metrics.chi2_bounds(dof_k[ok], count[ok], level)
        inside = float(np.mean((avg[ok] >= lo) & (avg[ok] <= hi))) if ok.any() else float("nan")
        v = np.asarray(values, dtype=float)
        finite = np.isfinite(v)
        n_all = int(finite.sum())
        d_all = float(np.mean(np.broadcast_to(np.asarray(dof, dtype=float), v.shape)[finite])) if n_all else np.nan
        overall = float(np.mean(v[finite])) if n_all else float("nan")
        lo_all, hi_all = metrics.chi2_bounds(d_all, n_all, level) if n_all else (np.nan, np.nan)
        return {
            prefix: overall,
            f"{prefix}_low": float(lo_all),
            f"{prefix}_high": float(hi_all),
            f"{prefix}_inside": inside,
        }

    # -- tables and files -----------------------------------------------------
    def summary(self) -> list[dict[str, Any]]:
        """One row per filter: RMSEs, per-component RMS, consistency, wall time."""
        rows = []
        for name, fr in self.filters.items():
            row: dict[str, Any] = {"filter": name}
            if self.position_indices:
                row["rmse_position"] = self.rmse(name, "position")
            if self.velocity_indices:
                row["rmse_velocity"] = self.rmse(name, "velocity")
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
        path = Path(path)
        fields: list[str] = []
        for r in rows:
            for key in r:
                if key not in fields:
                    fields.append(key)
        with path.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields)
            w.writeheader()
            for r in rows:
                w.writerow({k: _fmt(v) for k, v in r.items()})
        return path

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
        path.write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
        return path


def _fmt(v: Any) -> Any:
    if isinstance(v, float):
        return repr(v)
    return v


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
