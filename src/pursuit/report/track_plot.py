"""One track in the plane: measurements, truth, estimate and covariance ellipses."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from ..track import Track
from .figures import leaving_point, mark_leaving, view_limits

__all__ = ["plot_track", "ellipse_axes"]


def _ordinal(n: int) -> str:
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


def ellipse_axes(cov: np.ndarray, sigma: float) -> tuple[float, float, float]:
    """Width, height and angle (degrees) of the ``sigma``-σ ellipse of a 2×2 covariance.

    The ellipse is ``{p : (p − m)ᵀ C⁻¹ (p − m) = sigma²}``: its semi-axes are
    ``sigma √λ`` along the eigenvectors of C.
    """
    lam, vec = np.linalg.eigh(np.asarray(cov, dtype=float))
    lam = np.clip(lam, 0.0, None)
    angle = float(np.degrees(np.arctan2(vec[1, 1], vec[0, 1])))
    return 2.0 * sigma * float(np.sqrt(lam[1])), 2.0 * sigma * float(np.sqrt(lam[0])), angle


def plot_track(
    track: Track,
    *,
    measurements: Any = None,
    truth: Any = None,
    sensors: Any = None,
    position_indices: Sequence[int] = (0, 2),
    labels: Sequence[str] = ("x", "y"),
    unit: str = "m",
    sigma: float = 2.0,
    ellipses: int = 20,
    title: str | None = None,
    ax: Any = None,
) -> Figure:
    """The path of one track in the plane, as a reader of a tracking paper expects it.

    Parameters
    ----------
    track
        One run's track: ``mean`` ``(K, n)`` (or ``(K, 1, n)``) and ``cov``
        ``(K, n, n)``; ellipses need ``cov``.
    measurements
        ``(m, 2)`` measured positions (position fixes), drawn as dots.
    truth
        ``(K', 2)`` true positions, drawn as a line.
    sensors
        ``(s, 2)`` sensor positions (anchors, hydrophones), drawn as triangles.
    position_indices
        The state components on the two axes.
    labels, unit
        Axis names and their unit: ``x (m)``.
    sigma
        The ellipses are the ``sigma``-σ contours of the position covariance
        (the legend gives the probability they hold for a Gaussian:
        1 − exp(−σ²/2), 86.5 % for σ = 2).
    ellipses
        About how many ellipses to draw, evenly spaced over the track (0: none).
    title
        Axes title (default: the track's name).
    ax
        Axes to draw on (default: a new figure's, with the legend below the
        axes; on given axes the legend goes inside them).

    Returns
    -------
    Figure
        The figure the axes belong to.

    Notes
    -----
    The axes are those of the truth (without one, of the measured positions)
    and the sensors, with a margin, never of the estimate: an estimate that
    leaves them is cut at the edge and marked where it first leaves
    ("estimate leaves the axes").  With none of those, the axes fit the estimate.
    """
    mean = np.asarray(track.mean, dtype=float)
    if mean.ndim == 3 and mean.shape[1] == 1:
        mean = mean[:, 0]
    if mean.ndim != 2:
        raise ValueError(f"track: expected one run, mean of shape (K, n), got {np.shape(track.mean)}")
    i, j = (int(k) for k in position_indices)
    own_figure = ax is None
    if own_figure:
        fig = Figure(figsize=(7.0, 5.6), layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    if sensors is not None and len(sensors):
        s = np.asarray(sensors, dtype=float)
        ax.scatter(s[:, 0], s[:, 1], marker="^", s=60, color="tab:red", zorder=5, label="sensors")
    if measurements is not None and len(measurements):
        z = np.asarray(measurements, dtype=float)
        ax.scatter(z[:, 0], z[:, 1], s=9, color="0.55", zorder=2, label="measurements")
    if truth is not None and len(truth):
        t = np.asarray(truth, dtype=float)
        ax.plot(t[:, 0], t[:, 1], color="black", linewidth=1.8, zorder=3, label="truth")
    ax.plot(mean[:, i], mean[:, j], color="tab:blue", linewidth=1.3, marker=".", markersize=3, zorder=4, label="estimate")
    ax.plot(mean[0, i], mean[0, j], marker="o", markersize=6, markerfacecolor="white", color="tab:blue", zorder=4.5, label="first estimate")
    if track.cov is not None and ellipses > 0:
        cov = np.asarray(track.cov, dtype=float).reshape(mean.shape[0], mean.shape[1], mean.shape[1])
        stride = max(1, int(np.ceil(mean.shape[0] / ellipses)))
        prob = 100.0 * (1.0 - np.exp(-0.5 * sigma**2))  # χ²(2) CDF at σ²
        every = "" if stride == 1 else f", every {_ordinal(stride)} estimate"
        for n, k in enumerate(range(0, mean.shape[0], stride)):
            w, h, angle = ellipse_axes(cov[k][np.ix_([i, j], [i, j])], sigma)
            label = f"{sigma:g}σ position ellipse ({prob:.1f} %{every})" if n == 0 else "_nolegend_"
            ax.add_patch(
                Ellipse((mean[k, i], mean[k, j]), w, h, angle=angle, facecolor=(1.0, 0.5, 0.05, 0.12), edgecolor="tab:orange",
                        linewidth=0.9, zorder=3.5, label=label)
            )
    ref = [np.asarray(a, dtype=float).reshape(-1, 2) for a in (truth if truth is not None else measurements, sensors)
           if a is not None and len(a)]
    if ref:
        view = view_limits(np.vstack(ref))
        exit_at = leaving_point(mean[:, [i, j]], view)
        mark_leaving(ax, [] if exit_at is None else [exit_at])
        ax.set_xlim(*view[:, 0])
        ax.set_ylim(*view[:, 1])
        ax.set_autoscale_on(False)
    ax.set_xlabel(f"{labels[0]} ({unit})" if unit else labels[0])
    ax.set_ylabel(f"{labels[1]} ({unit})" if unit else labels[1])
    ax.set_aspect("equal", adjustable="box")  # metres the same both ways: a turn looks like a turn
    ax.grid(True, alpha=0.3)
    ax.set_title(title if title is not None else (track.name or "Track"))
    if own_figure:  # below the axes, so that it never hides data
        fig.legend(loc="outside lower center", ncols=3, fontsize=8, frameon=False)
        _fit_height(fig, ax)
    else:
        ax.legend(fontsize=8)
    return fig


def _fit_height(fig: Figure, ax: Any) -> None:
    """Give a wide or tall path a figure of its shape, not a square with empty bands (equal axes)."""
    ax.autoscale_view()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    if x1 > x0 and y1 > y0:
        ratio = float(np.clip((y1 - y0) / (x1 - x0), 0.3, 1.5))
        width = fig.get_figwidth()
        fig.set_figheight(0.8 * width * ratio + 1.6)  # axes, plus room for the title and the legend
