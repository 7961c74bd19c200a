"""EPMHT: PMHT for maneuvering targets, the maneuver input as a Markov chain (docs/spec/05-multi-target-pmht.md §3).

The motion model gains a piecewise-constant input per axis,
``x_t = F x_{t−1} + G u_t + w_t`` with ``u_t ∈ {a_1, …, a_J}`` a Markov
chain (transition matrix Π), and EM treats the inputs as missing data too:

* **E-step**: besides PMHT's association weights, a forward–backward (HMM)
  pass per track and axis over the window with emissions
  ``N(x̂_t; F x̂_{t−1} + G a_j, F P F' + Q)`` (x̂, P: the current smoothed
  states and covariances, restricted to the axis's position and velocity)
  gives ``γ_tj = P(u_t = a_j | window)``;
* **M-step**: PMHT's smoother with the known input ``ū_t = Σ_j γ_tj a_j``.

G per axis is ``dt²/2`` on the position and ``dt`` on the velocity (a
constant-velocity state).  The chain's distribution at a window's prior scan
is the forward (filtered) probability carried over from the previous window;
a new track starts from ``mode_prior`` (default uniform).  The emission uses
F P F' + Q as the spec says, so this E-step is not the exact EM one and the
objective (PMHT's, with the input ū) is not guaranteed to increase; with the
single level {0}, ū = 0 and EPMHT is PMHT step for step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._linalg import inv_spd, quadratic_form
from .._validation import as_float_array, in_range
from .pmht import LinearModel, Maneuver, PMHTTracker

__all__ = ["EPMHTTracker", "mode_posteriors"]


def mode_posteriors(
    model: LinearModel,
    maneuver: Maneuver,
    X: np.ndarray,
    smoothed: Any,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    first: np.ndarray,
    active: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed and filtered maneuver-level probabilities ``(M, L, B, A, J)`` by forward–backward.

    ``smoothed``: the last M-step's ``(mean, cov, ...)``, or None before the
    first (then P is the prior covariance at every step).
    """
    M, L, B, n = X.shape
    steps = np.arange(B)
    at_first = steps == first[..., None]  # (M, L, B)
    prev = np.concatenate([prior_mean[:, :, None], X[:, :, :-1]], axis=2)
    prev = np.where(at_first[..., None], prior_mean[:, :, None], prev)
    if smoothed is None:
        P_prev = np.broadcast_to(prior_cov[:, :, None], (M, L, B, n, n))
    else:
        Ps = smoothed[1]
        P_prev = np.concatenate([prior_cov[:, :, None], Ps[:, :, :-1]], axis=2)
        P_prev = np.where(at_first[..., None, None], prior_cov[:, :, None], P_prev)
    F = model.F  # (B, n, n)
    r = X - np.einsum("bij,mlbj->mlbi", F, prev)
    S = F @ P_prev @ np.ascontiguousarray(np.swapaxes(F, -1, -2)) + model.Q  # a transposed view costs matmul ~2.5x
    axes = maneuver.axes  # (A, 2)
    levels = maneuver.levels  # (J,)
    ra = r[..., axes]  # (M, L, B, A, 2)
    Sa = S[..., axes[:, :, None], axes[:, None, :]]  # (M, L, B, A, 2, 2)
    ga = np.take_along_axis(model.inputs, np.broadcast_to(axes[None], (B, *axes.shape)), axis=2)  # (B, A, 2)
    res = _level_residuals(ra, ga, levels)  # (M, L, B, A, J, 2)
    Sinv = inv_spd(Sa)  # closed-form 2x2 inverses: a fraction of LAPACK's per-matrix cost
    loge = -0.5 * quadratic_form(res, Sinv[..., None, :, :])  # the log-det is common to all j
    e = np.exp(loge - _max_last(loge)[..., None])
    Pi = maneuver.transition
    alpha = np.empty((M, L, B, *maneuver.prior.shape[2:]))
    a = maneuver.prior
    for b in range(B):
        nxt = np.einsum("mlai,ij->mlaj", a, Pi) * e[:, :, b]
        nxt = nxt / _sum_last(nxt)[..., None]
        a = np.where(active[:, :, b, None, None], nxt, a)
        alpha[:, :, b] = a
    gamma = np.empty_like(alpha)
    beta = np.ones_like(maneuver.prior)
    gamma[:, :, B - 1] = alpha[:, :, B - 1]
    for b in range(B - 2, -1, -1):
        back = np.einsum("ij,mlaj->mlai", Pi, e[:, :, b + 1] * beta)
        back = back / _sum_last(back)[..., None]
        beta = np.where(active[:, :, b + 1, None, None], back, beta)
        g = alpha[:, :, b] * beta
        gamma[:, :, b] = g / _sum_last(g)[..., None]
    return gamma, alpha


def _level_residuals(ra: np.ndarray, ga: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """``(M, L, B, A, J, 2)`` r − g a_j per level, for ``ra (M, L, B, A, 2)``, ``ga (B, A, 2)``, ``levels (J,)``.

    Each of the two components is computed into a component-major array
    (a view with the components last is returned): a broadcast subtraction
    with the two components innermost cost ~1.5x more.  The same values.
    """
    out = np.empty((ra.shape[-1], *ra.shape[:-1], levels.size))
    for i in range(ra.shape[-1]):
        np.subtract(ra[..., i, None], ga[:, :, i, None] * levels, out=out[i])
    return np.moveaxis(out, 0, -1)


def _max_last(x: np.ndarray) -> np.ndarray:
    """The maximum over the last axis, one whole-array ``np.maximum`` per entry of it.

    The same values as ``x.max(axis=-1)`` (NaN propagates alike); a reduction
    over a short trailing axis (J levels) costs ~15x more on EPMHT's stacks.
    """
    out = x[..., 0]
    for j in range(1, x.shape[-1]):
        out = np.maximum(out, x[..., j])
    return out


def _sum_last(x: np.ndarray) -> np.ndarray:
    """The sum over the last axis, added left to right one whole-array ``+`` per entry of it.

    A reduction over the short trailing axis (J levels) costs ~5x more on
    EPMHT's stacks; each entry is summed in the same order whatever the
    batch, so the result is batch-invariant.
    """
    out = x[..., 0].copy()
    for j in range(1, x.shape[-1]):
        out += x[..., j]
    return out


@dataclass(frozen=True)
class EPMHTTracker(PMHTTracker):
    """PMHT with a Markov-chain maneuver input per axis (EPMHT).

    Parameters
    ----------
    levels
        Maneuver input levels a_1..a_J per axis, m/s² (keyword only,
        default ``(−20, 0, 20)``: ±a with a = 20 m/s², radar scale).
    stay
        Π's diagonal; the rest of each row is spread evenly (keyword only, default 0.9).
    mode_prior
        A new track's level probabilities ``(J,)`` (keyword only; default uniform).
    Others
        As :class:`pursuit.multitarget.PMHTTracker`.  The motion model must
        be a constant-velocity one (``position_indices``, ``velocity_indices``).
    """

    levels: tuple[float, ...] = field(default=(-20.0, 0.0, 20.0), kw_only=True)
    stay: float = field(default=0.9, kw_only=True)
    mode_prior: tuple[float, ...] | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        levels = as_float_array("levels", self.levels)
        if levels.ndim != 1 or levels.size == 0 or not np.isfinite(levels).all():
            raise ValueError(f"levels: expected a non-empty sequence of finite accelerations, got {self.levels!r}")
        object.__setattr__(self, "levels", tuple(float(v) for v in levels))
        in_range("stay", self.stay, 0.0, 1.0, low_open=True)
        if self.mode_prior is not None:
            p = as_float_array("mode_prior", self.mode_prior)
            if p.shape != levels.shape or (p < 0).any() or not np.isclose(p.sum(), 1.0):
                raise ValueError(f"mode_prior: expected {levels.size} probabilities summing to 1, got {self.mode_prior!r}")
        motion = self.filter.motion
        pos = tuple(getattr(motion, "position_indices", ()) or ())
        vel = tuple(getattr(motion, "velocity_indices", ()) or ())
        if not pos or len(pos) != len(vel) or getattr(motion, "dim", None) != 2 * len(pos):
            raise ValueError("filter: EPMHT needs a constant-velocity motion model (position_indices, velocity_indices)")

    def _axes(self) -> np.ndarray:
        motion = self.filter.motion
        return np.array([motion.position_indices, motion.velocity_indices]).T  # (A, 2)

    def _inputs(self) -> Any:
        axes = self._axes()
        n = int(self.filter.motion.dim)
        default_dt = float(self.filter.motion.dt)

        def inputs(dt: float | None) -> np.ndarray:
            T = default_dt if dt is None else dt
            U = np.zeros((axes.shape[0], n))
            U[np.arange(axes.shape[0]), axes[:, 0]] = T * T / 2.0
            U[np.arange(axes.shape[0]), axes[:, 1]] = T
            return U

        return inputs

    def _maneuver(self, runs: int, capacity: int) -> Maneuver:
        J = len(self.levels)
        Pi = np.full((J, J), (1.0 - self.stay) / max(J - 1, 1))
        np.fill_diagonal(Pi, self.stay if J > 1 else 1.0)
        p0 = np.full(J, 1.0 / J) if self.mode_prior is None else np.asarray(self.mode_prior, dtype=float)
        axes = self._axes()
        prior = np.broadcast_to(p0, (runs, capacity, axes.shape[0], J)).copy()
        return Maneuver(np.asarray(self.levels, dtype=float), Pi, prior, axes, mode_posteriors)
