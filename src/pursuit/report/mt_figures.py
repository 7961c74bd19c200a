"""Figures of multi-target comparisons: GOSPA and its parts over time, and one run's scene."""

from __future__ import annotations

from typing import Any, Callable, Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from .figures import distinguish, legend_beside

__all__ = ["gospa_over_time", "scene"]

_PARTS = (("localisation", "localisation"), ("missed", "missed targets"), ("false", "false tracks"))


def gospa_over_time(summaries: Mapping[str, Mapping[str, Any]], times: np.ndarray, metrics: Mapping[str, float]) -> Figure:
    """Mean GOSPA per scan with its 95 % band (top) and its three parts (bottom), one line per tracker.

    Parameters
    ----------
    summaries
        Tracker name → :func:`pursuit.multitarget.metrics.gospa_summary` of its ``(K, M)`` GOSPA.
    times
        ``(K,)`` scan times, s.
    metrics
        ``c``, ``p``, ``alpha`` (named in the title).
    """
    fig = Figure(figsize=(9.0, 6.2), layout="constrained")
    grid = fig.add_gridspec(2, 3, height_ratios=(1.4, 1.0))
    top = fig.add_subplot(grid[0, :])
    parts = [fig.add_subplot(grid[1, j], sharex=top) for j in range(3)]
    t = np.asarray(times, dtype=float)
    colors = {}
    for name, s in summaries.items():
        tot = s["total"]
        (line,) = top.plot(t, tot.per_scan, label=f"{name} (mean {tot.mean:.3g})")
        colors[name] = line.get_color()
        lo, hi = tot.per_scan - tot.per_scan_half_width, tot.per_scan + tot.per_scan_half_width
        if np.isfinite(lo).all():
            top.fill_between(t, lo, hi, color=line.get_color(), alpha=0.15, linewidth=0)
    c, p, a = metrics["c"], metrics["p"], metrics["alpha"]
    top.set_ylabel("GOSPA (distance)")
    top.set_xlabel("time (s)")
    top.set_title(f"GOSPA per scan, mean over runs with 95 % band (c = {c:g}, p = {p:g}, α = {a:g})", fontsize=10)
    top.set_ylim(bottom=0)
    top.grid(alpha=0.3)
    distinguish(top)  # trackers that agree (GNN and JPDA on a clean scene) must not hide each other
    styles = {name: line.get_linestyle() for name, line in zip(summaries, top.lines)}
    legend_beside(top)
    for ax, (key, title) in zip(parts, _PARTS):
        for name, s in summaries.items():
            ax.plot(t, s[key].per_scan, color=colors[name], linestyle=styles[name])
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time (s)")
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    for ax in parts:
        ax.set_ylabel(f"distance^{p:g}")
    return fig


def scene(
    truth: Any,
    scans: Any,
    results: Mapping[str, Any],
    position_indices: Sequence[int],
    run: int,
    *,
    to_position: Callable[[np.ndarray], np.ndarray] | None = None,
    title_prefix: str = "",
) -> Figure:
    """One run: true trajectories, detections (clutter marked) and each tracker's confirmed, labelled tracks.

    One panel per tracker, on the same axes.  Detections are drawn in the
    position plane: directly when they are position fixes, else through
    ``to_position`` (a detection ``(…, m)`` → position ``(…, 2)``); with
    neither, they are left out (the panel says so).
    """
    names = list(results)
    i, j = (int(v) for v in list(position_indices)[:2])
    tpos = truth.states[:, run][..., [i, j]]  # (K, N, 2), NaN where absent
    # the view is the truth's box with a margin: clutter far from the targets would shrink them to a dot
    pts = tpos.reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=-1)]
    view = None
    aspect = 1.0
    if pts.size:
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.15 * float(np.max(hi - lo)) + 1.0
        view = (lo - pad, hi + pad)
        aspect = float((view[1][1] - view[0][1]) / (view[1][0] - view[0][0]))
    panel = 4.2
    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    height = rows * float(np.clip(panel * aspect + 0.9, 3.0, 6.0)) + 0.4
    fig = Figure(figsize=(panel * cols + 1.6, height), layout="constrained")
    grid = fig.subplots(rows, cols, sharex=True, sharey=True, squeeze=False)
    axes = grid.ravel()[: len(names)]
    for spare in grid.ravel()[len(names):]:
        spare.set_visible(False)
    z = scans.z[:, run]  # (K, D, m)
    det = None
    if z.shape[-1] == 2 and to_position is None:
        det = z
    elif to_position is not None:
        det = np.asarray(to_position(z), dtype=float)[..., :2]
    origin = None if scans.origin is None else scans.origin[:, run]
    for ax, name in zip(axes, names):
        if det is not None:
            flat = det.reshape(-1, 2)
            if origin is not None:
                o = origin.reshape(-1)
                clutter = o == -1
                target = o >= 0
                ax.scatter(*flat[clutter].T, s=9, marker="x", color="0.65", linewidths=0.7, label="clutter")
                ax.scatter(*flat[target].T, s=7, color="0.35", label="target detections")
            else:
                ax.scatter(*flat.T, s=7, color="0.5", label="detections")
        for n in range(tpos.shape[1]):
            path = tpos[:, n]
            ok = np.isfinite(path).all(axis=-1)
            if not ok.any():
                continue
            ax.plot(*path[ok].T, color="black", linewidth=1.2, label="truth" if n == 0 else None)
            ax.plot(*path[ok][0], marker="o", color="black", markersize=4)
        res = results[name]
        est = res.mean[:, run][..., [i, j]]  # (K, L, 2)
        lab = res.label[:, run]
        conf = res.confirmed[:, run]
        labels = np.unique(lab[conf])
        for q, label in enumerate(labels):
            at = conf & (lab == label)  # (K, L): where the track with this label is confirmed
            k_idx, l_idx = np.nonzero(at)
            pts = est[k_idx, l_idx]
            color = _tab10(q % 10)
            ax.plot(*pts.T, color=color, linewidth=1.6, alpha=0.9, marker=".", markersize=3)
            ax.annotate(str(int(label)), pts[-1], fontsize=7, color=color, xytext=(3, 3), textcoords="offset points")
        ax.set_title(f"{name}: {len(labels)} confirmed tracks", fontsize=10)
        ax.set_xlabel("x (m)")
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.3)
        if det is None:
            ax.text(0.02, 0.02, "detections not drawn (not position fixes)", transform=ax.transAxes, fontsize=7)
    if view is not None:
        axes[0].set_xlim(view[0][0], view[1][0])
        axes[0].set_ylim(view[0][1], view[1][1])
    for ax in axes:
        ax.set_ylabel("y (m)")
    legend_beside(axes[min(cols, len(names)) - 1])
    fig.suptitle(f"{title_prefix + ': ' if title_prefix else ''}run {run}, truth, detections and labelled tracks", fontsize=11)
    return fig


def _tab10(i: int):
    import matplotlib

    return matplotlib.colormaps["tab10"](i)
