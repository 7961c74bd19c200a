"""Probabilistic multi-hypothesis tracker (PMHT): EM over a sliding batch of scans.

PMHT (Streit & Luginbuhl 1995; docs/spec/05-multi-target-pmht.md §2) lets
every measurement's origin be an independent random variable (clutter or
one of the T tracks, with priors π) and runs EM over a window of B scans,
the assignments being the missing data:

* **E-step**: the posterior association weights
  ``w_trm = π_tm N(z_tr; H x̂_tm, R) / [π_t0 / V + Σ_m' π_tm' N(z_tr; H x̂_tm', R)]``
  (and ``w_tr0`` for clutter);
* **M-step**: per track and scan the synthetic measurement
  ``z̃_tm = Σ_r w_trm z_tr / W_tm`` with ``R̃_tm = R / W_tm``
  (``W_tm = Σ_r w_trm``; a miss where ``W_tm = 0``), then each track's state
  sequence is the Rauch-Tung-Striebel smoother of its synthetic
  measurements, started from the track's prior at the window start;
* **convergence**: the incomplete-data log-likelihood
  ``Σ_t Σ_r log(π_t0/V + Σ_m π_tm N(z_tr; H x_tm, R)) + Σ_m log p(x_m)``
  never decreases (a property test checks it); a run stops when its relative
  change is below ``tol`` (1e-6) or after ``max_iter`` (20) M-steps.

The window slides one scan at a time; the estimate reported for scan k is
the filtered one at the end of its window (the forward pass of the last
M-step), and when a full window advances, the filtered estimate at its first
scan becomes the prior of the next window.

Models: a linear motion model (``transition_matrix``, ``cov``) and a linear
measurement model (``matrix``, ``cov``), i.e. a :class:`pursuit.KalmanFilter`
per track.  With a singular Q (discrete white-noise acceleration) the
process term of the objective is the density on Q's range (pseudo-inverse
and pseudo-determinant), on which the smoother's steps lie.

Vectorisation: one EM for all runs and track slots at once, arrays
``(M, L, B, ...)``; Python loops run over scans, EM iterations and the B
steps of the smoother only.  A run that has converged is frozen while the
others iterate, so a run's result does not depend on the other runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from .._linalg import quadratic_form
from .._validation import in_range, positive, positive_int
from ..filters.jacobians import measurement_jacobian
from ..gaussian import Gaussian
from ..rng import RNGLike
from .management import initiate, new_table, update_counts
from .tracking import MultiTrackResult, TrackerBase, _as_initial, _layout_motion, checked_scans

__all__ = ["PMHTTracker", "PMHTResult", "WindowFit", "LinearModel", "Maneuver", "NoiseModes", "em_window", "linear_model"]



# --------------------------------------------------------------------------
# the linear-Gaussian model over a window
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class LinearModel:
    """F, Q and the measurement model of each step of a window.

    Attributes
    ----------
    F, Q
        ``(B, n, n)`` transition matrix and process noise into each window step.
    Q_pinv, Q_logpdet
        ``(B, n, n)`` Q's pseudo-inverse and ``(B,)`` log pseudo-determinant of 2πQ.
    H, R
        ``(m, n)`` (None for a nonlinear sensor) and ``(m, m)``.
    inputs
        ``(B, A, n)``: the state change per unit of maneuver input on axis a
        (EPMHT; ``A = 0`` for PMHT).
    measurement
        The measurement model, used when ``H`` is None (``h``, ``residual``,
        its Jacobian or central differences): the M-step then linearises h
        at the current states (an EKF smoother on the synthetic measurements).
    """

    F: np.ndarray
    Q: np.ndarray
    Q_pinv: np.ndarray
    Q_logpdet: np.ndarray
    H: np.ndarray
    R: np.ndarray
    inputs: np.ndarray
    measurement: Any = None

    def window(self, start: int, stop: int) -> "LinearModel":
        """The steps ``start:stop``."""
        return replace(
            self,
            F=self.F[start:stop],
            Q=self.Q[start:stop],
            Q_pinv=self.Q_pinv[start:stop],
            Q_logpdet=self.Q_logpdet[start:stop],
            inputs=self.inputs[start:stop],
        )


def linear_model(motion: Any, measurement: Any, dts: list[float | None], inputs: Any = None) -> LinearModel:
    """The :class:`LinearModel` of the steps with time steps ``dts`` (None: the model's own dt).

    ``inputs(dt) -> (A, n)`` gives the maneuver input vectors per axis (EPMHT).
    """
    F = np.stack([np.asarray(_call(motion.transition_matrix, dt), dtype=float) for dt in dts])
    Q = np.stack([np.asarray(_call(motion.cov, dt), dtype=float) for dt in dts])
    vals, vecs = np.linalg.eigh(Q)
    keep = vals > vals.max(axis=-1, keepdims=True) * 1e-12
    inv = np.where(keep, 1.0 / np.where(keep, vals, 1.0), 0.0)
    Q_pinv = np.einsum("kij,kj,klj->kil", vecs, inv, vecs)
    Q_logpdet = np.sum(np.where(keep, np.log(2.0 * np.pi * np.where(keep, vals, 1.0)), 0.0), axis=-1)
    linear = callable(getattr(measurement, "matrix", None))
    H = np.asarray(measurement.matrix(1), dtype=float) if linear else None
    R = np.asarray(measurement.cov(1), dtype=float)
    n = F.shape[-1]
    U = np.stack([np.asarray(inputs(dt), dtype=float) for dt in dts]) if inputs is not None else np.zeros((len(dts), 0, n))
    return LinearModel(F, Q, Q_pinv, Q_logpdet, H, R, U, measurement)


def _call(fn: Any, dt: float | None) -> Any:
    return fn(None, dt=dt) if dt is not None else fn(None)


# --------------------------------------------------------------------------
# EM over one window
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class WindowFit:
    """The EM result of one window, for all runs and track slots.

    Attributes
    ----------
    mean, cov
        ``(M, L, B, n)``, ``(M, L, B, n, n)`` smoothed states (the MAP track sequence).
    filt_mean, filt_cov
        The forward (filtered) pass of the last M-step.
    weights, clutter
        ``(M, L, B, D)`` w_trm and ``(M, B, D)`` w_tr0 at the final states (0 at padding).
    W
        ``(M, L, B)`` Σ_r w_trm.
    iterations, objective
        ``(M,)`` M-steps used and the final incomplete-data log-likelihood.
    history
        ``(max_iter + 1, M)`` objective after each M-step (index 0: at the
        start), NaN after a run stopped.
    mode_probs, mode_filtered
        EPMHT only: ``(M, L, B, A, J)`` smoothed and filtered maneuver-level probabilities
        (the multiple-model PMHT: its noise modes', ``A = 1``).
    """

    mean: np.ndarray
    cov: np.ndarray
    filt_mean: np.ndarray
    filt_cov: np.ndarray
    weights: np.ndarray
    clutter: np.ndarray
    W: np.ndarray
    iterations: np.ndarray
    objective: np.ndarray
    history: np.ndarray
    mode_probs: np.ndarray | None = None
    mode_filtered: np.ndarray | None = None


@dataclass(frozen=True)
class Maneuver:
    """EPMHT's maneuver input chain (docs/spec/05-multi-target-pmht.md §3).

    Levels ``(J,)``, Π ``(J, J)``, the level probabilities ``(M, L, A, J)`` at
    each slot's prior scan, per axis the (position, velocity) state indices
    ``(A, 2)``, and ``posteriors``, the E-step's forward–backward pass
    (:func:`pursuit.multitarget.epmht.mode_posteriors`: EPMHT hands it in,
    so this module does not import the one that builds on it).
    """

    levels: np.ndarray
    transition: np.ndarray
    prior: np.ndarray
    axes: np.ndarray
    posteriors: Callable[..., tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class NoiseModes:
    """The multiple-model PMHT's process-noise modes (:mod:`pursuit.multitarget.mmpmht`).

    Mode j has the process noise ``scales[j] Q``; Π ``(J, J)``; the mode
    probabilities ``(M, L, 1, J)`` at each slot's prior scan (one "axis", so
    the tracker carries them as EPMHT's); ``posteriors`` (the E-step's
    forward–backward pass over the modes, which also gives the process term
    of the objective) and ``process_noise`` (the M-step's per-slot Q) come
    from the module that builds on this one.  ``smoother``, when given,
    replaces the M-step's smoother: ``smoother(model, modes, prior_mean,
    prior_cov, active, measured, zs, W, H) -> (xs, Ps, xf, Pf, gamma, alpha)``
    (modes with different F: the multiple-model PMHT's IMM smoother, whose
    mode probabilities then replace the posteriors' γ and α).
    """

    scales: np.ndarray
    transition: np.ndarray
    prior: np.ndarray
    posteriors: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]]
    process_noise: Callable[..., np.ndarray]
    smoother: Callable[..., tuple[np.ndarray, ...]] | None = None


def em_window(
    model: LinearModel,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    first: np.ndarray,
    z: np.ndarray,
    start: np.ndarray,
    *,
    p_detect: float,
    clutter_density: float,
    volume: float | None = None,
    estimate_priors: bool = False,
    max_iter: int = 20,
    tol: float = 1e-6,
    maneuver: Maneuver | NoiseModes | None = None,
) -> WindowFit:
    """Run PMHT's EM on one window of B scans for all runs and track slots.

    Parameters
    ----------
    model
        The window's :class:`LinearModel` (B steps).
    prior_mean, prior_cov
        ``(M, L, n)``, ``(M, L, n, n)`` each track's prior before its first window step.
    first
        ``(M, L)`` the window step at which each track starts (0..B−1), B
        or more for a free slot (never active).
    z
        ``(B, M, D, m)`` detections, NaN rows = padding.
    start
        ``(M, L, B, n)`` initial track states (a warm start).
    p_detect, clutter_density, volume
        P_D, λ (false alarms per unit volume per scan) and the surveillance
        volume V.  Fixed priors π_t0 = λV/(λV + T_t P_D), π_tm = P_D/(λV + T_t P_D)
        (T_t: the tracks active at scan t).  Without V the E-step is the same
        (it needs only the ratio λ : P_D) and the objective leaves out the
        constant −Σ_t n_t log(λV + T_t P_D).
    estimate_priors
        Re-estimate π_tm = Σ_r w_trm / n_t and π_t0 = Σ_r w_tr0 / n_t at each M-step (needs ``volume``).
    max_iter, tol
        At most ``max_iter`` M-steps; a run stops when
        ``|L_i − L_{i−1}| ≤ tol |L_{i−1}|``.
    maneuver
        EPMHT: the maneuver chain (see :mod:`pursuit.multitarget.epmht`);
        or the multiple-model PMHT's noise modes (:class:`NoiseModes`): the
        modes are missing data too, the objective's process term is
        ``log Σ_modes p(X | modes) P(modes)`` and the M-step smooths with
        each slot's and step's mode-averaged precision (or, with its
        ``smoother``, the modes' own smoother: an approximate M-step).
    """
    B, M, D, m = z.shape
    L, n = prior_mean.shape[1], prior_mean.shape[-1]
    steps = np.arange(B)
    active = steps >= first[..., None]  # (M, L, B)
    detected = ~np.isnan(z).any(axis=-1)  # (B, M, D)
    zt = np.where(detected[..., None], z, 0.0).transpose(1, 0, 2, 3)  # (M, B, D, m)
    det = detected.transpose(1, 0, 2)  # (M, B, D)
    n_det = det.sum(axis=2)  # (M, B)
    Rinv = np.linalg.inv(model.R)
    R_logdet = float(np.linalg.slogdet(2.0 * np.pi * model.R)[1])
    T = active.sum(axis=1)  # (M, B)
    if volume is not None:
        norm = np.log(clutter_density * volume + T * p_detect)  # (M, B)
        log_c = np.log(clutter_density) - norm
        log_pi = np.broadcast_to((np.log(p_detect) - norm)[:, None, :], (M, L, B))
    else:
        log_c = np.full((M, B), np.log(clutter_density))
        log_pi = np.full((M, L, B), np.log(p_detect))
    log_pi = np.where(active, log_pi, -np.inf)
    log_c = np.array(log_c)

    def estep(r: np.ndarray, X: np.ndarray, log_c: np.ndarray, log_pi: np.ndarray):
        """Weights and the association term of the runs ``r`` (X, log_c, log_pi: those runs' rows)."""
        every_run = r.size == M  # the first E-step and any iteration before a run converged: no copies
        zr, dr, ar = (zt, det, active) if every_run else (zt[r], det[r], active[r])
        res = _residuals(model, zr, X)  # (M, L, B, D, m)
        logN = -0.5 * (quadratic_form(res, Rinv) + R_logdet)
        lt = np.where(dr[:, None] & ar[..., None], log_pi[..., None] + logN, -np.inf)
        top = np.maximum(log_c[..., None], lt.max(axis=1))  # (M, B, D)
        top = np.where(np.isfinite(top), top, 0.0)
        total = np.exp(log_c[..., None] - top) + np.exp(lt - top[:, None]).sum(axis=1)
        denom = top + np.log(total)
        w = np.where(dr[:, None], np.exp(lt - denom[:, None]), 0.0)
        w0 = np.where(dr, np.exp(log_c[..., None] - denom), 0.0)
        return w, w0, np.where(dr, denom, 0.0).sum(axis=(1, 2))

    every = np.arange(M)
    X = np.array(start, dtype=float)
    modes = maneuver if isinstance(maneuver, NoiseModes) else None
    maneuvers = modes is None and maneuver is not None and maneuver.levels.size > 0 and model.inputs.shape[1] > 0
    ubar = np.zeros((M, L, B, model.inputs.shape[1]))
    w, w0, assoc = estep(every, X, log_c, log_pi)
    gamma = alpha = None
    if modes is None:
        objective = assoc + _process_loglik(model, X, ubar, prior_mean, prior_cov, first, active)
    else:  # the mode posteriors at the current states: the E-step for the modes, and the process term
        gamma, alpha, proc = modes.posteriors(model, modes, X, prior_mean, prior_cov, first, active)
        objective = assoc + proc
    smoothed: tuple[np.ndarray, ...] | None = None
    history = np.full((max_iter + 1, M), np.nan)
    history[0] = objective
    iterations = np.zeros(M, dtype=np.int64)
    done = np.zeros(M, dtype=bool)
    # Each iteration works on the runs still iterating only (``r``); the others keep their arrays as they are.
    for it in range(1, max_iter + 1):
        r = np.nonzero(~done)[0]
        pm, pc, fr, ar = prior_mean[r], prior_cov[r], first[r], active[r]
        if maneuvers:
            Xr = X[r]
            prev = None if smoothed is None else tuple(a[r] for a in smoothed)
            g, a = maneuver.posteriors(model, replace(maneuver, prior=maneuver.prior[r]), Xr, prev, pm, pc, fr, ar)
            if gamma is None:
                gamma, alpha = g, a
            else:
                gamma[r], alpha[r] = g, a
            ubar[r] = np.einsum("mlbaj,j->mlba", g, maneuver.levels)
        wr, w0r = w[r], w0[r]
        if estimate_priors:
            nd = n_det[r]
            share = np.maximum(nd, 1)
            keep = nd == 0  # a scan without detections says nothing about π
            with np.errstate(divide="ignore"):
                log_c[r] = np.where(keep, log_c[r], np.log(w0r.sum(axis=2) / share) - np.log(volume))
                pi_t = wr.sum(axis=3) / share[:, None]  # (M', L, B)
                log_pi[r] = np.where(keep[:, None], log_pi[r], np.where(ar, np.log(pi_t), -np.inf))
        W = wr.sum(axis=3)  # (M', L, B)
        if model.H is not None:
            zs = _weighted_sum(wr, zt[r]) / np.where(W > 0, W, 1.0)[..., None]
            H = model.H
        else:  # linearised at the current states: z̃ = H x̄ + Σ_r w (z_r ⊖ h(x̄)) / W
            Xr = X[r]
            H = np.asarray(measurement_jacobian(model.measurement, Xr, 1), dtype=float)
            H = np.broadcast_to(H, (*Xr.shape[:-1], *H.shape[-2:]))  # a shared Jacobian, per slot and step
            nu = np.einsum("mlbd,mlbdi->mlbi", wr, _residuals(model, zt[r], Xr)) / np.where(W > 0, W, 1.0)[..., None]
            zs = np.einsum("mlbij,mlbj->mlbi", H, Xr) + nu
        if modes is not None and modes.smoother is not None:  # an approximate M-step (the IMM smoother)
            *new, g_m, a_m = modes.smoother(model, replace(modes, prior=modes.prior[r]), pm, pc, ar, ar & (W > 0), zs, W, H)
            new = tuple(new)
        else:
            Qs = None if modes is None else modes.process_noise(model, modes, gamma[r], pc, fr, ar)
            new = _smooth(model, pm, pc, ar, ar & (W > 0), zs, W, ubar[r], H, Qs)
        if smoothed is None:
            smoothed = new
        else:
            for full, part in zip(smoothed, new):
                full[r] = part
        X = smoothed[0]
        w_new, w0_new, assoc = estep(r, X[r], log_c[r], log_pi[r])
        w[r], w0[r] = w_new, w0_new
        if modes is None:
            value = assoc + _process_loglik(model, X[r], ubar[r], pm, pc, fr, ar)
        else:
            g, a, proc = modes.posteriors(model, replace(modes, prior=modes.prior[r]), X[r], pm, pc, fr, ar)
            gamma[r], alpha[r] = (g, a) if modes.smoother is None else (g_m, a_m)
            value = assoc + proc
        iterations[r] = it
        history[it, r] = value
        converged = np.abs(value - objective[r]) <= tol * np.abs(objective[r])
        objective[r] = value
        done[r] = converged
        if done.all():
            break
    xs, Ps, xf, Pf = smoothed
    return WindowFit(xs, Ps, xf, Pf, w, w0, w.sum(axis=3), iterations, objective, history, gamma, alpha)


def _smooth(
    model: LinearModel,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    active: np.ndarray,
    measured: np.ndarray,
    zs: np.ndarray,
    W: np.ndarray,
    ubar: np.ndarray,
    H: np.ndarray,
    Qs: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """KF on the synthetic measurements (R / W) then RTS, for all slots; before a track's first step its state is held.

    ``active (M, L, B)``: the track exists at the step; ``measured``: active and W > 0;
    ``H``: ``(m, n)``, or ``(M, L, B, m, n)`` per slot and step (a linearised sensor);
    ``Qs``: ``(M, L, B, n, n)`` process noise per slot and step instead of the model's (multiple-model PMHT).
    """
    M, L, B, _ = zs.shape
    n = prior_mean.shape[-1]
    R = model.R
    x, P = prior_mean, prior_cov
    xf = np.empty((M, L, B, n))
    Pf = np.empty((M, L, B, n, n))
    xp = np.empty((M, L, B, n))
    Pp = np.empty((M, L, B, n, n))
    C = np.empty((M, L, B, n, n))
    U = _input_term(model.inputs, ubar)
    # contiguous transposes: a matmul with a transposed view as its right operand costs ~2.5x more (same bits)
    Ft = np.ascontiguousarray(np.swapaxes(model.F, -1, -2))
    Ht = np.ascontiguousarray(np.swapaxes(H, -1, -2))
    for b in range(B):
        F = model.F[b]
        Q = model.Q[b] if Qs is None else Qs[:, :, b]
        step = active[..., b]  # before its first step a track holds its prior (the smoother gain is then I-like)
        x_pred = np.einsum("ij,...j->...i", F, x) + (U if np.isscalar(U) else U[:, :, b])
        PFt = P @ Ft[b]
        P_pred = F @ PFt + Q
        cross = PFt
        if not step.all():  # the selects are the identity on a step where every slot is active
            x_pred = np.where(step[..., None], x_pred, x)
            P_pred = np.where(step[..., None, None], P_pred, P)
            cross = np.where(step[..., None, None], PFt, P)
        xp[:, :, b], Pp[:, :, b], C[:, :, b] = x_pred, P_pred, cross
        Hb, Htb = (H, Ht) if H.ndim == 2 else (H[:, :, b], Ht[:, :, b])
        x, P = _kalman_update(x_pred, P_pred, zs[:, :, b], W[..., b], measured[..., b], Hb, Htb, R)
        xf[:, :, b], Pf[:, :, b] = x, P
    return (*_rts(xf, Pf, xp, Pp, C), xf, Pf)


def _kalman_update(
    x_pred: np.ndarray,
    P_pred: np.ndarray,
    z: np.ndarray,
    W: np.ndarray,
    upd: np.ndarray,
    H: np.ndarray,
    Ht: np.ndarray,
    R: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The Kalman update with the measurement noise R / W of the slots where ``upd``; the others keep the prediction.

    ``x_pred (M, L, n)``, ``P_pred (M, L, n, n)``, ``z (M, L, m)``, ``W`` and
    ``upd (M, L)``, ``H (m, n)`` or ``(M, L, m, n)`` and ``Ht``, its transpose (contiguous).
    """
    # R̃ = R / W without dividing (W may be tiny): S' = W H P⁻ H' + R = W S, gain K = W P⁻ H' S'⁻¹
    Wb = np.where(upd, W, 0.0)[..., None, None]
    PHt = P_pred @ Ht
    S = Wb * (H @ PHt) + R
    KtW = np.linalg.solve(S, np.swapaxes(PHt, -1, -2))  # S'⁻¹ H P⁻, i.e. Kᵀ / W
    nu = z - np.einsum("...ij,...j->...i", H, x_pred)
    x_upd = x_pred + Wb[..., 0] * np.einsum("...ji,...j->...i", KtW, nu)
    P_upd = P_pred - Wb * (PHt @ KtW)
    P_upd = 0.5 * (P_upd + np.swapaxes(P_upd, -1, -2))
    if upd.all():
        return x_upd, P_upd
    return np.where(upd[..., None], x_upd, x_pred), np.where(upd[..., None, None], P_upd, P_pred)


def _rts(xf: np.ndarray, Pf: np.ndarray, xp: np.ndarray, Pp: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel backward pass over axis 2 from the filtered, predicted and cross ``(M, L, B, ...)`` arrays."""
    B = xf.shape[2]
    xs, Ps = xf.copy(), Pf.copy()
    if B < 2:
        return xs, Ps
    # the gains G_b = C_{b+1} P⁻_{b+1}⁻¹ need only the forward pass: one solve for all steps (LAPACK per matrix, same bits)
    G = np.swapaxes(np.linalg.solve(Pp[:, :, 1:], np.swapaxes(C[:, :, 1:], -1, -2)), -1, -2)
    Gt = np.swapaxes(G, -1, -2)
    for b in range(B - 2, -1, -1):
        Gb = G[:, :, b]
        xs[:, :, b] = xf[:, :, b] + np.einsum("...ij,...j->...i", Gb, xs[:, :, b + 1] - xp[:, :, b + 1])
        Pn = Pf[:, :, b] + Gb @ (Ps[:, :, b + 1] - Pp[:, :, b + 1]) @ Gt[:, :, b]
        Ps[:, :, b] = 0.5 * (Pn + np.swapaxes(Pn, -1, -2))
    return xs, Ps


def _residuals(model: LinearModel, z: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``(M, L, B, D, m)`` z_r ⊖ h(x) for detections ``z (M, B, D, m)`` and states ``X (M, L, B, n)``."""
    if model.H is not None:
        # one component at a time into a component-major array: a broadcast subtraction whose
        # innermost axis is the m = 2 components costs about 3x more (returned as a view, last axis m)
        hx = np.einsum("ij,mlbj->mlbi", model.H, X)
        M, L, B, m = hx.shape
        out = np.empty((m, M, L, B, z.shape[2]))
        for i in range(m):
            np.subtract(z[:, None, :, :, i], hx[:, :, :, None, i], out=out[i])
        return np.moveaxis(out, 0, -1)
    hx = np.asarray(model.measurement.h(X, 1), dtype=float)
    return model.measurement.residual(z[:, None], hx[:, :, :, None, :])


def _weighted_sum(w: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``(M, L, B, m)`` Σ_r w_tr z_r for weights ``w (M, L, B, D)`` and detections ``z (M, B, D, m)``.

    One (L × D) @ (D × m) product per run and scan (``np.matmul`` on the
    stack, one fixed-size product per matrix, so batch-invariant); the einsum
    ``"mlbd,mbdi->mlbi"`` took a generic loop that cost ~7x more.
    """
    return np.swapaxes(np.swapaxes(w, 1, 2) @ z, 1, 2)


def _input_term(inputs: np.ndarray, ubar: np.ndarray) -> np.ndarray | float:
    """``(M, L, B, n)`` Σ_a ū_a g_a, the maneuver input's state change (0.0 without input axes).

    ``inputs (B, A, n)``, ``ubar (M, L, B, A)``.  One whole-array product per
    axis, summed in the order a = 0..A−1 (the einsum ``"ban,mlba->mlbn"``'s
    generic loop cost ~4x more); the einsum's values on the demo's windows.
    """
    A = inputs.shape[1]
    if A == 0:
        return 0.0
    out = ubar[..., 0, None] * inputs[:, 0]
    for a in range(1, A):
        out += ubar[..., a, None] * inputs[:, a]
    return out


def _gather_step(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``a (M, L, B, ...)`` at step ``index (M, L)`` of each slot."""
    idx = index.reshape(*index.shape, 1, *(1,) * (a.ndim - 3))
    return np.take_along_axis(a, idx, axis=2)[:, :, 0]


def _process_loglik(
    model: LinearModel,
    X: np.ndarray,
    ubar: np.ndarray,
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    first: np.ndarray,
    active: np.ndarray,
) -> np.ndarray:
    """``(M,)`` Σ_m log p(x_m | ū): the prior-predictive term at each track's first step plus the Q terms after it."""
    B = X.shape[2]
    u = _input_term(model.inputs, ubar)
    prev = np.concatenate([prior_mean[:, :, None], X[:, :, :-1]], axis=2)
    r = X - (np.einsum("bij,mlbj->mlbi", model.F, prev) + u)
    q_term = -0.5 * (quadratic_form(r, model.Q_pinv) + model.Q_logpdet)
    later = active & (np.arange(B) > first[..., None])
    fi = np.clip(first, 0, B - 1)
    F = model.F[fi]  # (M, L, n, n)
    S = F @ prior_cov @ np.swapaxes(F, -1, -2) + model.Q[fi]
    uf = _gather_step(np.broadcast_to(u, X.shape), fi)
    rf = _gather_step(X, fi) - (np.einsum("mlij,mlj->mli", F, prior_mean) + uf)
    logdet = np.linalg.slogdet(2.0 * np.pi * S)[1]
    f_term = -0.5 * (np.einsum("mli,mli->ml", rf, np.linalg.solve(S, rf[..., None])[..., 0]) + logdet)
    return np.where(later, q_term, 0.0).sum(axis=(1, 2)) + np.where(first < B, f_term, 0.0).sum(axis=1)


# --------------------------------------------------------------------------
# the tracker
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class PMHTResult(MultiTrackResult):
    """A :class:`MultiTrackResult` with PMHT's per-window EM report.

    Attributes
    ----------
    iterations
        ``(K, M)`` EM iterations (M-steps) of the window ending at each scan
        (0 where a run had no track).
    objective
        ``(K, M)`` the final incomplete-data log-likelihood of that window.
    """

    iterations: np.ndarray | None = None
    objective: np.ndarray | None = None


@dataclass(frozen=True)
class PMHTTracker(TrackerBase):
    """PMHT over a sliding window with track initiation and termination.

    Parameters
    ----------
    filter, p_detect, clutter_density
        As :class:`pursuit.multitarget.tracking.TrackerBase`; the filter must
        be a :class:`pursuit.KalmanFilter` (linear motion and measurement
        models), whose models PMHT's smoother uses.
    batch
        B, scans per window (keyword only, default 5).
    max_iter, tol
        EM stops after ``max_iter`` M-steps (default 20) or when the relative
        change of the incomplete-data log-likelihood is ≤ ``tol`` (1e-6).
    volume
        Surveillance volume V (keyword only).  Needed with ``estimate_priors``;
        otherwise it only shifts the reported objective by a constant.
    estimate_priors
        Re-estimate π at each M-step instead of the fixed expected-count priors (default False).
    hit_weight
        W_tm at the newest scan at or above which the scan counts as a hit
        for confirmation (M of N, ``confirm``) and termination (default 0.5).
        A track is terminated after ``max_misses`` consecutive scans below it
        (the hysteresis of Davey & Gray 2007).  A detection whose clutter
        weight w_tr0 at the newest scan is at least 1 − ``hit_weight`` is
        "unused" and may start a track (two-point initiation, ``max_speed``).
    gate, capacity, confirm, max_misses, max_speed, position, name
        As :class:`TrackerBase` (``gate`` is unused: PMHT does not gate).

    Notes
    -----
    Tentative tracks take part in the EM like confirmed ones (they need the
    weights to be confirmed); only confirmed tracks are reported as such.
    A new track's prior is its two-point state at its initiation scan k; it
    joins the windows from scan k + 1.
    """

    batch: int = field(default=5, kw_only=True)
    max_iter: int = field(default=20, kw_only=True)
    tol: float = field(default=1e-6, kw_only=True)
    volume: float | None = field(default=None, kw_only=True)
    estimate_priors: bool = field(default=False, kw_only=True)
    hit_weight: float = field(default=0.5, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        motion = getattr(self.filter, "motion", None)
        measurement = getattr(self.filter, "measurement", None)
        if not callable(getattr(motion, "transition_matrix", None)) or not callable(getattr(measurement, "h", None)):
            raise ValueError(
                f"filter: {type(self).__name__} needs a linear motion model (transition_matrix) and a measurement "
                f"model with h; got {type(self.filter).__name__}"
            )
        positive_int("batch", self.batch)
        positive_int("max_iter", self.max_iter)
        positive("tol", self.tol)
        in_range("hit_weight", self.hit_weight, 0.0, 1.0, low_open=True)
        if self.volume is not None:
            positive("volume", self.volume)
        if self.estimate_priors and self.volume is None:
            raise ValueError("volume: estimate_priors needs the surveillance volume")

    # EPMHT overrides these two
    def _inputs(self) -> Any:
        return None

    def _maneuver(self, runs: int, capacity: int) -> Maneuver | None:
        return None

    def track(self, z: Any, *, initial: Any = None, times: Any = None, rng: RNGLike = None) -> PMHTResult:
        """Track all runs' scans ``z (K, M, D, m)`` (NaN rows = padding); see :func:`pursuit.multitarget.track_scans`.

        ``initial``: tracks known before the first scan (Gaussian with mean
        ``(L0, n)`` or ``(M, L0, n)``), confirmed, in slots 0..L0−1.
        """
        z, times = checked_scans(z, times, self.filter)
        K, M, D, m = z.shape
        L, B = self.capacity, self.batch
        filt = self.filter
        motion = _layout_motion(filt)
        model_dt = getattr(motion, "dt", None)
        if self.max_speed is not None and times is None and model_dt is None:
            raise ValueError("times: initiation needs scan times when the motion model has no dt")
        dts = [None if times is None or k == 1 else float(times[k - 1] - times[k - 2]) for k in range(1, K + 1)]
        model = linear_model(motion, filt.measurement, dts, self._inputs())
        if m != model.R.shape[0]:
            raise ValueError(f"z: the sensor gives {model.R.shape[0]}-component detections, got {m}")
        n = model.F.shape[-1]

        if initial is not None:
            mean0, cov0, L0 = _as_initial(initial, M, L)
        else:
            mean0, cov0, L0 = np.zeros((M, L, n)), np.broadcast_to(np.eye(n), (M, L, n, n)).copy(), 0
        parking = filt.init(Gaussian(np.zeros((M, L, n)), np.broadcast_to(np.eye(n), (M, L, n, n))), batch=(M, L), rng=rng)
        table = new_table(filt.init(Gaussian(mean0, cov0), batch=(M, L), rng=rng), M, L, L0)
        prior_mean, prior_cov = mean0, cov0
        prior_scan = np.zeros((M, L), dtype=np.int64)  # scan of each slot's prior (0: before scan 1)
        X = np.zeros((M, L, 0, n))  # the last window's smoothed states (warm start)
        maneuver = self._maneuver(M, L)

        out_mean = np.full((K, M, L, n), np.nan)
        out_cov = np.full((K, M, L, n, n), np.nan)
        out_label = np.full((K, M, L), -1, dtype=np.int64)
        out_conf = np.zeros((K, M, L), dtype=bool)
        out_drop = np.zeros((K, M), dtype=np.int64)
        out_iter = np.zeros((K, M), dtype=np.int64)
        out_obj = np.full((K, M), np.nan)
        for k in range(1, K + 1):
            s = max(1, k - B + 1)  # window: scans s..k
            Bw = k - s + 1
            alive = table.alive
            first = np.where(alive, prior_scan - (s - 1), Bw)  # window step at which each track starts
            wmodel = model.window(s - 1, k)
            start = _warm_start(wmodel, X, prior_mean, first, Bw)
            # EM on the alive slots only, packed to the left (free slots would be inert but cost as much)
            slots = np.argsort(~alive, axis=1, kind="stable")[:, : max(1, int(alive.sum(axis=1).max()))]
            pack = _packer(slots)
            packed = em_window(
                wmodel, pack(prior_mean), pack(prior_cov), pack(first), z[s - 1 : k], pack(start),
                p_detect=self.p_detect, clutter_density=self.clutter_density, volume=self.volume,
                estimate_priors=self.estimate_priors, max_iter=self.max_iter, tol=self.tol,
                maneuver=None if maneuver is None else replace(maneuver, prior=pack(maneuver.prior)),
            )  # fmt: skip
            fit = _unpack(packed, slots, L)
            in_window = alive & (first < Bw)
            out_iter[k - 1] = np.where(in_window.any(axis=1), fit.iterations, 0)
            out_obj[k - 1] = np.where(in_window.any(axis=1), fit.objective, np.nan)
            joined = alive & (first <= Bw - 1)
            est_mean = np.where(joined[..., None], fit.filt_mean[:, :, -1], prior_mean)
            est_cov = np.where(joined[..., None, None], fit.filt_cov[:, :, -1], prior_cov)
            X = fit.mean
            # the window slides: its first scan leaves and its filtered estimate becomes the next prior
            if Bw == B:
                leave = alive & (first == 0)
                prior_mean = np.where(leave[..., None], fit.filt_mean[:, :, 0], prior_mean)
                prior_cov = np.where(leave[..., None, None], fit.filt_cov[:, :, 0], prior_cov)
                prior_scan = np.where(leave, s, prior_scan)
                if maneuver is not None and fit.mode_filtered is not None:
                    maneuver = replace(maneuver, prior=np.where(leave[..., None, None], fit.mode_filtered[:, :, 0], maneuver.prior))
                X = X[:, :, 1:]

            # management: hits from W at the newest scan, unused detections from the clutter weight
            hit = joined & (fit.W[:, :, -1] >= self.hit_weight)
            state = filt.init(Gaussian(est_mean, est_cov), batch=(M, L), rng=rng)
            table = update_counts(table, state, hit & alive, parking, self.confirm, self.max_misses)
            if self.max_speed is not None:
                detected = ~np.isnan(z[k - 1]).any(axis=-1)
                unused = detected & (fit.clutter[:, -1] >= 1.0 - self.hit_weight)
                step_dt = dts[k - 1] if dts[k - 1] is not None else model_dt
                table = initiate(table, filt, z[k - 1], unused, self.position, motion, self.max_speed, step_dt, rng)
            born = table.alive & (table.age == 0)  # started at this scan (update_counts aged the others)
            new_mean, new_cov = np.asarray(table.state.mean), np.asarray(table.state.cov)
            prior_mean = np.where(born[..., None], new_mean, prior_mean)
            prior_cov = np.where(born[..., None, None], np.broadcast_to(new_cov, prior_cov.shape), prior_cov)
            prior_scan = np.where(born, k, prior_scan)
            if maneuver is not None:
                maneuver = replace(maneuver, prior=np.where(born[..., None, None], self._maneuver(M, L).prior, maneuver.prior))
            gone = ~table.alive
            prior_cov = np.where(gone[..., None, None], np.eye(n), prior_cov)  # keep free slots well-posed
            est_mean = np.where(born[..., None], new_mean, est_mean)
            est_cov = np.where(born[..., None, None], np.broadcast_to(new_cov, est_cov.shape), est_cov)

            alive = table.alive
            out_mean[k - 1] = np.where(alive[..., None], est_mean, np.nan)
            out_cov[k - 1] = np.where(alive[..., None, None], est_cov, np.nan)
            out_label[k - 1] = table.label
            out_conf[k - 1] = table.confirmed
            out_drop[k - 1] = table.dropped
        return PMHTResult(out_mean, out_cov, out_label, out_conf, out_drop, self.name, out_iter, out_obj)


def _packer(slots: np.ndarray) -> Any:
    """``pack(a (M, L, ...)) -> (M, L', ...)``: the slots ``slots (M, L')`` of each run."""

    def pack(a: np.ndarray) -> np.ndarray:
        return np.take_along_axis(a, slots.reshape(*slots.shape, *(1,) * (a.ndim - 2)), axis=1)

    return pack


def _unpack(fit: WindowFit, slots: np.ndarray, capacity: int) -> WindowFit:
    """The per-slot arrays of a packed fit back in ``capacity`` slots (zeros in the others)."""

    def unpack(a: np.ndarray | None) -> np.ndarray | None:
        if a is None:
            return None
        out = np.zeros((a.shape[0], capacity, *a.shape[2:]))
        np.put_along_axis(out, slots.reshape(*slots.shape, *(1,) * (a.ndim - 2)), a, axis=1)
        return out

    return replace(
        fit,
        mean=unpack(fit.mean),
        cov=unpack(fit.cov),
        filt_mean=unpack(fit.filt_mean),
        filt_cov=unpack(fit.filt_cov),
        weights=unpack(fit.weights),
        W=unpack(fit.W),
        mode_probs=unpack(fit.mode_probs),
        mode_filtered=unpack(fit.mode_filtered),
    )


def _warm_start(model: LinearModel, X: np.ndarray, prior_mean: np.ndarray, first: np.ndarray, B: int) -> np.ndarray:
    """Initial states: the last window's smoothed states where a track had them, else the prior predicted forward."""
    M, L, Bx, n = X.shape
    out = np.empty((M, L, B, n))
    x = prior_mean
    for b in range(B):
        pred = np.einsum("ij,...j->...i", model.F[b], x)
        pred = np.where((b >= first)[..., None], pred, x)
        if b < Bx:
            known = (b >= first)[..., None]  # the track was in the last window at this scan
            pred = np.where(known, X[:, :, b], pred)
        out[:, :, b] = pred
        x = pred
    return out
