"""Multiple-model PMHT: process-noise modes as missing data in PMHT's EM (docs/spec/05-multi-target-pmht.md §3, option).

Each track's motion switches between J modes that share F and differ in
the scale of the process noise, ``x_t = F x_{t−1} + w_t``,
``w_t ~ N(0, s_j Q)`` in mode j, the mode a Markov chain (Π).  EM treats
the modes as missing data beside the assignments (the multiple-model PMHT
of Ruan & Willett, restricted to modes that differ in Q only):

* **E-step**: PMHT's association weights, and per track a forward–backward
  pass over the modes with the exact emissions ``N(x̂_t; F x̂_{t−1}, s_j Q)``
  of the current state estimates (at a track's first step
  ``N(x̂; F m₀, F P₀ F' + s_j Q)``), giving ``γ_tj = P(mode_t = j | X̂)``;
* **M-step**: Σ_j γ_tj log N(x_t; F x_{t−1}, s_j Q) is one Gaussian term with
  the precision ``h_t Q⁺``, ``h_t = Σ_j γ_tj / s_j``, so the RTS smoother of
  PMHT with ``Q / h_t`` at each step (at the first step the prior
  covariance ``(Σ_j γ_j (F P₀ F' + s_j Q)⁻¹)⁻¹``) maximises it exactly;
* **objective**: PMHT's association term plus ``log Σ_modes p(X | modes) P(modes)``
  (the forward pass's normaliser).  This is exact EM: the objective never
  decreases (a property test checks it with a linear sensor).

With one mode of scale 1 it is PMHT step for step.  This is not the IMM
smoother in the M-step that the spec names as the option (modes with
different F, a coordinated turn, do not give one Gaussian term per step);
it is the part of the multiple-model PMHT that stays exact EM.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import as_float_array, in_range
from .pmht import LinearModel, NoiseModes, PMHTTracker

__all__ = ["MMPMHTTracker", "noise_mode_posteriors", "mode_process_noise"]


def _first_step(model: LinearModel, scales: np.ndarray, prior_cov: np.ndarray, first: np.ndarray):
    """At each slot's first step: F, F P₀ F' and the per-mode prior-predictive covariances ``(M, L, J, n, n)``."""
    B = model.F.shape[0]
    fi = np.clip(first, 0, B - 1)
    F = model.F[fi]  # (M, L, n, n)
    A = F @ prior_cov @ np.swapaxes(F, -1, -2)
    S = A[:, :, None] + scales[:, None, None] * model.Q[fi][:, :, None]
    return fi, F, A, S


def noise_mode_posteriors(
    model: LinearModel,
    modes: NoiseModes,
    X: np.ndarray,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    first: np.ndarray,
    active: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed and filtered mode probabilities ``(M, L, B, 1, J)`` and the process term ``(M,)`` of the objective.

    The process term is ``Σ_tracks log Σ_modes p(X | modes) P(modes)``; Q is
    singular for a discrete white-noise acceleration, so the emissions after
    the first step are densities on Q's range (pseudo-inverse and
    pseudo-determinant, as PMHT's objective).
    """
    M, L, B, n = X.shape
    s = modes.scales
    steps = np.arange(B)
    prev = np.concatenate([prior_mean[:, :, None], X[:, :, :-1]], axis=2)
    r = X - np.einsum("bij,mlbj->mlbi", model.F, prev)
    quad = np.einsum("mlbi,bij,mlbj->mlb", r, model.Q_pinv, r)
    rank = np.rint(np.einsum("bij,bji->b", model.Q_pinv, model.Q))  # the dimension of Q's range
    loge = -0.5 * (quad[..., None] / s + model.Q_logpdet[:, None] + rank[:, None] * np.log(s))  # (M, L, B, J)
    fi, F, _, S = _first_step(model, s, prior_cov, first)
    rf = np.take_along_axis(X, fi[:, :, None, None], axis=2)[:, :, 0] - np.einsum("mlij,mlj->mli", F, prior_mean)
    sol = np.linalg.solve(S, np.broadcast_to(rf[:, :, None, :, None], (*S.shape[:-1], 1)))[..., 0]
    lf = -0.5 * (np.einsum("mli,mlji->mlj", rf, sol) + np.linalg.slogdet(2.0 * np.pi * S)[1])  # (M, L, J)
    loge = np.where((steps == first[..., None])[..., None], lf[:, :, None], loge)
    Pi = modes.transition
    a = modes.prior[:, :, 0]  # (M, L, J)
    alpha = np.empty((M, L, B, len(s)))
    loglik = np.zeros((M, L))
    for b in range(B):
        act = active[:, :, b]
        le = loge[:, :, b]
        top = le.max(axis=-1, keepdims=True)
        c = (a @ Pi) * np.exp(le - top)
        tot = c.sum(axis=-1)
        loglik += np.where(act, np.log(tot) + top[..., 0], 0.0)
        a = np.where(act[..., None], c / tot[..., None], a)
        alpha[:, :, b] = a
    gamma = np.empty_like(alpha)
    gamma[:, :, B - 1] = alpha[:, :, B - 1]
    beta = np.ones((M, L, len(s)))
    for b in range(B - 2, -1, -1):
        le = loge[:, :, b + 1]
        back = (np.exp(le - le.max(axis=-1, keepdims=True)) * beta) @ Pi.T
        back = back / back.sum(axis=-1, keepdims=True)
        beta = np.where(active[:, :, b + 1, None], back, beta)
        g = alpha[:, :, b] * beta
        gamma[:, :, b] = g / g.sum(axis=-1, keepdims=True)
    return gamma[:, :, :, None], alpha[:, :, :, None], loglik.sum(axis=1)


def mode_process_noise(
    model: LinearModel, modes: NoiseModes, gamma: np.ndarray, prior_cov: np.ndarray, first: np.ndarray, active: np.ndarray
) -> np.ndarray:
    """The M-step's process noise per slot and step ``(M, L, B, n, n)``: Q / Σ_j (γ_j / s_j), the prior term at the first step."""
    g = gamma[:, :, :, 0]  # (M, L, B, J)
    s = modes.scales
    h = (g / s).sum(axis=-1)  # the mode-averaged precision scale
    Qs = model.Q[None, None] / h[..., None, None]
    B = g.shape[2]
    fi, _, A, S = _first_step(model, s, prior_cov, first)
    gf = np.take_along_axis(g, fi[:, :, None, None], axis=2)[:, :, 0]  # (M, L, J)
    Sbar = np.linalg.inv(np.einsum("mlj,mljab->mlab", gf, np.linalg.inv(S)))
    Qf = Sbar - A  # PSD: (harmonic mean of A + s_j Q) ≥ A
    Qf = 0.5 * (Qf + np.swapaxes(Qf, -1, -2))
    at_first = (np.arange(B) == first[..., None])[..., None, None]
    return np.where(at_first, Qf[:, :, None], Qs)


@dataclass(frozen=True)
class MMPMHTTracker(PMHTTracker):
    """PMHT whose tracks switch between process-noise levels (a multiple-model PMHT).

    Parameters
    ----------
    noise_scales
        The modes' process noise as multiples of the motion model's Q
        (keyword only, default ``(1, 100)``: the model's Q and one a hundred
        times larger, for maneuvers) [DEFAULT].
    stay
        Π's diagonal; the rest of each row is spread evenly (keyword only, default 0.95).
    mode_prior
        A new track's mode probabilities ``(J,)`` (keyword only; default uniform).
    Others
        As :class:`pursuit.multitarget.PMHTTracker`.
    """

    noise_scales: tuple[float, ...] = field(default=(1.0, 100.0), kw_only=True)
    stay: float = field(default=0.95, kw_only=True)
    mode_prior: tuple[float, ...] | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        scales = as_float_array("noise_scales", self.noise_scales)
        if scales.ndim != 1 or scales.size == 0 or not (np.isfinite(scales) & (scales > 0)).all():
            raise ValueError(f"noise_scales: expected a non-empty sequence of positive numbers, got {self.noise_scales!r}")
        object.__setattr__(self, "noise_scales", tuple(float(v) for v in scales))
        in_range("stay", self.stay, 0.0, 1.0, low_open=True)
        if self.mode_prior is not None:
            p = as_float_array("mode_prior", self.mode_prior)
            if p.shape != scales.shape or (p < 0).any() or not np.isclose(p.sum(), 1.0):
                raise ValueError(f"mode_prior: expected {scales.size} probabilities summing to 1, got {self.mode_prior!r}")

    def _maneuver(self, runs: int, capacity: int) -> NoiseModes:
        J = len(self.noise_scales)
        Pi = np.full((J, J), (1.0 - self.stay) / max(J - 1, 1))
        np.fill_diagonal(Pi, self.stay if J > 1 else 1.0)
        p0 = np.full(J, 1.0 / J) if self.mode_prior is None else np.asarray(self.mode_prior, dtype=float)
        prior = np.broadcast_to(p0, (runs, capacity, 1, J)).copy()
        return NoiseModes(np.asarray(self.noise_scales, dtype=float), Pi, prior, noise_mode_posteriors, mode_process_noise)
