"""Rauch-Tung-Striebel fixed-interval smoother for the KF, EKF and UKF.

One backward pass serves all Gaussian filters, because each of them records
the same three quantities at every step: the predicted mean x⁻_k, the
predicted covariance P⁻_k and the cross-covariance C_k = cov(x_{k−1}, x⁻_k)
(``P_{k−1} Fᵀ`` for the KF/EKF, the sigma-point cross-covariance for the
UKF/CKF).  The smoother gain is G_k = C_{k+1} (P⁻_{k+1})⁻¹ and

    x^s_k = x_k + G_k (x^s_{k+1} − x⁻_{k+1})
    P^s_k = P_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import symmetrize
from ..track import SMOOTHER_KEYS, Track

__all__ = ["SmoothedTrack", "rts_smooth"]


@dataclass(frozen=True)
class SmoothedTrack:
    """Smoothed means ``(K, *batch, n)`` and covariances ``(K, *batch, n, n)``."""

    mean: np.ndarray
    cov: np.ndarray


def rts_smooth(track: Track) -> SmoothedTrack:
    """Smooth a Gaussian filter's track.

    Parameters
    ----------
    track
        Output of :func:`pursuit.run` with ``store_predictions=True`` and
        ``keep_cov=True``.

    Raises
    ------
    ValueError
        If the track lacks the predictions or covariances, or comes from a
        particle filter or an IMM (recognised by their step info, ``ess`` and
        ``mode_probs``), which have no smoother yet.

    Notes
    -----
    With a fading strategy the filter's predicted covariance includes λ,
    while the cross-covariance does not; the smoother then uses the inflated
    P⁻ in the gain, which damps the backward correction.
    """
    kind = _unsmoothable_kind(track)
    if kind is not None:
        raise ValueError(
            f"rts_smooth: track {track.name!r} comes from {kind}, which pursuit has no smoother for yet; "
            "the RTS smoother takes a Gaussian filter's track (KF, EKF, UKF, CKF or a CS-family filter)"
        )
    missing = [k for k in SMOOTHER_KEYS if k not in track.info]
    if missing or track.cov is None:
        raise ValueError(
            "rts_smooth needs a track from run(..., store_predictions=True, keep_cov=True); "
            f"missing: {', '.join(missing + ([] if track.cov is not None else ['cov']))}"
        )
    x_pred = track.info["pred_mean"]
    P_pred = track.info["pred_cov"]
    C = track.info["cross_cov"]
    K = track.steps
    xs = np.array(track.mean, dtype=float)
    Ps = np.array(track.cov, dtype=float)
    for k in range(K - 2, -1, -1):
        # G = C P⁻⁻¹ computed as a solve: G^T = P⁻^{-1} C^T (P⁻ symmetric)
        G = np.swapaxes(np.linalg.solve(P_pred[k + 1], np.swapaxes(C[k + 1], -1, -2)), -1, -2)
        xs[k] = xs[k] + np.einsum("...ij,...j->...i", G, xs[k + 1] - x_pred[k + 1])
        Ps[k] = symmetrize(Ps[k] + G @ (Ps[k + 1] - P_pred[k + 1]) @ np.swapaxes(G, -1, -2))
    return SmoothedTrack(mean=xs, cov=Ps)


def _unsmoothable_kind(track: Track) -> str | None:
    """What kind of filter made ``track`` if it is one without a smoother (by its step info), else ``None``."""
    if "ess" in track.info:
        return "a particle filter"
    if "mode_probs" in track.info:
        return "an interacting multiple model (IMM) filter"
    return None
