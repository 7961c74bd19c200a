"""Figures of a Monte Carlo comparison (matplotlib, no global pyplot state)."""

from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..results import MonteCarloResult

__all__ = ["rmse_over_time", "trajectory", "fading_over_time", "mark_events", "figure_problems", "labelled"]


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
    events: Sequence[tuple[float, str]] = (),
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
        Unit for the y label (default: the scenario's unit of the
        component, :meth:`MonteCarloResult.component_unit`; none when it
        declared none or the component mixes units).
    filters
        Subset and order of filters (default all).
    title
        Figure title (default derived from the component).
    events
        ``(time, label)`` pairs drawn as labelled vertical lines (e.g. an
        outlier).
    """
    fig, ax = _new()
    names = list(filters) if filters is not None else result.filter_names
    label = component if isinstance(component, str) else "state " + ",".join(map(str, component))
    for name in names:
        ax.plot(result.times, result.rmse_per_step(name, component), label=name, linewidth=1.4)
    if log:
        ax.set_yscale("log")
    u = result.component_unit(component) if unit is None else unit
    ax.set_xlabel("time (s)")
    ax.set_ylabel(labelled(f"{label} RMSE", u))
    ax.set_title(title or f"{label.capitalize()} RMSE over {result.runs} runs")
    mark_events(ax, events)
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig


def mark_events(ax, events: Sequence[tuple[float, str]]) -> None:
    """Draw each ``(time, label)`` as a dashed vertical line labelled at the top of the axes."""
    for t, text in events:
        ax.axvline(t, color="0.35", linestyle="--", linewidth=1.0, zorder=0)
        ax.annotate(text, (t, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12),
                    textcoords="offset points", fontsize=8, color="0.25")


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
    stored = result.stored()
    if not 0 <= run < stored.runs:
        kept = "" if stored is result else f" (only runs 0..{stored.runs - 1} of {result.runs} were kept whole)"
        raise ValueError(f"run: must lie in [0, {stored.runs - 1}], got {run}{kept}")
    result = stored
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
        ax.set_xlabel(labelled(result.state_labels[i], result.unit(i)))
        ax.set_ylabel(labelled(result.state_labels[j], result.unit(j)))
        ax.set_aspect("equal", adjustable="datalim")
    else:
        i = pos[0]
        ax.plot(result.times, truth[:, i], color="black", linewidth=2.0, label="truth")
        for name in names:
            ax.plot(result.times, result.filters[name].estimates[:, run, i], linewidth=1.2, label=name)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(labelled(result.state_labels[i], result.unit(i)))
    ax.set_title(title or f"Truth and estimates, run {run}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    return fig


def fading_over_time(
    results: dict[str, MonteCarloResult],
    *,
    filters: Sequence[str] | None = None,
    statistic: str = "mean",
    log: bool = True,
    events: dict[str, Sequence[tuple[float, str]]] | None = None,
    title: str | None = None,
    share: bool = False,
) -> Figure:
    """The fading factor λ_k against time, one panel per result (e.g. per condition).

    Parameters
    ----------
    results
        ``{panel title: result}``; each filter's step info must hold
        ``fading`` (every Gaussian filter records it).
    filters
        Subset and order of filters (default: those that recorded λ).
    statistic
        ``"mean"`` or ``"median"`` of λ over the runs at each step.  The mean
        of a strategy that fades hard in a few runs (IFMKF saturating at
        λ_max) is dominated by those runs; the median with ``share`` shows
        what a typical run does and how many runs fade.
    log
        Logarithmic λ axis.
    events
        Optional ``{panel title: [(time, label), ...]}`` to mark.
    title
        Figure title.
    share
        Add a second column with the share of runs that faded (λ > 1) at
        each step, in percent.
    """
    if statistic not in ("mean", "median"):
        raise ValueError(f"statistic: must be 'mean' or 'median', got {statistic!r}")
    reduce = np.mean if statistic == "mean" else np.median
    panels = list(results.items())
    ncols = 2 if share else 1
    fig = Figure(figsize=(6.4 * (1.7 if share else 1.0), 2.6 * max(len(panels), 1) + 0.6), layout="constrained")
    grid = fig.subplots(len(panels), ncols, sharex=True, squeeze=False)
    axes = grid[:, 0]
    for row, (panel, result) in zip(grid, panels):
        ax = row[0]
        names = list(filters) if filters is not None else result.filter_names
        for name in names:
            if "fading" not in result.info_keys(name):
                continue
            if statistic == "mean":  # from the reduced statistics: works in summary mode too
                values = result.info_mean(name, "fading")
            else:
                if result.store != "full":
                    raise ValueError("statistic='median' needs every run's fading factors (store='full')")
                values = reduce(result.filters[name].info["fading"], axis=1)
            (line,) = ax.plot(result.times, values, label=name, linewidth=1.3)
            if share:
                faded = 100.0 * np.asarray(result.info_mean(name, "faded"), dtype=float)
                row[1].plot(result.times, faded, label=name, linewidth=1.3, color=line.get_color())
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(f"{statistic} λ")
        ax.set_title(panel, fontsize=10)
        for a in row:
            mark_events(a, (events or {}).get(panel, ()))
            a.grid(True, alpha=0.3)
        if share:
            row[1].set_ylabel("runs faded (%)")
            row[1].set_ylim(-3.0, 103.0)
            row[1].set_title("share of runs with λ > 1", fontsize=10)
    for a in grid[-1]:
        a.set_xlabel("time (s)")
    axes[0].legend(fontsize=8, ncol=3)
    if title:
        fig.suptitle(title)
    return fig


def labelled(name: str, unit: str | None) -> str:
    """An axis label: ``name (unit)``; the bare name for a dimensionless (``""``) or unknown (None) unit."""
    return f"{name} ({unit})" if unit else name


def figure_problems(fig: Figure) -> list[str]:
    """What keeps a figure from being publication-ready: unlabelled axes, a missing legend.

    Every axes that shows data needs a y label and an x label (an axes whose
    x axis is shared with a labelled one, as in stacked panels, or a figure
    with a common x label, is fine); the series of an axes that shows more
    than one labelled series must appear in a legend (its own, another
    panel's or the figure's).  Returns an empty list for a good figure.
    """
    problems = []
    axes = fig.get_axes()
    legends = [leg for ax in axes if (leg := ax.get_legend()) is not None] + list(fig.legends)
    in_legend = {t.get_text() for leg in legends for t in leg.get_texts()}
    common_x = bool(getattr(fig, "_supxlabel", None) and fig._supxlabel.get_text().strip())
    for n, ax in enumerate(axes):
        if not (ax.lines or ax.collections or ax.patches or ax.images):
            continue
        where = f"axes {n} ({ax.get_title() or 'untitled'})"
        shared = [a for a in ax.get_shared_x_axes().get_siblings(ax) if a is not ax]
        if not ax.get_xlabel().strip() and not common_x and not any(a.get_xlabel().strip() for a in shared):
            problems.append(f"{where}: no x label")
        if not ax.get_ylabel().strip():
            problems.append(f"{where}: no y label")
        labels = {a.get_label() for a in (*ax.lines, *ax.collections) if not a.get_label().startswith("_")}
        if len(labels) > 1 and not labels <= in_legend:
            problems.append(f"{where}: series {sorted(labels - in_legend)} are in no legend")
    return problems
