"""Multiple-model PMHT: process-noise or turn modes as missing data in PMHT's EM (docs/spec/05-multi-target-pmht.md §3, option).

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

With one mode of scale 1 it is PMHT step for step.

**Motion modes** (``turn_rates``): mode j is a coordinated turn at the known
rate ω_j (ω = 0: constant velocity), ``x_t = F(ω_j) x_{t−1} + w_t``,
``w_t ~ N(0, s_j Q)``, F(ω) the turn of :class:`pursuit.models.ConstantTurn`
in the (x, y) plane of the track's constant-velocity state.  Σ_j γ_tj
log N(x_t; F_j x_{t−1}, s_j Q) is then no longer one Gaussian term, so the
M-step is the spec's option instead, an IMM smoother on the synthetic
measurements (:func:`pursuit.filters.imm_smoother.imm_smooth`: the forward
IMM filter and Kim's 1994 backward pass,
``μ^s_t(i, j) = μ_t(i) Π_ij μ^s_{t+1}(j) / c̄_{t+1}(j)``,
``x^s_ij = x̂_t^i + G_ij (x^s_{t+1}^j − F_j x̂_t^i)``,
``G_ij = P_t^i F_jᵀ (F_j P_t^i F_jᵀ + s_j Q)⁻¹``, collapsed per mode with
``μ_{j|i} = μ^s_t(i, j) / μ^s_t(i)`` and over the modes with μ^s_t).  Its
smoothed mixture mean is the track's new states, its mode probabilities the
γ (and its filtered ones the α carried to the next window).  The objective
keeps the same form, PMHT's association term plus
``log Σ_modes p(X | modes) P(modes)`` with the per-mode emissions
``N(x̂_t; F_j x̂_{t−1}, s_j Q)`` (``N(x̂; F_j m₀, F_j P₀ F_jᵀ + s_j Q)`` at a
track's first step), and EM stops on PMHT's rule; but the M-step only
approximately maximises it (the IMM's mixing and Kim's approximation), so
**the objective is no longer guaranteed to increase**.  With the single
rate 0 (and scale 1) the IMM smoother is the RTS smoother and the tracker
PMHT; with Π = I and a known prior mode it is that mode's smoother.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache, partial

import numpy as np

from .._linalg import quadratic_form
from .._validation import as_float_array, in_range
from ..filters.imm_smoother import imm_smooth
from ..models.maneuver import ConstantTurn
from .pmht import LinearModel, NoiseModes, PMHTTracker
from .tracking import _layout_motion

__all__ = ["MMPMHTTracker", "noise_mode_posteriors", "mode_process_noise", "motion_mode_posteriors", "mode_transitions", "imm_m_step"]


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
    quad = quadratic_form(r, model.Q_pinv)
    rank = np.rint(np.einsum("bij,bji->b", model.Q_pinv, model.Q))  # the dimension of Q's range
    loge = -0.5 * (quad[..., None] / s + model.Q_logpdet[:, None] + rank[:, None] * np.log(s))  # (M, L, B, J)
    fi, F, _, S = _first_step(model, s, prior_cov, first)
    rf = np.take_along_axis(X, fi[:, :, None, None], axis=2)[:, :, 0] - np.einsum("mlij,mlj->mli", F, prior_mean)
    sol = np.linalg.solve(S, np.broadcast_to(rf[:, :, None, :, None], (*S.shape[:-1], 1)))[..., 0]
    lf = -0.5 * (np.einsum("mli,mlji->mlj", rf, sol) + np.linalg.slogdet(2.0 * np.pi * S)[1])  # (M, L, J)
    loge = np.where((steps == first[..., None])[..., None], lf[:, :, None], loge)
    return _forward_backward(loge, modes.transition, modes.prior[:, :, 0], active)


def _forward_backward(loge: np.ndarray, Pi: np.ndarray, a: np.ndarray, active: np.ndarray):
    """The HMM pass over the modes of the emissions ``loge (M, L, B, J)``: γ, α ``(M, L, B, 1, J)`` and ``(M,)`` Σ log p."""
    M, L, B, J = loge.shape
    alpha = np.empty((M, L, B, J))
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
    beta = np.ones((M, L, J))
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


@lru_cache(maxsize=256)
def _turn_blocks(T: float, rates: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The constant-velocity ``(4, 4)`` block of step T and the turns' ``(J, 4, 4)`` (cached: EM asks every iteration)."""
    cv = ConstantTurn(omega=0.0, q=0.0, dt=T).transition_matrix()
    return cv, np.stack([ConstantTurn(omega=w, q=0.0, dt=T).transition_matrix() for w in rates])


def mode_transitions(model: LinearModel, rates: np.ndarray, scales: np.ndarray, plane: tuple[int, int, int, int]):
    """Each mode's F and Q into each window step, ``(B, J, n, n)`` twice: turns at ``rates`` in the plane ``(x, vx, y, vy)``.

    The step's time T is read from the constant-velocity F (``F[x, vx]``);
    the rest of the state (a z axis) keeps the model's F; Q_j = s_j Q.
    """
    B, n = model.F.shape[0], model.F.shape[-1]
    idx = np.ix_(plane, plane)
    F = np.broadcast_to(model.F[:, None], (B, len(rates), n, n)).copy()
    key = tuple(float(w) for w in rates)
    for b in range(B):
        T = float(model.F[b, plane[0], plane[1]])
        blocks = _turn_blocks(T, key) if T > 0 else None
        if blocks is None or np.abs(model.F[b][idx] - blocks[0]).max() > 1e-12:
            raise ValueError(
                "turn_rates: turn modes need a constant-velocity motion model whose (x, vx, y, vy) block is "
                f"[[1, T, 0, 0], [0, 1, 0, 0], [0, 0, 1, T], [0, 0, 0, 1]]; got {model.F[b][idx].tolist()}"
            )
        F[b][(slice(None), *idx)] = blocks[1]
    Q = scales[:, None, None] * model.Q[:, None]
    return F, Q


def motion_mode_posteriors(
    model: LinearModel,
    modes: NoiseModes,
    X: np.ndarray,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    first: np.ndarray,
    active: np.ndarray,
    *,
    rates: np.ndarray,
    plane: tuple[int, int, int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """As :func:`noise_mode_posteriors` for modes with their own F: the emissions ``N(x̂_t; F_j x̂_{t−1}, s_j Q)``.

    Only the process term ``(M,)`` is used (the objective): with turn modes
    γ and α come from the IMM smoother of the M-step.
    """
    M, L, B, n = X.shape
    s = modes.scales
    F, _ = mode_transitions(model, rates, s, plane)  # (B, J, n, n)
    steps = np.arange(B)
    prev = np.concatenate([prior_mean[:, :, None], X[:, :, :-1]], axis=2)
    r = X[:, :, :, None] - np.einsum("bjik,mlbk->mlbji", F, prev)  # (M, L, B, J, n)
    quad = quadratic_form(r, model.Q_pinv[:, None])
    rank = np.rint(np.einsum("bij,bji->b", model.Q_pinv, model.Q))
    loge = -0.5 * (quad / s + model.Q_logpdet[:, None] + rank[:, None] * np.log(s))  # (M, L, B, J)
    fi = np.clip(first, 0, B - 1)
    Ff = F[fi]  # (M, L, J, n, n)
    S = Ff @ prior_cov[:, :, None] @ np.swapaxes(Ff, -1, -2) + s[:, None, None] * model.Q[fi][:, :, None]
    xf = np.take_along_axis(X, fi[:, :, None, None], axis=2)[:, :, 0]
    rf = xf[:, :, None] - np.einsum("mljik,mlk->mlji", Ff, prior_mean)  # (M, L, J, n)
    sol = np.linalg.solve(S, rf[..., None])[..., 0]
    lf = -0.5 * (np.einsum("mlji,mlji->mlj", rf, sol) + np.linalg.slogdet(2.0 * np.pi * S)[1])
    loge = np.where((steps == first[..., None])[..., None], lf[:, :, None], loge)
    return _forward_backward(loge, modes.transition, modes.prior[:, :, 0], active)


def imm_m_step(
    model: LinearModel,
    modes: NoiseModes,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    active: np.ndarray,
    measured: np.ndarray,
    zs: np.ndarray,
    W: np.ndarray,
    H: np.ndarray,
    *,
    rates: np.ndarray,
    plane: tuple[int, int, int, int],
) -> tuple[np.ndarray, ...]:
    """The approximate M-step with turn modes: the IMM smoother (Kim) of every slot's synthetic measurements ``zs`` (R / W).

    Returns smoothed and filtered means and covariances (the moment-matched
    mixtures) and the smoothed and filtered mode probabilities ``(M, L, B, 1, J)``.
    """
    F, Q = mode_transitions(model, rates, modes.scales, plane)
    out = imm_smooth(
        prior_mean, prior_cov, modes.prior[:, :, 0], modes.transition, F, Q, zs, H, model.R,
        weight=W, measured=measured, active=active,
    )  # fmt: skip
    return out.mean, out.cov, out.filt_mean, out.filt_cov, out.mode_probs[:, :, :, None], out.filt_mode_probs[:, :, :, None]


@dataclass(frozen=True)
class MMPMHTTracker(PMHTTracker):
    """PMHT whose tracks switch between motion modes (a multiple-model PMHT).

    Parameters
    ----------
    noise_scales
        The modes' process noise as multiples of the motion model's Q
        (keyword only).  Default: ``(1, 100)`` (the model's Q and one a
        hundred times larger, for maneuvers) [DEFAULT] without ``turn_rates``;
        1 for every mode with them.
    turn_rates
        The modes' turn rates ω_j (rad/s; 0: constant velocity; ω > 0 turns
        counter-clockwise), one per mode, paired with ``noise_scales``
        (keyword only, default None: noise modes only, exact EM).  With them
        the M-step is the IMM smoother (an approximate EM); the motion model
        must be constant velocity with at least two axes.
    stay
        Π's diagonal; the rest of each row is spread evenly (keyword only, default 0.95).
    transition
        The full Markov matrix Π ``(J, J)`` instead of ``stay`` (keyword only; rows sum to 1).
    mode_prior
        A new track's mode probabilities ``(J,)`` (keyword only; default uniform).
    Others
        As :class:`pursuit.multitarget.PMHTTracker`.
    """

    noise_scales: tuple[float, ...] | None = field(default=None, kw_only=True)
    turn_rates: tuple[float, ...] | None = field(default=None, kw_only=True)
    stay: float = field(default=0.95, kw_only=True)
    transition: tuple[tuple[float, ...], ...] | None = field(default=None, kw_only=True)
    mode_prior: tuple[float, ...] | None = field(default=None, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        rates = None
        if self.turn_rates is not None:
            rates = as_float_array("turn_rates", self.turn_rates)
            if rates.ndim != 1 or rates.size == 0 or not np.isfinite(rates).all():
                raise ValueError(f"turn_rates: expected a non-empty sequence of finite turn rates (rad/s), got {self.turn_rates!r}")
            object.__setattr__(self, "turn_rates", tuple(float(v) for v in rates))
            motion = _layout_motion(self.filter)
            pos, vel = getattr(motion, "position_indices", ()), getattr(motion, "velocity_indices", ())
            if len(pos) < 2 or len(vel) < 2 or getattr(motion, "dim", None) != len(pos) + len(vel):
                raise ValueError(
                    f"turn_rates: turn modes need a constant-velocity motion model with x and y axes, got {type(motion).__name__}"
                )
        if self.noise_scales is None:
            default = (1.0, 100.0) if rates is None else (1.0,) * rates.size
            object.__setattr__(self, "noise_scales", default)
        scales = as_float_array("noise_scales", self.noise_scales)
        if scales.ndim != 1 or scales.size == 0 or not (np.isfinite(scales) & (scales > 0)).all():
            raise ValueError(f"noise_scales: expected a non-empty sequence of positive numbers, got {self.noise_scales!r}")
        if rates is not None and scales.size != rates.size:
            raise ValueError(f"noise_scales: expected one scale per turn rate ({rates.size}), got {self.noise_scales!r}")
        object.__setattr__(self, "noise_scales", tuple(float(v) for v in scales))
        in_range("stay", self.stay, 0.0, 1.0, low_open=True)
        J = scales.size
        if self.transition is not None:
            Pi = as_float_array("transition", self.transition)
            if Pi.shape != (J, J) or not np.isfinite(Pi).all() or (Pi < 0).any() or not np.allclose(Pi.sum(axis=1), 1.0):
                raise ValueError(f"transition: expected a ({J}, {J}) Markov matrix (non-negative rows summing to 1), got {self.transition!r}")
            object.__setattr__(self, "transition", tuple(tuple(float(v) for v in row) for row in Pi))
        if self.mode_prior is not None:
            p = as_float_array("mode_prior", self.mode_prior)
            if p.shape != scales.shape or (p < 0).any() or not np.isclose(p.sum(), 1.0):
                raise ValueError(f"mode_prior: expected {scales.size} probabilities summing to 1, got {self.mode_prior!r}")

    def _plane(self) -> tuple[int, int, int, int]:
        """The (x, vx, y, vy) indices of the track state."""
        motion = _layout_motion(self.filter)
        p, v = motion.position_indices, motion.velocity_indices
        return (int(p[0]), int(v[0]), int(p[1]), int(v[1]))

    def _maneuver(self, runs: int, capacity: int) -> NoiseModes:
        J = len(self.noise_scales)
        if self.transition is not None:
            Pi = np.asarray(self.transition, dtype=float)
        else:
            Pi = np.full((J, J), (1.0 - self.stay) / max(J - 1, 1))
            np.fill_diagonal(Pi, self.stay if J > 1 else 1.0)
        p0 = np.full(J, 1.0 / J) if self.mode_prior is None else np.asarray(self.mode_prior, dtype=float)
        prior = np.broadcast_to(p0, (runs, capacity, 1, J)).copy()
        scales = np.asarray(self.noise_scales, dtype=float)
        if self.turn_rates is None:
            return NoiseModes(scales, Pi, prior, noise_mode_posteriors, mode_process_noise)
        kw = {"rates": np.asarray(self.turn_rates, dtype=float), "plane": self._plane()}
        return NoiseModes(scales, Pi, prior, partial(motion_mode_posteriors, **kw), mode_process_noise, partial(imm_m_step, **kw))
