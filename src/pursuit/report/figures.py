"""Figures of a Monte Carlo comparison (matplotlib, no global pyplot state)."""

from __future__ import annotations

import re
from typing import Sequence

import numpy as np
from matplotlib import ticker
from matplotlib.figure import Figure

from ..results import MonteCarloResult

__all__ = [
    "rmse_over_time",
    "trajectory",
    "view_limits",
    "leaving_point",
    "first_outside",
    "mark_leaving",
    "fading_over_time",
    "consistency_over_time",
    "mark_events",
    "figure_problems",
    "labelled",
    "distinguish",
    "legend_beside",
    "plain_log_ticks",
    "coincident",
]

# Each series gets its own line style and marker, so that curves lying on top of
# each other stay visible (and readable in greyscale print).
LINE_STYLES = ("-", "--", "-.", ":")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
# Two curves closer than this share of the axis span at most steps look like one.
COINCIDE = 0.01
COINCIDE_SHARE = 0.9
MARKS_PER_LINE = 10
# ANEES/ANIS above this are drawn at it (and the panel says so): a diverged filter reaches 1e300 or inf
CONSISTENCY_CAP = 1e12


def _new(width: float = 7.6, height: float = 4.0) -> tuple[Figure, object]:
    fig = Figure(figsize=(width, height), layout="constrained")
    ax = fig.add_subplot()
    return fig, ax


def _series(ax) -> list:
    """The labelled data lines of an axes (not reference lines such as axhline/axvline)."""
    return [ln for ln in ax.lines if not ln.get_label().startswith("_") and ln.get_transform() == ax.transData]


def _scaled(ax, y: np.ndarray) -> np.ndarray:
    y = np.asarray(y, dtype=float)
    if ax.get_yscale() == "log":
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(y > 0, np.log10(np.where(y > 0, y, 1.0)), np.nan)
    return y


def coincident(ax, a, b, tol: float = COINCIDE) -> str | None:
    """``"="`` if two lines have the same points, ``"≈"`` if they lie within ``tol`` of the y span, else None.

    The span is that of every series of the axes, on the axis's scale (decades
    on a log axis), so "close" means "drawn on top of each other"; ``"≈"``
    needs that at ``COINCIDE_SHARE`` of the points (two filters that differ
    only in the first steps still hide each other for the rest).
    """
    xa, ya = (np.asarray(v, dtype=float) for v in a.get_data())
    xb, yb = (np.asarray(v, dtype=float) for v in b.get_data())
    if xa.shape != xb.shape or not np.array_equal(xa, xb, equal_nan=True):
        return None
    if np.array_equal(ya, yb, equal_nan=True):
        return "="
    sa, sb = _scaled(ax, ya), _scaled(ax, yb)
    every = np.concatenate([_scaled(ax, ln.get_ydata()) for ln in _series(ax)] or [sa])
    span = float(np.nanmax(every) - np.nanmin(every)) if np.isfinite(every).any() else 0.0
    both = np.isfinite(sa) & np.isfinite(sb)
    if not both.any() or np.any(np.isfinite(sa) != np.isfinite(sb)):
        return None
    close = np.abs(sa[both] - sb[both]) <= tol * span
    return "≈" if float(np.mean(close)) >= COINCIDE_SHARE else None


def distinguish(ax, *, note: bool = True, skip: Sequence[str] = ("truth",)) -> None:
    """Draw the series of an axes distinguishably: own line style, staggered markers, coincidences named.

    Each labelled line gets the next line style and marker; the markers of
    line ``i`` of ``n`` start ``i/n`` of the way into the marker spacing, so
    two curves on top of each other show both marker shapes.  With ``note``,
    a line that coincides with an earlier one (:func:`coincident`) says so in
    its legend label: ``"EWFMKF (= STF)"`` (same values) or ``"UKF (≈ CKF)"``.
    Lines labelled in ``skip`` (the truth) keep their own style.  Call it
    after the y scale is set and before the legend is drawn.
    """
    lines = [ln for ln in _series(ax) if ln.get_label() not in skip]
    n = max(len(lines), 1)
    for i, ln in enumerate(lines):
        k = len(ln.get_xdata())
        every = max(1, k // MARKS_PER_LINE)
        ln.set_linestyle(LINE_STYLES[i % len(LINE_STYLES)])
        ln.set_marker(MARKERS[i % len(MARKERS)])
        ln.set_markersize(4.5)
        ln.set_markerfacecolor("none")
        ln.set_markevery((i * every // n, every) if k > MARKS_PER_LINE else None)
    if not note:
        return
    for j, ln in enumerate(lines):
        for first in lines[:j]:
            how = coincident(ax, first, ln)
            if how:
                ln.set_label(f"{ln.get_label()} ({how} {first.get_label().split(' (')[0]})")
                break


def legend_beside(ax, **kw) -> None:
    """The axes' legend to the right of the plot, where it cannot hide data (constrained layout makes room)."""
    kw.setdefault("fontsize", 8)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, **kw)


class _PlainLogFormatter(ticker.LogFormatter):
    """Matplotlib's choice of which log ticks to label, written as plain numbers with up to four digits."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        # an axis stretched to the float limit by a diverged filter puts a tick at inf: no label, no crash
        return super().__call__(x, pos) if np.isfinite(x) and x > 0 else ""

    def _num_to_string(self, x: float, vmin: float, vmax: float) -> str:
        text = f"{x:.4g}"
        return f"{x:.0f}" if "e" in text and 1.0 <= abs(x) < 1e7 else text  # 10000, not 1e+04


def plain_log_ticks(ax, axis: str = "y") -> None:
    """Label a log axis with plain numbers (2, 3, 0.0025, 100) instead of ``2×10⁰`` or ``3e-03``."""
    a = ax.yaxis if axis == "y" else ax.xaxis
    a.set_major_formatter(_PlainLogFormatter())
    a.set_minor_formatter(_PlainLogFormatter(labelOnlyBase=False, minor_thresholds=(1.2, 0.5)))


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

    A filter with runs flagged diverged (:mod:`pursuit.divergence`) says how
    many in its legend label; if its RMSE reaches :data:`DWARF_RATIO` times
    that of every filter without, the y axis is logarithmic even when
    ``log`` is False, so the other curves stay readable.
    """
    fig, ax = _new()
    names = list(filters) if filters is not None else result.filter_names
    label = component if isinstance(component, str) else "state " + ",".join(map(str, component))
    curves = {name: result.rmse_per_step(name, component) for name in names}
    counts = {name: (result.divergence(name) or {}).get("diverged", 0) for name in names}
    for name in names:
        n = counts[name]
        text = f"{name} (diverged in {n} of {result.runs} runs)" if n else name
        ax.plot(result.times, curves[name], label=text, linewidth=1.4)
    if not log and _dwarfs_the_rest(curves, counts):
        log = True  # a diverged filter's curve would flatten every other one on a linear axis
    if log:
        ax.set_yscale("log")
        plain_log_ticks(ax)
    distinguish(ax)
    u = result.component_unit(component) if unit is None else unit
    ax.set_xlabel("time (s)")
    ax.set_ylabel(labelled(f"{label} RMSE", u))
    ax.set_title(title or f"{label.capitalize()} RMSE over {result.runs} runs")
    mark_events(ax, events)
    ax.grid(True, alpha=0.3)
    legend_beside(ax)
    return fig


DWARF_RATIO = 100.0
"""A diverged filter's largest RMSE this many times the others' switches an RMSE figure to a log axis."""


def _dwarfs_the_rest(curves: dict[str, np.ndarray], diverged: dict[str, int]) -> bool:
    """Whether a filter with diverged runs reaches :data:`DWARF_RATIO` times the largest RMSE of the filters without."""
    def top(names):
        vals = [np.nanmax(np.where(np.isfinite(curves[n]), curves[n], np.nan), initial=0.0) for n in names]
        return max(vals, default=0.0)

    bad = [n for n in curves if diverged[n]]
    good = [n for n in curves if not diverged[n]]
    if not bad or not good:
        return False
    rest = top(good)
    return rest > 0 and (top(bad) > DWARF_RATIO * rest or any(not np.isfinite(curves[n]).all() for n in bad))


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

    The axes are those of the truth and the sensors (``landmarks``) with a
    margin (:data:`VIEW_MARGIN`), never of the estimates: an estimate that
    leaves them is cut at the edge and marked where it first leaves (legend
    entry "estimate leaves the axes"), and a filter whose run was flagged
    diverged (:mod:`pursuit.divergence`) says so, with the step, in its
    legend label; a diverged run's estimate is drawn only up to where it
    first leaves.
    """
    stored = result.stored()
    if not 0 <= run < stored.runs:
        kept = "" if stored is result else f" (only runs 0..{stored.runs - 1} of {result.runs} were kept whole)"
        raise ValueError(f"run: must lie in [0, {stored.runs - 1}], got {run}{kept}")
    result = stored
    fig, ax = _new(7.6, 4.8)
    names = list(filters) if filters is not None else result.filter_names
    pos = list(result.position_indices) or [0]
    truth = result.truth[:, run, :]
    exits = []
    if len(pos) >= 2:
        i, j = pos[0], pos[1]
        ax.plot(truth[:, i], truth[:, j], color="black", linewidth=2.0, label="truth")
        lm = np.asarray(landmarks, dtype=float).reshape(-1, 2) if landmarks is not None and len(landmarks) else None
        view = view_limits(truth[:, [i, j]], lm)
        for name in names:
            est = result.filters[name].estimates[:, run, :][:, [i, j]]
            out = leaving_point(est, view)
            if out is not None and _flagged_label(result, name, run) != name:
                # a diverged run is drawn up to where it leaves: its later wanderings would cross the whole plot
                est = np.vstack([est[: first_outside(est, view)], out])
            ax.plot(est[:, 0], est[:, 1], linewidth=1.2, label=_flagged_label(result, name, run))
            exits.append(out)
        if lm is not None:
            ax.scatter(lm[:, 0], lm[:, 1], marker="^", color="tab:red", zorder=5, label="sensors")
        ax.set_xlabel(labelled(result.state_labels[i], result.unit(i)))
        ax.set_ylabel(labelled(result.state_labels[j], result.unit(j)))
        ax.set_aspect("equal", adjustable="box")  # "datalim" would move the limits set below
    else:
        i = pos[0]
        t = np.asarray(result.times, dtype=float)
        ax.plot(t, truth[:, i], color="black", linewidth=2.0, label="truth")
        span = np.array([[t[0], np.nanmin(truth[:, i])], [t[-1], np.nanmax(truth[:, i])]])
        view = view_limits(span, None, axes=(1,))
        if t[-1] > t[0]:
            view[:, 0] = t[0], t[-1]  # time: the whole run, no margin
        for name in names:
            est = result.filters[name].estimates[:, run, i]
            ax.plot(t, est, linewidth=1.2, label=_flagged_label(result, name, run))
            exits.append(leaving_point(np.column_stack([t, est]), view))
        ax.set_xlabel("time (s)")
        ax.set_ylabel(labelled(result.state_labels[i], result.unit(i)))
    mark_leaving(ax, [e for e in exits if e is not None])
    ax.set_xlim(*view[:, 0])
    ax.set_ylim(*view[:, 1])
    ax.set_autoscale_on(False)
    ax.set_title(title or f"Truth and estimates, run {run}")
    ax.grid(True, alpha=0.3)
    distinguish(ax)
    legend_beside(ax)
    return fig


VIEW_MARGIN = 0.25
"""Share of the truth's (and sensors') extent added on every side of a state-space plot."""


def view_limits(points: np.ndarray, sensors: np.ndarray | None = None, *, axes: Sequence[int] = (0, 1)) -> np.ndarray:
    """``(2, 2)`` limits ``[[x0, y0], [x1, y1]]`` of the finite ``points`` (and ``sensors``) with a margin.

    The margin is :data:`VIEW_MARGIN` of the largest extent among ``axes``
    (the axes in the same unit) on each of them; the other axes get that
    share of their own extent.  A point-like extent gets a margin of 1 unit.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if sensors is not None and len(sensors):
        p = np.vstack([p, np.asarray(sensors, dtype=float).reshape(-1, 2)])
    p = p[np.isfinite(p).all(axis=1)]
    if not len(p):
        return np.array([[0.0, 0.0], [1.0, 1.0]])
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = hi - lo
    common = max(float(np.max(extent[list(axes)])), 0.0)
    margin = VIEW_MARGIN * extent
    for a in axes:
        margin[a] = VIEW_MARGIN * common
    margin = np.where(margin > 0, margin, np.maximum(1.0, 1e-9 * np.abs(lo)))
    return np.array([lo - margin, hi + margin])


def first_outside(path: np.ndarray, view: np.ndarray) -> int | None:
    """Index of the first point of a ``(K, 2)`` path outside the box ``view`` (non-finite counts), or None."""
    path = np.asarray(path, dtype=float)
    lo, hi = view
    with np.errstate(invalid="ignore"):
        inside = np.isfinite(path).all(axis=1) & np.all((path >= lo) & (path <= hi), axis=1)
    return None if inside.all() else int(np.argmin(inside))


def leaving_point(path: np.ndarray, view: np.ndarray) -> np.ndarray | None:
    """Where a ``(K, 2)`` path first leaves the box ``view`` (on its edge), or None if it stays inside.

    A non-finite point counts as outside; a path that starts outside is
    marked at its first point, clipped to the box.
    """
    path = np.asarray(path, dtype=float)
    lo, hi = view
    k = first_outside(path, view)
    if k is None:
        return None
    p1 = path[k]
    if k == 0 or not np.isfinite(p1).all():
        p = path[k - 1] if k > 0 else np.clip(np.nan_to_num(p1, nan=0.0), lo, hi)
        return np.clip(p, lo, hi)
    p0 = path[k - 1]
    d = p1 - p0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - p0) / d, np.where(d < 0, (lo - p0) / d, np.inf))
    return np.clip(p0 + float(np.min(t)) * d, lo, hi)


LEAVES_LABEL = "estimate leaves the axes"
"""The legend entry of the marks where estimates leave a state-space plot."""


def mark_leaving(ax, points: Sequence[np.ndarray]) -> None:
    """Mark where estimates leave the axes: red crosses on the edge, one legend entry."""
    if not points:
        return
    xy = np.asarray(points, dtype=float)
    ax.scatter(xy[:, 0], xy[:, 1], marker="X", s=70, color="tab:red", edgecolor="white", linewidth=0.6,
               zorder=6, clip_on=False, label=LEAVES_LABEL)


def _flagged_label(result: MonteCarloResult, name: str, run: int) -> str:
    """The filter's name, with the step at which this run was flagged diverged, if it was."""
    flags = result.filters[name].info.get("diverged")
    if flags is None:
        return name
    col = np.asarray(flags)[:, run]
    if not col.any():
        return name
    return f"{name} (diverged at step {int(np.argmax(col)) + 1})"


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
            plain_log_ticks(ax)
        distinguish(ax, note=False)  # one legend serves both columns, whose overlaps differ: styles, not notes
        ax.set_ylabel(f"{statistic} λ")
        ax.set_title(panel, fontsize=10)
        for a in row:
            mark_events(a, (events or {}).get(panel, ()))
            a.grid(True, alpha=0.3)
        if share:
            distinguish(row[1], note=False)
            row[1].set_ylabel("runs faded (%)")
            row[1].set_ylim(-3.0, 103.0)
            row[1].set_title("share of runs with λ > 1", fontsize=10)
    legend_beside(grid[0, -1])
    for a in grid[-1]:
        a.set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    return fig


def consistency_over_time(
    result: MonteCarloResult,
    *,
    filters: Sequence[str] | None = None,
    level: float = 0.95,
    title: str | None = None,
    events: Sequence[tuple[float, str]] = (),
) -> Figure | None:
    """ANEES and ANIS against time with the per-step χ² band of a consistent filter.

    One panel per statistic the filters report (NEES needs covariances, NIS
    innovations); the shaded band is the two-sided ``level`` χ² interval of
    one step's average over the runs (:meth:`MonteCarloResult.consistency_bounds`),
    drawn once where the filters share it and as dotted lines in the filter's
    colour where a filter's differs.  The y axis is logarithmic: an
    inconsistent filter is off by orders of magnitude.  None when no filter
    reports either statistic.
    """
    names = list(filters) if filters is not None else result.filter_names
    panels = []
    for what in ("nees", "nis"):
        have = []
        for name in names:
            try:
                have.append((name, getattr(result, f"a{what}")(name)))
            except ValueError:
                continue
        if have:
            panels.append((what, have))
    if not panels:
        return None
    fig = Figure(figsize=(7.6, 2.9 * len(panels) + 0.7), layout="constrained")
    axs = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    t = result.times
    for ax, (what, have) in zip(axs, panels):
        band = result.consistency_bounds(have[0][0], what, level)
        ax.fill_between(t, *band, color="0.5", alpha=0.22, linewidth=0, label=f"χ² {100 * level:g} % band")
        clipped = []
        for name, values in have:
            values = np.asarray(values, dtype=float)
            # a diverged filter's ANEES reaches 1e300 or inf and would stretch the axis past the float range
            over = ~np.isfinite(values) | (values > CONSISTENCY_CAP)
            if np.any(over & ~np.isnan(values)):
                clipped.append(name)
                values = np.where(over & ~np.isnan(values), CONSISTENCY_CAP, values)
            (line,) = ax.plot(t, values, label=name, linewidth=1.3)
            lo, hi = result.consistency_bounds(name, what, level)
            if not (np.array_equal(lo, band[0], equal_nan=True) and np.array_equal(hi, band[1], equal_nan=True)):
                for bound in (lo, hi):  # this filter's own band (other degrees of freedom)
                    ax.plot(t, bound, color=line.get_color(), linestyle=":", linewidth=0.9, label=f"_band of {name}")
        if clipped:
            ax.axhline(CONSISTENCY_CAP, color="0.4", linewidth=0.8, linestyle=(0, (1, 1)))
        ax.set_yscale("log")
        plain_log_ticks(ax)
        distinguish(ax)
        mark_events(ax, events)
        ax.set_ylabel(f"A{what.upper()} (average over runs)")
        note = f"\n{', '.join(clipped)}: values above {CONSISTENCY_CAP:.0e} (or infinite) drawn at the dotted line" if clipped else ""
        ax.set_title(f"{what.upper()}: {'state' if what == 'nees' else 'innovation'} error normalised by the filter's covariance"
                     + note, fontsize=9)
        ax.grid(True, alpha=0.3)
        legend_beside(ax)
    axs[-1].set_xlabel("time (s)")
    fig.suptitle(title or f"Consistency over {result.runs} runs (inside the band: as confident as accurate)")
    return fig


def labelled(name: str, unit: str | None) -> str:
    """An axis label: ``name (unit)``; the bare name for a dimensionless (``""``) or unknown (None) unit."""
    return f"{name} ({unit})" if unit else name


def figure_problems(fig: Figure) -> list[str]:
    """What keeps a figure from being publication-ready.

    Every axes that shows data needs a y label and an x label (an axes whose
    x axis is shared with a labelled one, as in stacked panels, or a figure
    with a common x label, is fine), and an x label names a quantity (not a
    bare symbol such as ``l`` without a unit); the series of an axes that
    shows more than one labelled series must appear in a legend (its own,
    another panel's or the figure's); no legend may cover a data point; two
    series that coincide (:func:`coincident`) must differ in line style or
    marker; tick labels are plain numbers, not ``2×10⁰``.  Returns an empty
    list for a good figure.
    """
    fig.draw_without_rendering()  # legend positions and tick labels exist only after a layout
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
        xlabel = ax.get_xlabel().strip()
        if xlabel and "(" not in xlabel and len(re.sub(r"\W", "", xlabel)) < 2:
            problems.append(f"{where}: x label {xlabel!r} names no quantity")
        labels = {a.get_label() for a in (*ax.lines, *ax.collections) if not a.get_label().startswith("_")}
        if len(labels) > 1 and not labels <= in_legend:
            problems.append(f"{where}: series {sorted(labels - in_legend)} are in no legend")
        ticks = [t.get_text() for t in (*ax.get_xticklabels(which="both"), *ax.get_yticklabels(which="both")) if t.get_visible()]
        if any("times" in t for t in ticks):
            problems.append(f"{where}: tick labels in scientific notation ({[t for t in ticks if 'times' in t][0]})")
        series = _series(ax)
        for j, b in enumerate(series):
            for a in series[:j]:
                alike = (a.get_linestyle(), a.get_marker()) == (b.get_linestyle(), b.get_marker())
                if alike and coincident(ax, a, b):
                    problems.append(f"{where}: series {a.get_label()!r} and {b.get_label()!r} coincide and are drawn alike")
        for leg in legends:
            box = leg.get_window_extent()
            inside = ax.get_window_extent()
            for ln in series + [ln for ln in ax.lines if ln.get_transform() == ax.transData and ln not in series]:
                xy = ln.get_transform().transform(np.column_stack([np.asarray(v, dtype=float) for v in ln.get_data()]))
                xy = xy[np.isfinite(xy).all(axis=1)]
                visible = (xy[:, 0] >= inside.x0) & (xy[:, 0] <= inside.x1) & (xy[:, 1] >= inside.y0) & (xy[:, 1] <= inside.y1)
                covered = visible & (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
                if covered.any():
                    problems.append(f"{where}: the legend covers {int(covered.sum())} point(s) of {ln.get_label()!r}")
    return problems
