"""Figures of maneuvering-target comparisons: per-axis RMSE with the maneuvers shaded, zoom, IMM modes, detections."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..results import MonteCarloResult
from .figures import distinguish, legend_beside, plain_log_ticks

__all__ = ["Segment", "rmse_panels", "mode_probabilities", "detection_rates"]

_COMPONENTS = (("position", "m"), ("velocity", "m/s"), ("acceleration", "m/s²"))


@dataclass(frozen=True)
class Segment:
    """A maneuver to shade: it acts from ``start`` to ``stop`` (s) on ``axes``; a label and a sign for the colour."""

    start: float
    stop: float
    axes: tuple[str, ...]
    label: str
    sign: float = 1.0
    turn: bool = False


def _shade(ax, segments: Sequence[Segment], axis: str | None, *, label: bool, window: tuple[float, float] | None = None) -> None:
    lo, hi = window if window is not None else (-np.inf, np.inf)
    for s in segments:
        if axis is not None and axis not in s.axes:
            continue
        color = "tab:green" if s.turn else ("tab:red" if s.sign > 0 else "tab:blue")
        ax.axvspan(s.start, s.stop, color=color, alpha=0.10, linewidth=0)
        a, b = max(s.start, lo), min(s.stop, hi)
        if label and a < b:
            ax.text((a + b) / 2, 0.97, s.label, transform=ax.get_xaxis_transform(), ha="center", va="top", fontsize=7, clip_on=True)


def rmse_panels(
    result: MonteCarloResult,
    axis: str,
    indices: tuple[int, int, int],
    segments: Sequence[Segment] = (),
    *,
    window: tuple[float, float] | None = None,
    log: bool = False,
    title: str | None = None,
) -> Figure:
    """Position, velocity and acceleration RMSE of one axis against time, maneuvers shaded.

    Parameters
    ----------
    result
        A Monte Carlo result.
    axis
        Axis name (``"y"``), for labels and for picking its segments.
    indices
        State indices of that axis's position, velocity and acceleration.
    segments
        Maneuvers to shade.
    window
        Optional ``(t0, t1)`` zoom; the y limits follow the visible data.
    log
        Logarithmic RMSE axes.
    title
        Figure title.
    """
    fig = Figure(figsize=(7.0, 7.2), layout="constrained")
    axs = fig.subplots(3, 1, sharex=True)
    t = result.times
    visible = np.ones(t.shape, dtype=bool) if window is None else (t >= window[0]) & (t <= window[1])
    for row, ((comp, unit), idx) in enumerate(zip(_COMPONENTS, indices)):
        ax = axs[row]
        top = 0.0
        for name in result.filter_names:
            r = result.rmse_per_step(name, (idx,))
            ax.plot(t, r, label=name, linewidth=1.3)
            top = max(top, float(np.nanmax(r[visible])) if visible.any() else 0.0)
        _shade(ax, segments, axis, label=row == 0, window=window)
        if log:
            ax.set_yscale("log")
            plain_log_ticks(ax)
        elif window is not None and top > 0:
            ax.set_ylim(0.0, 1.08 * top)
        distinguish(ax, note=False)  # one legend for three panels: styles, not notes, keep overlaps visible
        ax.set_ylabel(f"{axis} {comp} RMSE ({unit})")
        ax.grid(True, alpha=0.3)
    if window is not None:
        axs[0].set_xlim(*window)
    axs[-1].set_xlabel("time (s)")
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 5), fontsize=8)
    fig.suptitle(title or f"{axis} axis RMSE over {result.runs} runs (shaded: maneuvers)")
    return fig


def mode_probabilities(result: MonteCarloResult, segments: Sequence[Segment] = (), labels: dict[str, Sequence[str]] | None = None) -> Figure | None:
    """Mean IMM mode probabilities against time, one panel per IMM filter (None if there is none)."""
    imms = [n for n in result.filter_names if "mode_probs" in result.filters[n].info]
    if not imms:
        return None
    fig = Figure(figsize=(9.0, 2.6 * len(imms) + 0.6), layout="constrained")
    axs = np.atleast_1d(fig.subplots(len(imms), 1, sharex=True))
    for ax, name in zip(axs, imms):
        mu = result.filters[name].info["mode_probs"].mean(axis=1)  # (K, r)
        names = (labels or {}).get(name) or [f"mode {j}" for j in range(mu.shape[1])]
        for j in range(mu.shape[1]):
            ax.plot(result.times, mu[:, j], label=names[j], linewidth=1.3)
        _shade(ax, segments, None, label=False)
        ax.set_ylim(0.0, 1.0)
        ax.set_ylabel("mean mode probability μ")
        ax.set_title(name, fontsize=9)
        ax.grid(True, alpha=0.3)
        distinguish(ax)
        legend_beside(ax, title="mode (model)", title_fontsize=8)
    axs[-1].set_xlabel("time (s)")
    fig.suptitle("IMM mode probabilities, mean over runs (shaded: any axis maneuvering)")
    return fig


def detection_rates(result: MonteCarloResult, axes: str, segments: Sequence[Segment] = (), false_alarm: dict[str, float] | None = None) -> Figure | None:
    """Share of runs whose maneuver detector fired, per axis against time (None if no filter detects)."""
    names = [n for n in result.filter_names if "maneuver" in result.filters[n].info]
    if not names:
        return None
    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
    axs = fig.subplots(len(axes), 1, sharex=True, squeeze=False)[:, 0]
    for a, (ax, axis) in enumerate(zip(axs, axes)):
        for name in names:
            rate = result.filters[name].info["maneuver"][..., a].mean(axis=1)
            ax.plot(result.times, rate, label=name, linewidth=1.2)
            p = (false_alarm or {}).get(name)
            if p is not None:
                ax.axhline(p, color="grey", linestyle="--", linewidth=0.8)
        _shade(ax, segments, axis, label=a == 0)
        ax.set_ylim(0.0, 1.0)
        ax.set_ylabel(f"{axis}: share detecting")
        ax.grid(True, alpha=0.3)
        distinguish(ax, note=False)
    legend_beside(axs[0])
    axs[-1].set_xlabel("time (s)")
    fig.suptitle("Share of runs with D > M (dashed: configured false-alarm rate)")
    return fig
