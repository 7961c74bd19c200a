"""Figures of particle-filter experiments: errors of one run, particle clouds, metrics against a swept value."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from ..results import MonteCarloResult
from .figures import MARKERS, distinguish, labelled, legend_beside, plain_log_ticks

__all__ = ["abs_error_over_time", "particle_clouds", "metric_against_value"]


def abs_error_over_time(
    result: MonteCarloResult, run: int = 0, component: int = 0, *, filters: Sequence[str] | None = None, title: str | None = None
) -> Figure:
    """|x̂ − x| of one state component against time, one run, each filter."""
    if not 0 <= run < result.runs:
        raise ValueError(f"run: must lie in [0, {result.runs - 1}], got {run}")
    fig = Figure(figsize=(7.6, 4.0), layout="constrained")
    ax = fig.add_subplot()
    for name in filters if filters is not None else result.filter_names:
        err = np.abs(result.filters[name].estimates[:, run, component] - result.truth[:, run, component])
        ax.plot(result.times, err, linewidth=1.2, label=name)
    label = result.state_labels[component]
    ax.set_xlabel("time (s)")
    ax.set_ylabel(labelled(f"|{label} error|", result.unit(component)))
    ax.set_title(title or f"Absolute error of {label}, run {run}")
    ax.grid(True, alpha=0.3)
    distinguish(ax)
    legend_beside(ax)
    return fig


def particle_clouds(
    snapshots: Mapping[str, Mapping[int, Mapping[str, np.ndarray]]],
    truth: np.ndarray,
    component: int = 0,
    *,
    label: str = "x",
    title: str | None = None,
) -> Figure:
    """Particle values against particle index at chosen steps: one row per filter, one column per step.

    Parameters
    ----------
    snapshots
        ``{filter: {step: {"particles": (1, N, n), "weights": (1, N)}}}``
        for one run (see :func:`pursuit.engine.snapshots.particle_snapshots`).
    truth
        ``(K, n)`` truth of that run; a horizontal line marks the true value.
    component
        State component to plot.
    label
        Its axis label, with the unit (e.g. ``"x (m)"``).
    """
    names = list(snapshots)
    steps = sorted({s for snap in snapshots.values() for s in snap})
    if not names or not steps:
        raise ValueError("snapshots: nothing to draw")
    fig = Figure(figsize=(3.2 * len(steps), 2.6 * len(names)), layout="constrained")
    axes = fig.subplots(len(names), len(steps), squeeze=False, sharey="col")
    for r, name in enumerate(names):
        for c, step in enumerate(steps):
            ax = axes[r][c]
            snap = snapshots[name].get(step)
            if snap is None:
                ax.set_visible(False)
                continue
            p = np.asarray(snap["particles"])[0, :, component]
            w = np.asarray(snap["weights"])[0]
            size = 4.0 + 60.0 * w / max(float(w.max()), 1e-300)
            ax.scatter(np.arange(p.size), p, s=size, alpha=0.6, linewidths=0)
            ax.axhline(truth[step - 1, component], color="black", linewidth=1.0, label="truth")
            ax.set_title(f"{name}, step {step}", fontsize=9)
            ax.set_ylabel(label)
            ax.set_xlabel("particle index")
            ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig


def _series_name(row: Mapping[str, object], variants: set) -> str:
    """``"UPF"``, or ``"UPF, 4 corner nodes"`` when the rows have scenario variants."""
    return str(row["filter"]) if len(variants) <= 1 or not row.get("variant") else f"{row['filter']}, {row['variant']}"


def metric_against_value(
    rows: Sequence[Mapping[str, object]],
    value_key: str,
    metric: str,
    *,
    error_key: str | None = None,
    xlabel: str | None = None,
    ylabel: str | None = None,
    log: bool = False,
    title: str | None = None,
    paper: Sequence[tuple[str, float, float, str]] = (),
    references: Sequence[tuple[str, float]] = (),
) -> Figure:
    """A metric against the swept value, one line per filter (and variant).

    Rows without a swept value (baselines such as a UKF that has no
    particles) are drawn as horizontal lines across the plot, each in its own
    colour and dash pattern and named in the legend with ``(baseline)``.
    ``xlabel`` names the swept quantity (default ``value_key``).

    ``paper`` marks a paper's values beside ours: ``(series, x, value,
    legend)``, drawn as large filled hexagons (a shape no series uses) in the
    colour of that series, a little right of ``x`` so that neither hides our
    point, one legend entry per legend text.  ``references``
    are ``(label, value)`` horizontal lines in black (e.g. an MMSE limit),
    named in the legend as given.
    """
    fig = Figure(figsize=(7.6, 4.0), layout="constrained")
    ax = fig.add_subplot()
    groups: dict[str, list[Mapping[str, object]]] = {}
    variants = {row.get("variant") for row in rows}
    for row in rows:
        groups.setdefault(_series_name(row, variants), []).append(row)
    swept = [float(r[value_key]) for r in rows if r.get(value_key) is not None]
    baselines = []
    for key, rs in groups.items():
        base = [r for r in rs if r.get(value_key) is None]
        baselines.extend((key, r) for r in base)
        rs = [r for r in rs if r.get(value_key) is not None]
        if not rs:
            continue
        x = np.array([float(r[value_key]) for r in rs])
        y = np.array([float(r[metric]) for r in rs])
        order = np.argsort(x)
        (line,) = ax.plot(x[order], y[order], label=key)
        if error_key is not None:
            err = np.array([float(r[error_key]) for r in rs])
            ax.errorbar(x[order], y[order], yerr=err[order], fmt="none", capsize=3, ecolor=line.get_color(), elinewidth=1.0)
    if log:
        ax.set_yscale("log")
        plain_log_ticks(ax)
    distinguish(ax)
    colours = {ln.get_label().split(" (")[0]: ln.get_color() for ln in ax.lines if not ln.get_label().startswith("_")}
    span = (min(swept), max(swept)) if swept else (0.0, 1.0)
    first = sum(1 for ln in ax.lines if not ln.get_label().startswith("_"))  # colours after the swept series (not the error caps)
    dashes = ((0, (6, 3)), (0, (2, 2)), (0, (8, 3, 2, 3)), (0, (1, 3)))
    xs = np.linspace(span[0], span[1], 9)
    for i, (key, row) in enumerate(baselines):
        # a real line over the swept range (not axhline), so the legend and the checks see it as data; own dashes
        # and markers (staggered) so that two baselines at nearly the same value both stay visible
        ax.plot(xs, np.full(xs.shape, float(row[metric])), linestyle=dashes[i % len(dashes)], linewidth=1.2,
                color=f"C{(first + i) % 10}", marker=MARKERS[-1 - i % len(MARKERS)], markersize=5,
                markerfacecolor="none", markevery=(i % 2, 2), label=f"{key} (baseline)")
    for j, (label, value) in enumerate(references):
        ax.plot(span, [value, value], color="black", linestyle=(0, (1, 1.5)) if j % 2 == 0 else (0, (5, 2, 1, 2)),
                linewidth=1.6, label=label)
    marked: dict[str, list[tuple[float, float, str]]] = {}
    for series, x, value, legend in paper:
        marked.setdefault(legend, []).append((x, value, colours.get(series, "black")))
    shift = 0.012 * (span[1] - span[0])  # just right of our point at the same value, so neither hides the other
    for legend, pts in marked.items():
        ax.plot([p[0] + shift for p in pts], [p[1] for p in pts], linestyle="none", marker="H", markersize=9,
                color=pts[0][2], markeredgecolor="black", markeredgewidth=0.8, zorder=5, label=legend)
    ax.set_xlabel(xlabel or value_key)
    ax.set_ylabel(ylabel or metric)
    ax.set_title(title or f"{metric} against {xlabel or value_key}")
    ax.grid(True, alpha=0.3)
    legend_beside(ax)
    return fig
