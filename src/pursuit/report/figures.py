"""Figures of a Monte Carlo comparison (matplotlib, no global pyplot state)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..results import MonteCarloResult

__all__ = ["rmse_over_time", "trajectory", "UNITS"]

UNITS = {"position": "m", "velocity": "m/s", "acceleration": "m/s²"}


def _new(width: float = 6.4, height: float = 4.0) -> tuple[Figure, object]:
    fig = Figure(figsize=(width, height), layout="constrained")
    ax = fig.add_subplot()
    return fig, ax


def rmse_over_time(
    result: MonteCarloResult,
    component: str | Sequence[int] = "position",
    *,
    log: bool = False,
    unit: str | None = None,
    filters: Sequence[str] | None = None,
    title: str | None = None,
) -> Figure:
    """RMSE against time for each filter.

    Parameters
    ----------
    result
        A Monte Carlo result.
    component
        ``"position"``, ``"velocity"``, a state label or explicit indices.
    log
        Logarithmic y axis.
    unit
        Unit for the y label (default from the component name).
    filters
        Subset and order of filters (default all).
    title
        Figure title (default derived from the component).
    """
    fig, ax = _new()
    names = list(filters) if filters is not None else result.filter_names
    label = component if isinstance(component, str) else "state " + ",".join(map(str, component))
    for name in names:
        ax.plot(result.times, result.rmse_per_step(name, component), label=name, linewidth=1.4)
    if log:
        ax.set_yscale("log")
    u = unit if unit is not None else UNITS.get(label, "")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{label} RMSE ({u})" if u else f"{label} RMSE")
    ax.set_title(title or f"{label.capitalize()} RMSE over {result.runs} runs")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig


def trajectory(
    result: MonteCarloResult,
    run: int = 0,
    *,
    filters: Sequence[str] | None = None,
    landmarks: np.ndarray | None = None,
    title: str | None = None,
) -> Figure:
    """One run's truth with each filter's estimate.

    With two or more position components the plot is the path in the plane
    (first two position axes); with one it is position against time; with
    none, the first state component against time.
    """
    if not 0 <= run < result.runs:
        raise ValueError(f"run: must lie in [0, {result.runs - 1}], got {run}")
    fig, ax = _new(6.4, 4.8)
    names = list(filters) if filters is not None else result.filter_names
    pos = list(result.position_indices) or [0]
    truth = result.truth[:, run, :]
    if len(pos) >= 2:
        i, j = pos[0], pos[1]
        ax.plot(truth[:, i], truth[:, j], color="black", linewidth=2.0, label="truth")
        for name in names:
            est = result.filters[name].estimates[:, run, :]
            ax.plot(est[:, i], est[:, j], linewidth=1.2, label=name)
        if landmarks is not None and len(landmarks):
            lm = np.asarray(landmarks)
            ax.scatter(lm[:, 0], lm[:, 1], marker="^", color="tab:red", zorder=5, label="sensors")
        ax.set_xlabel(f"{result.state_labels[i]} (m)")
        ax.set_ylabel(f"{result.state_labels[j]} (m)")
        ax.set_aspect("equal", adjustable="datalim")
    else:
        i = pos[0]
        ax.plot(result.times, truth[:, i], color="black", linewidth=2.0, label="truth")
        for name in names:
            ax.plot(result.times, result.filters[name].estimates[:, run, i], linewidth=1.2, label=name)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(result.state_labels[i])
    ax.set_title(title or f"Truth and estimates, run {run}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig
