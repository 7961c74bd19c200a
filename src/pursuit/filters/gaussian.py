"""Gaussian filters: Kalman (KF), extended (EKF), unscented (UKF) and cubature (CKF).

All four share one predict-fade-update cycle and differ only in how they
propagate a Gaussian through the motion model and the measurement model:

* KF and EKF linearise (exactly for the KF) and use the Joseph-form update
  ``P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ``, its first term computed as
  ``(A L)(A L)ᵀ`` with ``A = I − K H`` and ``L`` the Cholesky factor of
  ``P⁻``, so that round-off stays relative to the result even when ``P⁻``
  is ill-conditioned;
* UKF and CKF use sigma points and the same Joseph form with the
  statistically linearised ``H = Pxzᵀ P⁻⁻¹`` and the linearisation-error
  covariance ``D = Pzz − H P⁻ Hᵀ`` added to R.  This equals
  ``P⁻ − K S Kᵀ`` exactly in exact arithmetic, but every term is a sum of
  positive-semidefinite products (for non-negative covariance weights), so
  the covariance stays positive definite over millions of steps, where the
  subtraction loses it after long gaps with precise measurements.  The
  first term is computed as ``A_L A_Lᵀ`` with ``A_L = (I − K H) L = L − K Gᵀ``
  (``L`` the points' Cholesky factor, ``G = L⁻¹ Pxz`` summed from the
  points), so neither ``L⁻¹`` nor a product with an ill-conditioned ``P⁻``
  is formed: a last-bit change of the inputs after a long gap cannot turn
  it indefinite.  The whole update is formed as one Gram matrix
  ``W Wᵀ`` with ``W = [A_L, K C, K Eᵀ]`` (``C Cᵀ = R``, ``Eᵀ E = D``): the
  product ``K (R + D) Kᵀ`` cancels when a large gain nearly annuls a large
  linearisation error, and its round-off then exceeds the smallest
  eigenvalue (UKF with TOA after a 500 s gap).

Any Gaussian filter can gate outliers: with ``gate=p`` a measurement whose
NIS exceeds the χ²(dof) quantile ``p`` is not used (that run only predicts)
and the step info flags it in ``gated``.

Every ``step`` returns ``(state, info)`` with the same info keys in every
filter:

``innovation`` (*b, m)
    z_k − ẑ_k; NaN where the measurement component is missing.
``S`` (*b, m, m)
    Innovation covariance.  Missing components are decoupled and given unit
    variance, so they add nothing to NIS or the log-likelihood.
``nis`` (*b,)
    Normalised innovation squared νᵀ S⁻¹ ν over the measured components;
    NaN when nothing was measured.
``dof`` (*b,)
    Number of measured components (the χ² degrees of freedom of NIS).
``loglik`` (*b,)
    log N(ν; 0, S) over the measured components (0 when nothing was
    measured): the log marginal likelihood increment of the step.
``fading`` (*b,)
    λ_k used in the predict step.
``faded`` (*b,)
    True where λ_k > 1 (the filter faded its memory this step).
``repaired`` (*b,)
    True where a covariance had to be repaired to stay positive definite.
``gated`` (*b,)
    True where the χ² gate rejected the measurement: the estimate is the
    prediction, while ``innovation``, ``S``, ``nis``, ``dof`` and ``loglik``
    describe the rejected measurement.  Always False without a gate.  A
    fading strategy with an outlier gate of its own (IFMKF) also sets it.
``pred_mean``, ``pred_cov``, ``cross_cov``
    Predicted mean and covariance and cov(x_{k−1}, x⁻_k), kept by
    :func:`pursuit.run` only when asked, for the RTS smoother.

A NaN measurement means predict only: every component NaN gives the
predicted mean and covariance unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar, Iterator, NamedTuple, Sequence

import numpy as np

from .._linalg import cholesky_psd, inv_spd, is_shared, logdet_spd, mv, quad, small_cholesky, small_inv_det, small_inv_logdet, symmetrize
from .._validation import MAX_MEASUREMENT, in_range, measurement_for_step, model_dim, nonnegative, prior_of_size, time_step
from ..gaussian import Gaussian
from ..models.linear_motion import LinearMotion
from ..models.measurement import LinearGaussian, _GaussianNoise
from ..models.motion import _Kinematic
from ..rng import RNGLike
from .base import FilterBase, as_gaussian, prior_batch
from .fading import Constant, FadingContext, FadingStrategy, NoFading
from .gating import apply_gate, chi2_gate_thresholds, keep_prediction
from .jacobians import call_with_dt, measurement_jacobian, motion_jacobian

__all__ = [
    "GaussianState",
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "CubatureKalmanFilter",
    "motion_jacobian",
    "measurement_jacobian",
    "linear_update",
    "check_prior_against_noise",
    "MAX_PRIOR_NOISE_RATIO",
]

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class GaussianState:
    """State of a Gaussian filter.

    Attributes
    ----------
    mean
        ``(*batch, n)`` filtered mean.
    cov
        ``(*batch, n, n)`` filtered covariance.  When every run has the same
        covariance (a linear model, a shared prior and the same missing
        measurements) this is a read-only broadcast view of one matrix.
    k
        Index of the last step processed (0 for the prior).
    memory
        The fading strategy's memory.
    """

    mean: np.ndarray
    cov: np.ndarray
    k: int = 0
    memory: Any = None

    @property
    def batch(self) -> tuple[int, ...]:
        """Batch shape."""
        return self.mean.shape[:-1]


# --------------------------------------------------------------------------
# model helpers
# --------------------------------------------------------------------------
def _residual(measurement: Any, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    res = getattr(measurement, "residual", None)
    return res(a, b) if res is not None else a - b


def _core(P: np.ndarray) -> np.ndarray:
    """One matrix if ``P`` is a broadcast of it over the batch, else ``P``."""
    if P.ndim > 2 and is_shared(P, 2):
        return P[(0,) * (P.ndim - 2)]
    return P


def _t(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


# --------------------------------------------------------------------------
# the largest prior an update can represent
# --------------------------------------------------------------------------
MAX_PRIOR_NOISE_RATIO = 2.0**48
"""Largest accepted (H P₀ Hᵀ)_ii / R_ii of a prior (≈ 2.8e14); see :func:`check_prior_against_noise`."""


def check_prior_against_noise(
    measurement: Any, mean: np.ndarray, cov: np.ndarray, k: int = 1, names: Sequence[str] | None = None
) -> None:
    """Refuse a prior covariance too large for float64 to update against the measurement noise.

    For each measurement component i the ratio ρ_i = (H P₀ Hᵀ)_ii / R_ii is formed with H the
    measurement Jacobian at the prior mean ``mean`` and P₀ = ``cov``.  The first update shrinks the measured directions of
    P to about R while the unmeasured ones keep the prior's size, so the updated covariance has a
    condition number of about ρ; float64 represents a positive-definite matrix only up to a
    condition number of about 1/ε = 2⁵² ≈ 4.5e15, and R survives in S = H P₀ Hᵀ + R with
    log2(1/(ρ ε)) bits.  Measured on WSNRange (prior s·I, 10 runs x 100 steps): EKF, UKF and CKF
    were exact up to ρ ≈ 6e14 and broke from 2e16 (non-positive-definite covariances and negative
    NIS, unflagged; UKF/CKF 1e7 m off).  The limit 2⁴⁸ ≈ 2.8e14 keeps a factor 16 below 1/ε.
    Later steps may exceed it (a long gap grows P along the motion model, and the filters handle
    that); the check is on the prior, which is the user's input.

    ``names`` labels the measurement components in the message (default ``measurement component i``).

    Raises
    ------
    ValueError
        Starting ``prior.cov:``, naming the component, the ratio and a prior variance that fits.
    """
    mean = np.asarray(mean, dtype=float)
    P = np.asarray(cov, dtype=float)
    try:
        H = measurement_jacobian(measurement, mean, k)
        R = np.asarray(measurement.cov(k), dtype=float)
    except (AttributeError, TypeError, ValueError, ArithmeticError, np.linalg.LinAlgError):  # a user's model that cannot be evaluated here is checked by its first step
        return
    if R.ndim != 2 or H.shape[-2] != R.shape[-1]:
        return
    with np.errstate(all="ignore"):
        hph = np.einsum("...ij,...jk,...ik->...i", H, P, H)
        ratio = hph / np.diagonal(R)
    bad = ratio > MAX_PRIOR_NOISE_RATIO  # NaN (a zero R) is left to the models' own checks
    if not np.any(bad):
        return
    where = np.unravel_index(int(np.nanargmax(np.where(bad, ratio, -np.inf))), ratio.shape)
    i, rho = int(where[-1]), float(ratio[where])
    raise ValueError(
        f"prior.cov: too large for the measurement noise: {names[i] if names else f'measurement component {i}'} would have a predicted variance "
        f"H P Hᵀ = {float(hph[where]):.3g}, {rho:.3g} times its noise variance R = {float(np.diagonal(R)[i]):.3g}, beyond "
        f"2^48 ≈ {MAX_PRIOR_NOISE_RATIO:.3g} (float64 cannot represent the updated covariance: it would lose positive "
        f"definiteness and give negative NIS); scale the prior covariance by at most {MAX_PRIOR_NOISE_RATIO / rho:.3g}"
    )


# --------------------------------------------------------------------------
# the shared cycle
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class _Prediction:
    mean: np.ndarray  # (*b, n)
    propagated: np.ndarray  # P̄ without Q: (n, n) or (*b, n, n)
    Q: np.ndarray
    cross: np.ndarray  # cov(x_{k-1}, x⁻_k) without fading
    repaired: np.ndarray | None = None


@dataclass(frozen=True)
class _Measured:
    zp: np.ndarray  # predicted measurement (*b, m)
    Pzz: np.ndarray  # H P⁻ Hᵀ or its sigma-point analogue, without R
    Pxz: np.ndarray  # P⁻ Hᵀ or the sigma-point cross-covariance
    H: np.ndarray | None  # linearisation for the Joseph form (KF/EKF; None for sigma-point filters)
    repaired: np.ndarray | None = None
    # sigma-point filters: the Joseph form with H = Gᵀ L⁻¹ (statistical linearisation), kept factored
    D: np.ndarray | None = None  # linearisation-error covariance Pzz − H P⁻ Hᵀ
    L: np.ndarray | None = None  # Cholesky factor of P⁻ the points were drawn with (χ = x⁻ + L ξ)
    G: np.ndarray | None = None  # L⁻¹ Pxz = (H L)ᵀ, summed from the points (no solve with L)
    E: np.ndarray | None = None  # rows √wc_i e_iᵀ with D = Eᵀ E; None when a weight wc is negative


class _OnePrediction(NamedTuple):
    """:class:`_Prediction` of one run on 2-D arrays (a tuple: a frozen dataclass costs microseconds to build)."""

    mean: np.ndarray  # (n,)
    propagated: np.ndarray  # (n, n)
    Q: np.ndarray
    cross: np.ndarray


class _OneMeasured(NamedTuple):
    """:class:`_Measured` of one run on 2-D arrays."""

    zp: np.ndarray
    Pzz: np.ndarray
    Pxz: np.ndarray
    H: np.ndarray | None
    D: np.ndarray | None = None
    L: np.ndarray | None = None
    G: np.ndarray | None = None
    E: np.ndarray | None = None


@dataclass(frozen=True)
class UpdateMoments:
    """The part of one Gaussian update that does not depend on the measurement, for a batch of tracks.

    For a filter whose update depends on ``z`` only through the innovation
    ν = residual(z, ẑ) (no gate, a constant fading factor), the prediction,
    ẑ, S, the gain K and the updated covariance are the same for every
    measurement a track may be updated with; :meth:`update` then applies
    one innovation per (track, measurement) pair.  Made by
    :meth:`_GaussianFilter.update_moments`; the multi-target trackers use it
    to update every track with every detection of a scan.

    Attributes
    ----------
    pred_mean, pred_cov
        ``(*b, n)`` and ``(n, n)`` or ``(*b, n, n)``: the prediction, its
        covariance symmetrised (the state of a step without a measurement).
    zp
        ``(*b, m)`` predicted measurement.
    K, S_inv, logdet
        Gain ``(.., n, m)``, S⁻¹ ``(.., m, m)`` and log det S ``(..)``, each
        either one for the whole batch (shared covariance) or one per track.
    cov
        Updated covariance, ``(n, n)`` or ``(*b, n, n)``, symmetrised.
    measurement
        The measurement model (its ``residual`` wraps angles).
    """

    pred_mean: np.ndarray
    pred_cov: np.ndarray
    zp: np.ndarray
    K: np.ndarray
    S_inv: np.ndarray
    logdet: np.ndarray
    cov: np.ndarray
    measurement: Any

    def update(self, z: np.ndarray, index: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mean, NIS and log-likelihood of updating track ``index`` with ``z``.

        ``z (P, m)`` holds complete measurements (no NaN); ``index`` selects
        ``P`` tracks from the batch axes (an integer array for one batch
        axis, a tuple of them for more), repeats allowed.  Equals
        ``step`` with ``z`` on those tracks, to round-off.
        """
        def take(a: np.ndarray, core: int) -> np.ndarray:
            return a if a.ndim == core else a[index]  # shared: one for all, broadcast below

        m = self.zp.shape[-1]
        nu = _residual(self.measurement, z, self.zp[index])
        mean = self.pred_mean[index] + mv(take(self.K, 2), nu)
        nis = quad(nu, take(self.S_inv, 2))
        loglik = -0.5 * (nis + take(self.logdet, 0) + m * _LOG_2PI)
        return mean, nis, loglik

    def covariance(self, index: Any, count: int) -> np.ndarray:
        """``(count, n, n)`` updated covariance of the tracks ``index``: a read-only broadcast view when shared."""
        n = self.cov.shape[-1]
        if self.cov.ndim == 2:
            return np.broadcast_to(self.cov, (count, n, n))
        return self.cov[index]


@dataclass(frozen=True)
class _GaussianFilter(FilterBase):
    """Shared predict-fade-update cycle; subclasses give the two transforms."""

    motion: Any
    measurement: Any
    fading: FadingStrategy = NoFading
    gate: float | None = field(default=None, kw_only=True)

    motion_needs = ("f", "cov")
    measurement_needs = ("h", "cov")
    need_linear_motion = True  # the compiled Gaussian filters propagate with F
    compiled_step_sensor = True  # the compiled step packs the sensor of step k (a moving observer)

    def __post_init__(self) -> None:
        if self.gate is not None:
            in_range("gate", self.gate, 0.0, 1.0, low_open=True, high_open=True)
        if isinstance(self.fading, (int, float)):
            object.__setattr__(self, "fading", Constant(float(self.fading)))
        super().__post_init__()

    def _compiled_unsupported(self) -> str | None:
        if self.compiled_path and type(self.fading) is not Constant:
            return f"the fading strategy {type(self.fading).__name__} (compiled: a constant factor)"
        return super()._compiled_unsupported()

    def _measurement_dim(self) -> int:
        """m: the measurement model's ``dim``, else the size of its noise covariance (a user's model need not say)."""
        m = model_dim(self.measurement)
        return np.shape(self.measurement.cov(1))[-1] if m is None else m

    # -- public API ---------------------------------------------------------
    def init(self, prior: Gaussian, batch: tuple[int, ...] = (), rng: RNGLike = None) -> GaussianState:
        """Initial state from a Gaussian prior, for a batch of runs.

        ``rng`` is accepted for a uniform interface; Gaussian filters draw
        nothing.
        """
        prior = as_gaussian(prior)
        batch = prior_batch(prior, batch)
        prior_of_size(prior.dim, model_dim(self.motion), self.motion)
        check_prior_against_noise(self.measurement, prior.mean, prior.cov)
        mean, cov = prior.broadcast(batch)
        return GaussianState(mean=mean, cov=cov, k=0, memory=self.fading.init(batch))

    def step(
        self, state: GaussianState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[GaussianState, MutableMapping[str, np.ndarray]]:
        """One predict-fade-update cycle with measurement ``z`` (``(*batch, m)``).

        Parameters
        ----------
        state
            State after step ``k − 1``.
        z
            Measurement; NaN entries are missing (all NaN: predict only).
        k
            Step index (default ``state.k + 1``), passed to the models.
        dt
            Time since the previous step, for irregular sampling (default:
            the motion model's own ``dt``).

        Returns
        -------
        state, info
            ``info`` maps the keys of the module docstring to arrays: a
            ``dict``, or for one run without a batch axis a mutable mapping
            that makes ``S``, ``nis`` and ``loglik`` when first read (the
            compiled online lane's too).
        """
        # compiled: one run first tries the online lane, which validates by itself.  The lane is made by
        # _online_step's first call, which also makes the lane's step this filter's own ``step`` (an instance
        # attribute, one Python frame per call): this class step then runs only where called as such
        lane = self.__dict__.get("_online_lane")
        if lane is not None:
            fast = lane.step(state, z, k, dt)
            if fast is not None:
                return fast
        elif self._specs is not None:
            fast = self._online_step(state, z, k, dt)
            if fast is not None:
                return fast
        return self._step_without_lane(state, z, k, dt)

    def _step_without_lane(
        self, state: GaussianState, z: np.ndarray, k: int | None, dt: float | None
    ) -> tuple[GaussianState, MutableMapping[str, np.ndarray]]:
        """:meth:`step` where the online lane does not apply (or there is none): the batched or NumPy step."""
        k = state.k + 1 if k is None else int(k)
        if dt is not None:
            dt = time_step(dt, k)
        batch = state.mean.shape[:-1]
        complete = _checked_measurement(z, batch, self.measurement)  # the cheap check of one run, else the full one
        if not complete:
            z = measurement_for_step(z, batch, self._measurement_dim(), k)
        if self._specs is not None and len(batch) <= 1:
            return self._compiled_step(state, z, k, dt)
        # One run without a batch axis.  A batch (1,), even with a shared covariance, keeps the general step:
        # its bits must equal those of the same run in a larger batch (a Monte Carlo chunk of one run, an IMM's
        # mixture, a multi-target gather), and the one-run maths agrees with them to round-off only.
        if not batch and type(self) in _ONE_RUN_TYPES and type(self.fading) is Constant:
            out = self._one_run_step(state, z, k, dt, complete)
            if out is not None:
                return out
        return self.numpy_step(state, z, k, dt)

    def _one_run_step(
        self, state: GaussianState, z: np.ndarray, k: int, dt: float | None, complete: bool = False
    ) -> tuple[GaussianState, MutableMapping[str, np.ndarray]] | None:
        """:meth:`numpy_step` for one run without a batch axis (batch ``()``) and a constant fading factor, or None.

        The maths of the general step on plain 2-D arrays: ``ndarray.dot``
        instead of ``einsum``, ``matmul`` and broadcasts (each costs several
        times the arithmetic on a 4 x 4 matrix), closed-form S⁻¹ and log det S
        in Python floats, LAPACK's Cholesky called directly.  It agrees with
        :meth:`numpy_step` to round-off (not bit for bit: which is why a batch
        ``(1,)`` takes the general step), with the same info keys, shapes and
        dtypes; the info is a :class:`_OneRunInfo` that makes ``S``, ``nis``
        and ``loglik`` when first read.  The matrices of a built-in
        time-invariant model are read once per filter (and ``dt``), not per
        step.  None where the general step must decide: some but not all
        components of ``z`` missing, a covariance that needs a repair, a
        model that returns batched matrices for one state; the caller then
        runs :meth:`numpy_step`.  ``complete``: ``z`` is known to have no
        missing component.
        """
        x, P = state.mean, state.cov
        lam = self.fading.lam
        pred = self._predict_one(x, P, k, dt)
        if pred is None:
            return None
        P_pred = pred.propagated + pred.Q if lam == 1.0 else lam * pred.propagated + pred.Q
        meas = self._measure_one(pred.mean, P_pred, k)
        if meas is None:
            return None
        m = z.shape[0]
        missing = 0 if complete else int(np.isnan(z).sum())
        if not missing:
            noise = self._noise_one(k)
            if noise is None or len(noise[2]) != m * m or meas.zp.shape != (m,):
                return None  # a batched R, or a model inconsistent with z: the general step decides (and raises)
            plain = getattr(type(self.measurement), "residual", None) is _GaussianNoise.residual  # z − ẑ, no call
            measurement = None if plain else self.measurement
            mean, cov, moments = _one_run_moments(pred.mean, P_pred, z, meas, measurement, *noise)
            gated = self.gate is not None and moments.nis() > chi2_gate_thresholds(self.gate, m)[m]
            if gated:  # the prediction, the info describing the rejected measurement (as apply_gate)
                mean, cov = pred.mean.copy(), _sym(P_pred)  # a copy: the state must not share info's pred_mean
            dof, fading, faded, repaired = _constants(m, lam)
            info = _OneRunInfo({
                "innovation": moments.nu,
                "dof": dof,
                "fading": fading,
                "faded": faded,
                "repaired": repaired,
                "gated": _TRUE if gated else _FALSE,
                "pred_mean": pred.mean,
                "pred_cov": P_pred,
                "cross_cov": pred.cross,
            }, moments)
        elif missing == m:  # predict only: zero gain, unit variance for every missing component
            mean, cov = pred.mean.copy(), _sym(P_pred)
            info = _OneRunInfo({
                "innovation": np.array([np.nan] * m),
                "S": _eye(m).copy(),
                "nis": np.array(np.nan),
                "dof": _constant(0),
                "loglik": np.array(0.0),
                "fading": _constant(float(lam)),
                "faded": _constant(lam > 1.0),
                "repaired": _constant(False),
                "gated": _constant(False),
                "pred_mean": pred.mean,
                "pred_cov": P_pred,
                "cross_cov": pred.cross,
            }, None)
        else:
            return None
        # GaussianState is a frozen dataclass without __post_init__: filling its __dict__ is what __init__ does, cheaper
        new = object.__new__(GaussianState)
        new.__dict__.update(mean=mean, cov=cov, k=k, memory=state.memory)
        return new, info

    def _motion_one(self, k: int, dt: float | None) -> tuple[np.ndarray, np.ndarray] | None:
        """``(F, Q)`` at ``dt`` of a built-in time-invariant linear motion model, made once per ``dt``; None for other models.

        Those models' F and Q depend on ``dt`` alone (not on ``k`` or ``x``)
        and are read-only, so the one-run step reads them from this cache
        instead of calling the model twice per step; the sigma-point filters'
        predictions (batched and one-run) also take it as the sign that f is
        F x, to predict without points.
        """
        cache = self.__dict__.get("_one_run_motion")
        if cache is None:
            cache = {} if _time_invariant_linear(self.motion) else False
            object.__setattr__(self, "_one_run_motion", cache)  # per filter: not a field
        if cache is False:
            return None
        got = cache.get(dt)
        if got is None:
            F = np.asarray(call_with_dt(self.motion.transition_matrix, k, dt=dt), dtype=float)
            Q = np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float)
            if F.ndim != 2 or Q.ndim != 2:
                return None
            if F.flags.writeable or Q.flags.writeable:
                return F, Q  # not the frozen matrices of construction: they may change, so read them every step
            if len(cache) >= _MAX_DT_CACHE:
                cache.clear()
            got = cache[dt] = (F, Q)
        return got

    def _noise_one(self, k: int) -> tuple[np.ndarray, np.ndarray | None, list[float]] | None:
        """``(R, C, r)`` of step ``k``: R ``(m, m)``, its Cholesky factor C (None where R does not factor) and its entries as floats.

        Made once for a built-in measurement model (R fixed and read-only at
        construction), per step for any other; None for a batched R.
        """
        noise = self.__dict__.get("_one_run_noise")
        if noise is not None:
            return noise
        R = np.asarray(self.measurement.cov(k), dtype=float)
        if R.ndim != 2:
            return None
        noise = (R, small_cholesky(R), R.ravel().tolist())
        if _fixed_noise(self.measurement) and not R.flags.writeable:
            object.__setattr__(self, "_one_run_noise", noise)  # per filter: not a field
        return noise

    # The one-run hooks: _predict and _measure for x (n,), P (n, n), on 2-D arrays; None: use the general step.
    def _predict_one(self, x: np.ndarray, P: np.ndarray, k: int, dt: float | None) -> _OnePrediction | None:
        raise NotImplementedError

    def _measure_one(self, x_pred: np.ndarray, P_pred: np.ndarray, k: int) -> _OneMeasured | None:
        raise NotImplementedError

    def numpy_step(
        self, state: GaussianState, z: np.ndarray, k: int, dt: float | None
    ) -> tuple[GaussianState, dict[str, np.ndarray]]:
        """The NumPy step, whatever the backend (``z`` already checked and broadcast to ``(*batch, m)``).

        :meth:`step` calls it unless the step runs compiled; the compiled
        step calls it for the runs whose covariance needs a repair.
        """
        batch = state.batch
        P = _core(state.cov)
        pred = self._predict(state.mean, P, k, dt)
        ctx = FadingContext(
            k=k,
            pred_mean=pred.mean,
            propagated_cov=pred.propagated,
            process_cov=pred.Q,
            z=z,
            measurement=self.measurement,
            trial_update=lambda lam: self._trial(pred, lam, z, k),
            linearize=lambda: self._linearize(pred, k),
        )
        fade, memory = self.fading.factor(state.memory, ctx)
        lam = np.asarray(fade.lam, dtype=float)
        P_pred = _scale(lam, pred.propagated) + pred.Q

        meas, P_pred = self._measure_factored(pred.mean, P_pred, k)
        mean, cov, info = _update(pred.mean, P_pred, z, ~np.isnan(z), meas, self.measurement, k)
        if fade.skip is not None:
            # The strategy's own gate: those runs keep the prediction, while the
            # info still describes the measurement they rejected (as for `gate`).
            mean, cov = keep_prediction(np.asarray(fade.skip, dtype=bool), pred.mean, P_pred, mean, cov)
        gated = np.zeros(batch, dtype=bool)
        if self.gate is not None:
            mean, cov, gated = apply_gate(self.gate, info, pred.mean, P_pred, mean, cov)

        if cov.ndim == 2 and batch:
            cov = np.broadcast_to(cov, (*batch, *cov.shape))
        info["fading"] = np.broadcast_to(lam, batch)
        info["faded"] = np.broadcast_to(lam > 1.0, batch)
        info["repaired"] = _any_repaired(batch, pred.repaired, meas.repaired)
        info["gated"] = gated
        info["pred_mean"] = pred.mean
        info["pred_cov"] = P_pred
        info["cross_cov"] = pred.cross
        for key, value in fade.info.items():
            info[key] = value
        if "gated" in fade.info:  # a fading strategy's own outlier gate (IFMKF) rejects too
            info["gated"] = np.asarray(fade.info["gated"], dtype=bool) | gated
        return GaussianState(mean=mean, cov=cov, k=k, memory=memory), info

    def update_moments(self, state: GaussianState, k: int, dt: float | None = None) -> UpdateMoments | None:
        """Predict and compute everything of the update that does not depend on the measurement.

        Returns None where the update depends on the measurement beyond its
        innovation: a ``gate``, a fading strategy other than a constant
        factor (adaptive strategies read z), or a subclass with a ``step``
        of its own.  The hooks are the NumPy step's, whatever the backend.

        Parameters
        ----------
        state
            State after step ``k − 1``, any batch.
        k, dt
            Step index and time since the previous step (None: the model's own).
        """
        if not self._plain_step():
            return None
        k = int(k)
        dt = time_step(dt, k)
        pred, meas, P_pred = self._predict_and_measure(state, k, dt)
        R = np.asarray(self.measurement.cov(k), dtype=float)
        S, S_inv, K, cov = _gain_and_cov(P_pred, meas, R, R, meas.Pzz, meas.Pxz, meas.H, meas.D)
        return UpdateMoments(pred.mean, symmetrize(P_pred), meas.zp, K, S_inv, logdet_spd(S), symmetrize(cov), self.measurement)

    def posterior(
        self, state: GaussianState, z: np.ndarray, k: int, dt: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The NumPy step's posterior mean, covariance and ``repaired`` flags, without its info.

        For callers that discard the info of a batch of steps (the partial
        UPF's UKF per particle): NIS, log det S and the info arrays are not
        made.  The mean and covariance are :meth:`numpy_step`'s, bit for
        bit (for one run without a batch axis :meth:`step` takes a cheaper
        path, equal to round-off).  Nothing is checked: ``z`` must already be
        ``(*batch, m)`` (NaN: missing), as :meth:`numpy_step` takes it, and
        ``k``, ``dt`` what :meth:`step` accepted.  None where the step
        is more than predict-and-update (a ``gate``, a fading strategy other
        than a constant factor, a subclass with a step of its own) or where
        :meth:`step` runs compiled (a compiled backend and at most one batch
        axis): the caller then runs :meth:`step`.
        """
        if not self._plain_step() or (self._specs is not None and len(state.batch) <= 1):
            return None
        pred, meas, P_pred = self._predict_and_measure(state, k, dt)
        mean, cov, _ = _update(pred.mean, P_pred, z, ~np.isnan(z), meas, self.measurement, k, with_info=False)
        batch = state.batch
        if cov.ndim == 2 and batch:
            cov = np.broadcast_to(cov, (*batch, *cov.shape))
        return mean, cov, _any_repaired(batch, pred.repaired, meas.repaired)

    def _plain_step(self) -> bool:
        """Whether a step is predict-then-update alone: no gate, a constant fading factor, this class's own step."""
        own = type(self).step is _GaussianFilter.step and type(self).numpy_step is _GaussianFilter.numpy_step
        return self.gate is None and type(self.fading) is Constant and own

    def _predict_and_measure(self, state: GaussianState, k: int, dt: float | None) -> tuple[_Prediction, _Measured, np.ndarray]:
        """The prediction with the constant fading factor, the update's moments and P⁻ as they saw it."""
        pred = self._predict(state.mean, _core(state.cov), k, dt)
        P_pred = _scale(np.asarray(self.fading.lam, dtype=float), pred.propagated) + pred.Q
        meas, P_pred = self._measure_factored(pred.mean, P_pred, k)
        return pred, meas, P_pred

    # -- hooks --------------------------------------------------------------
    def _predict(self, x: np.ndarray, P: np.ndarray, k: int, dt: float | None) -> _Prediction:
        raise NotImplementedError

    def _measure(self, x_pred: np.ndarray, P_pred: np.ndarray, k: int) -> _Measured:
        raise NotImplementedError

    def _measure_factored(self, x_pred: np.ndarray, P_pred: np.ndarray, k: int) -> tuple[_Measured, np.ndarray]:
        """:meth:`_measure`, and P⁻ as its points saw it (:func:`_as_factored`): what a step that keeps the prediction keeps."""
        meas = self._measure(x_pred, P_pred, k)
        return meas, _as_factored(P_pred, meas)

    def _trial(self, pred: _Prediction, lam: np.ndarray, z: np.ndarray, k: int):
        P_pred = _scale(lam, pred.propagated) + pred.Q
        meas, P_pred = self._measure_factored(pred.mean, P_pred, k)
        mean, cov, _ = _update(pred.mean, P_pred, z, ~np.isnan(z), meas, self.measurement, k, with_info=False)
        return mean, cov

    def _linearize(self, pred: _Prediction, k: int) -> np.ndarray:
        """H_k for fading strategies: the measurement Jacobian at the prediction."""
        return measurement_jacobian(self.measurement, pred.mean, k)


def _scale(lam: np.ndarray, P: np.ndarray) -> np.ndarray:
    if lam.ndim == 0:
        return P if lam == 1.0 else lam * P
    return lam[..., None, None] * P


def _any_repaired(batch, *flags) -> np.ndarray:
    out = np.zeros(batch, dtype=bool)
    for f in flags:
        if f is not None:
            out = out | np.broadcast_to(f, batch)
    return out


def _as_factored(P_pred: np.ndarray, meas: _Measured) -> np.ndarray:
    """P⁻ as the update's sigma points saw it: L Lᵀ of the repaired matrix where their factor needed a repair.

    A step that keeps the prediction (nothing measured, a gate, a fading
    strategy's skip) then keeps a positive-definite P⁻, as the update did.
    """
    rep = meas.repaired
    if rep is None or not np.any(rep):
        return P_pred
    fixed = symmetrize(meas.L @ _t(meas.L))
    return np.where(np.asarray(rep)[..., None, None], fixed, P_pred)


def _update(x_pred, P_pred, z, valid, meas: _Measured, measurement, k, with_info: bool = True):
    """Kalman measurement update with missing components masked out.

    ``with_info=False`` returns None for the info and skips what only the
    info needs (NIS, log det S, the masked innovation): the mean and
    covariance are the same arrays, bit for bit.
    """
    R = np.asarray(measurement.cov(k), dtype=float)
    m = R.shape[-1]
    batch = x_pred.shape[:-1]
    nu_full = _residual(measurement, z, meas.zp)
    Pzz, Pxz, H, D = meas.Pzz, meas.Pxz, meas.H, meas.D

    if valid.all():
        nu = nu_full
        R_eff = R
        dof = np.full(batch, m)
    else:
        # A missing component gets zero innovation, no coupling and unit
        # variance: its Kalman gain column is then exactly zero.
        if valid.ndim > 1 and (valid == valid.reshape(-1, m)[0]).all():
            valid = valid.reshape(-1, m)[0]  # same pattern in every run: stay shared
        vv = valid[..., :, None] & valid[..., None, :]
        nu = np.where(valid, nu_full, 0.0)
        Pzz = np.where(vv, Pzz, 0.0)
        Pxz = Pxz * valid[..., None, :]
        R_eff = np.where(vv, R, 0.0) + np.eye(m) * (~valid)[..., None, :]
        if H is not None:
            H = H * valid[..., :, None]
        if D is not None:
            D = np.where(vv, D, 0.0)
        dof = np.broadcast_to(valid.sum(axis=-1), batch)

    S, S_inv, K, cov = _gain_and_cov(P_pred, meas, R, R_eff, Pzz, Pxz, H, D)
    mean = x_pred + mv(K, nu)
    measured = dof > 0
    if not np.all(measured):
        # nothing measured: the prediction itself, not its factor's reconstruction L Lᵀ
        cov = np.where(measured[..., None, None], cov, P_pred)
    cov = symmetrize(cov)
    if not with_info:
        return mean, cov, None

    nis = quad(nu, S_inv)
    loglik = -0.5 * (nis + logdet_spd(S) + dof * _LOG_2PI)
    nis = np.where(measured, nis, np.nan)
    loglik = np.where(measured, loglik, 0.0)
    innovation = np.where(valid, nu_full, np.nan) if not np.all(valid) else nu_full
    info = {
        "innovation": np.broadcast_to(innovation, (*batch, m)),
        "S": np.broadcast_to(S, (*batch, m, m)),
        "nis": np.broadcast_to(nis, batch),
        "dof": np.broadcast_to(dof, batch),
        "loglik": np.broadcast_to(loglik, batch),
    }
    return mean, cov, info


_ONE_RUN = ((), (1,))  # batches of one run: their measurement gets the cheap check
_F64 = np.dtype(np.float64)


def _checked_measurement(z: Any, batch: tuple[int, ...], measurement: Any) -> bool:
    """True when ``z`` already is what :func:`measurement_for_step` returns for one run: float64, ``(*batch, m)``, within range.

    The bounds are checked on Python floats (an array reduction costs more
    than the step's arithmetic); anything else, NaN included, goes through
    :func:`measurement_for_step`, which raises the errors.  True means no
    component is missing.
    """
    if batch not in _ONE_RUN or type(z) is not np.ndarray or z.shape[:-1] != batch:
        return False
    if z.dtype is not _F64 and z.dtype != _F64:  # identity first: a dtype comparison costs more than this whole check
        return False
    m = getattr(measurement, "dim", None)
    if type(m) is not int:  # what model_dim accepts, the common case first
        m = model_dim(measurement)
    if m is None or z.shape[-1] != m:
        return False
    values = z.tolist() if z.ndim == 1 else z.ravel().tolist()
    total = sum(values)
    return total - total == 0.0 and max(map(abs, values)) <= MAX_MEASUREMENT  # the first is False for NaN or ±inf


@lru_cache(maxsize=256, typed=True)  # typed: 0 and False are different arrays
def _constant(value: Any) -> np.ndarray:
    """A read-only 0-d array of ``value`` (``dof``, ``fading``, the flags), made once: steps share it."""
    out = np.array(value)
    out.flags.writeable = False
    return out


_TRUE, _FALSE = _constant(True), _constant(False)


@lru_cache(maxsize=256)
def _constants(m: int, lam: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``dof``, ``fading``, ``faded`` and ``repaired`` of a fully measured one-run step: read-only 0-d arrays, made once."""
    return _constant(m), _constant(float(lam)), _constant(lam > 1.0), _FALSE


@lru_cache(maxsize=16)
def _eye(n: int) -> np.ndarray:
    out = np.eye(n)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=16)
def _halves(n: int) -> np.ndarray:
    out = np.full((n, n), 0.5)
    out.flags.writeable = False
    return out


def _sym(A: np.ndarray) -> np.ndarray:
    """:func:`pursuit._linalg.symmetrize` of one matrix, bit for bit.

    The transpose is copied first and the half is an array: a ufunc mixing C
    and Fortran order, or taking a Python scalar, costs several times the
    arithmetic on a small matrix.
    """
    return (A + A.T.copy()) * _halves(A.shape[0])


def _one_run_update(x_pred, P_pred, z, meas: _OneMeasured, measurement, k):
    """:func:`_update` and :func:`_gain_and_cov` for one run with every component measured, on 2-D arrays.

    Returns ``(mean, cov, ν, S, nis, loglik)`` with NIS and the
    log-likelihood as Python floats, or None for a batched R.  The eager form
    of :func:`_one_run_moments` (which the filters' one-run step calls).
    """
    R = np.asarray(measurement.cov(k), dtype=float)
    if R.ndim != 2:
        return None
    mean, cov, moments = _one_run_moments(x_pred, P_pred, z, meas, measurement, R, small_cholesky(R), R.ravel().tolist())
    return mean, cov, moments.nu, moments.value("S"), moments.nis(), moments.loglik()


def _one_run_moments(
    x_pred: np.ndarray, P_pred: np.ndarray, z: np.ndarray, meas: _OneMeasured, measurement: Any,
    R: np.ndarray, C: np.ndarray | None, r: list[float],
) -> tuple[np.ndarray, np.ndarray, "_Innovation"]:
    """The update of one run with every component measured: ``(mean, cov, innovation moments)``.

    ``R (m, m)``, ``C`` its Cholesky factor (None where it does not factor)
    and ``r`` its entries as Python floats; ``measurement`` gives the
    ``residual`` (None: the plain difference ``z − ẑ``).  S is formed and inverted in
    Python floats (the closed forms of :func:`pursuit._linalg.small_inv_det`,
    LAPACK beyond 3 x 3); NIS and the log-likelihood are left to the
    returned :class:`_Innovation`, computed when asked for.

    The covariance is the Joseph form of the general step (:func:`_gain_and_cov`),
    each term a Gram matrix: ``(A L)(A L)ᵀ + (K C)(K C)ᵀ`` for the KF/EKF
    (``A = I − K H``, ``L`` the factor of P⁻), ``W Wᵀ`` for sigma points.
    NumPy computes ``X.dot(X.T)`` with BLAS ``syrk`` and mirrors its
    triangle, so each term, and their sum, is symmetric to the bit and needs
    no symmetrisation; ``K R Kᵀ`` as a product (where ``R`` does not factor)
    is not, and is symmetrised as the general step does.
    """
    m = len(meas.zp)
    nu = z - meas.zp if measurement is None else _residual(measurement, z, meas.zp)
    t = meas.Pzz.ravel().tolist()
    if m == 2:  # symmetrize(Pzz + R) of the general step, bit for bit: (a + b) * 0.5 per entry
        a, b, c, d = t[0] + r[0], t[1] + r[1], t[2] + r[2], t[3] + r[3]
        s = [(a + a) * 0.5, (b + c) * 0.5, (c + b) * 0.5, (d + d) * 0.5]
    else:
        t = [u + v for u, v in zip(t, r)]
        s = [(t[i * m + j] + t[j * m + i]) * 0.5 for i in range(m) for j in range(m)]
    small = small_inv_det(s, m)
    if small is None:  # m > 3, or a determinant the closed forms cannot trust: LAPACK decides
        S = np.array(s).reshape(m, m)
        S_inv = inv_spd(S)
        moments = _Innovation(m, nu, s, S_inv.tolist(), None, float(logdet_spd(S)))
    else:
        w, det = small
        S_inv = np.array(w)
        moments = _Innovation(m, nu, s, w, det, None)
    K = meas.Pxz.dot(S_inv)
    mean = x_pred + K.dot(nu)
    if meas.L is not None:  # sigma points: the Joseph form through the points' factor (see _gain_and_cov)
        AL = meas.L - K.dot(meas.G.T)
        if C is not None and meas.E is not None:  # the Gram matrix of _joseph_gram
            W = np.concatenate([AL, K.dot(C), K.dot(meas.E.T)], axis=1)
            return mean, W.dot(W.T), moments
        return mean, _sym(AL.dot(AL.T) + K.dot(R + meas.D).dot(K.T)), moments
    # KF/EKF: A P⁻ Aᵀ as the Gram matrix of P⁻'s factor (see _sandwich)
    A = _eye(P_pred.shape[0]) - K.dot(meas.H)
    L = small_cholesky(P_pred)
    if L is not None and C is not None:
        AL, KC = A.dot(L), K.dot(C)
        return mean, AL.dot(AL.T) + KC.dot(KC.T), moments
    if L is None:
        cov = A.dot(P_pred).dot(A.T)
    else:
        AL = A.dot(L)
        cov = AL.dot(AL.T)
    return mean, _sym(cov + K.dot(R).dot(K.T)), moments


class _Innovation:
    """S, NIS and the log-likelihood of one fully measured update, from Python floats, each made when first asked for."""

    __slots__ = ("m", "nu", "v", "s", "w", "det", "logdet", "_nis")

    def __init__(self, m: int, nu: np.ndarray, s: list[float], w: list[list[float]], det: float | None, logdet: float | None):
        self.m, self.nu, self.s, self.w = m, nu, s, w  # s: S row by row; w: the rows of S⁻¹
        # ν's floats now: info["innovation"] is the array nu, which a caller may change in place before reading nis
        self.v = nu.tolist()
        self.det, self.logdet = det, logdet  # log det S is np.log(det) where logdet is None
        self._nis: float | None = None

    def nis(self) -> float:
        """νᵀ S⁻¹ ν."""
        nis = self._nis
        if nis is None:
            v, w, m = self.v, self.w, self.m
            nis = self._nis = sum([v[i] * w[i][j] * v[j] for i in range(m) for j in range(m)])
        return nis

    def loglik(self) -> float:
        """log N(ν; 0, S)."""
        logdet = self.logdet
        if logdet is None:
            # np.log, not math.log: the bits of logdet_spd (NumPy's SIMD log may differ from libm's in the last bit)
            logdet = self.logdet = float(np.log(self.det))
        return -0.5 * (self.nis() + logdet + self.m * _LOG_2PI)

    def value(self, key: str) -> np.ndarray:
        """The info value ``S``, ``nis`` or ``loglik``, as the general step's (fresh float64 arrays)."""
        if key == "S":
            return np.array(self.s).reshape(self.m, self.m)
        if key == "nis":
            return np.array(self.nis())
        if key == "loglik":
            return np.array(self.loglik())
        raise KeyError(key)


INFO_KEYS = ("innovation", "S", "nis", "dof", "loglik", "fading", "faded", "repaired", "gated", "pred_mean", "pred_cov", "cross_cov")
"""The info keys of every Gaussian filter's step, in order."""

_LAZY_KEYS = frozenset({"S", "nis", "loglik"})


class _OneRunInfo(MutableMapping):
    """The info of a one-run step: :meth:`_GaussianFilter.numpy_step`'s keys and values, ``S``, ``nis`` and ``loglik`` made on first access.

    A fully measured step of one run costs a few microseconds more when its
    info is built eagerly (three arrays, NIS and a logarithm) than its
    filter arithmetic can spare; most callers read one key or none.  Each
    value is made once and returned again (the same array), with the shape,
    dtype and value the eager dict had.  Setting or deleting a key first
    makes every value, after which it is an ordinary mapping.  It iterates
    in the general step's key order, prints and pickles as that step's plain
    ``dict`` (``pickle`` and ``copy`` give a ``dict``).
    """

    __slots__ = ("_values", "_moments")

    def __init__(self, values: dict[str, Any], moments: _Innovation | None):
        self._values = values  # every key but those moments makes (all of them when moments is None)
        self._moments = moments

    def __getitem__(self, key: str) -> Any:
        try:
            return self._values[key]
        except KeyError:
            if self._moments is None or key not in _LAZY_KEYS:
                raise
        value = self._values[key] = self._moments.value(key)
        return value

    def _resolve(self) -> dict[str, Any]:
        if self._moments is not None:
            self._values = {key: self[key] for key in INFO_KEYS}
            self._moments = None
        return self._values

    def __setitem__(self, key: str, value: Any) -> None:
        self._resolve()[key] = value

    def __delitem__(self, key: str) -> None:
        del self._resolve()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(INFO_KEYS) if self._moments is not None else iter(self._values)

    def __len__(self) -> int:
        return len(INFO_KEYS) if self._moments is not None else len(self._values)

    def __contains__(self, key: object) -> bool:
        return key in INFO_KEYS if self._moments is not None else key in self._values

    def __repr__(self) -> str:
        return repr(dict(self))

    def __reduce__(self):
        return (dict, (dict(self),))

    # what a caller of the general step may do with its plain dict
    def copy(self) -> dict[str, Any]:
        """A plain ``dict`` with every value made."""
        return dict(self)

    def __or__(self, other: Any) -> dict[str, Any]:
        return dict(self) | other if isinstance(other, Mapping) else NotImplemented

    def __ror__(self, other: Any) -> dict[str, Any]:
        return dict(other) | dict(self) if isinstance(other, Mapping) else NotImplemented


_MAX_DT_CACHE = 64  # distinct dt values whose (F, Q) a filter keeps for its one-run step


def _time_invariant_linear(motion: Any) -> bool:
    """Whether F and Q of ``motion`` depend on ``dt`` alone and ``f`` and ``jacobian`` are F: the built-in linear models."""
    base = _Kinematic if isinstance(motion, _Kinematic) else LinearMotion if isinstance(motion, LinearMotion) else None
    if base is None:
        return False
    names = ("f", "jacobian", "transition_matrix", "cov", "_matrices") if base is _Kinematic else ("f", "jacobian", "transition_matrix", "cov")
    t = type(motion)
    return all(getattr(t, name) is getattr(base, name) for name in names)  # a subclass overriding one is a user's model


def _fixed_noise(measurement: Any) -> bool:
    """Whether ``measurement.cov(k)`` is the read-only R fixed at construction (the built-in models' ``cov``)."""
    return isinstance(measurement, _GaussianNoise) and type(measurement).cov is _GaussianNoise.cov


def _gain_and_cov(P_pred, meas: _Measured, R, R_eff, Pzz, Pxz, H, D):
    """S, S⁻¹, the gain K and the Joseph-form covariance (not yet symmetrised): the part of the update that ignores z."""
    S = symmetrize(Pzz + R_eff)
    S_inv = inv_spd(S)
    K = Pxz @ S_inv
    if meas.L is not None:
        # Sigma points: the Joseph form through the points' factor, (I − K H) L = L − K Gᵀ, so
        # neither H = Gᵀ L⁻¹ nor a product with P⁻ is formed.  With L ill-conditioned (a long gap
        # makes P⁻ nearly singular) the solve for H and the products A P⁻ Aᵀ lost positive
        # definiteness to round-off; a Gram matrix A_L A_Lᵀ cannot.
        AL = meas.L - K @ _t(meas.G)
        cov = _joseph_gram(AL, K, R, meas.E)
        if cov is None:
            cov = AL @ _t(AL) + K @ (R_eff + D) @ _t(K)
    else:  # KF/EKF: every _Measured carries H or the points' factor L
        n = P_pred.shape[-1]
        A = np.eye(n) - K @ H
        cov = _sandwich(A, P_pred) + K @ R_eff @ _t(K)
    return S, S_inv, K, cov


def _joseph_gram(AL: np.ndarray, K: np.ndarray, R: np.ndarray, E: np.ndarray | None) -> np.ndarray | None:
    """The sigma-point Joseph form A_L A_Lᵀ + K (R + D) Kᵀ as one Gram matrix W Wᵀ, or None.

    ``W = [A_L, K C, K Eᵀ]`` with ``C Cᵀ = R`` and ``Eᵀ E = D``.  The product
    ``K (R + D) Kᵀ`` cancels when the gain is large and ``R + D`` has one
    large eigenvalue along a direction that ``K`` nearly annuls (a UKF with
    time-of-arrival after a 500 s gap: gain entries 1e7, a linearisation
    error of 7e4 along (1, 1, 1)); its round-off of about ε·|K|²·|R + D|
    then exceeds the covariance's smallest eigenvalue and the result is
    indefinite.  A Gram matrix errs relative to its own diagonal and stays
    positive semidefinite.  Columns of ``K`` for missing components are exactly
    zero, so ``R`` and ``E`` need no masking.  None when ``E`` is unknown (a
    negative weight wc) or ``R`` does not factor: the caller uses the product.
    """
    if E is None:
        return None
    try:
        C = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        return None
    C = np.broadcast_to(C, (*K.shape[:-2], *C.shape[-2:]))
    # W filled in place: np.concatenate of the three blocks cost as much as the two products (p3-upf's
    # 20 000 particle UKFs); the same values
    n, m = AL.shape[-1], K.shape[-1]
    W = np.empty((*np.broadcast_shapes(AL.shape[:-2], K.shape[:-2], E.shape[:-2]), AL.shape[-2], n + m + E.shape[-2]))
    W[..., :n] = AL
    np.matmul(K, C, out=W[..., n : n + m])
    np.matmul(K, _t(E), out=W[..., n + m :])
    return W @ _t(W)


def _sandwich(A: np.ndarray, P: np.ndarray) -> np.ndarray:
    """A P Aᵀ computed as the Gram matrix (A L)(A L)ᵀ of P's Cholesky factor L.

    The direct product errs by about ε·|A|·|P|·|A|, which exceeds the
    smallest eigenvalue of the result when P⁻ is ill-conditioned (a long gap,
    then one precise component: an EKF with range-bearing went indefinite
    after a 500 s gap when its inputs were scaled by 1 + 1e-15).  The Gram
    matrix errs relative to its own diagonal instead.  A stack holding a
    matrix that does not factor takes the direct product (the next step's
    factorisation repairs and flags it).
    """
    try:
        L = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return A @ P @ _t(A)
    AL = A @ L
    return AL @ _t(AL)


def linear_update(
    x_pred: np.ndarray, P_pred: np.ndarray, z: np.ndarray, H: np.ndarray, measurement: Any, k: int
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The shared Kalman update for a linear measurement ``z = H x + v``, for filters built elsewhere.

    Filters that form their own prediction (the CS-model filters, the IMM's
    model-matched filters) call this so that missing components, the Joseph
    form and the info keys ``innovation``, ``S``, ``nis``, ``dof`` and
    ``loglik`` mean exactly what they mean in every Gaussian filter.

    Parameters
    ----------
    x_pred, P_pred
        Predicted mean ``(*b, n)`` and covariance ``(*b, n, n)``.
    z
        Measurement ``(*b, m)``; NaN components are missing.
    H
        ``(m, n)`` or ``(*b, m, n)``.
    measurement
        Gives ``cov(k)`` (R, ``(m, m)`` or broadcasting against ``(*b, m, m)``)
        and optionally ``residual(a, b)``.
    k
        Step index passed to ``measurement.cov``.

    Returns
    -------
    mean, cov, info
    """
    H = np.asarray(H, dtype=float)
    PHt = P_pred @ _t(H)
    meas = _Measured(mv(H, x_pred), H @ PHt, PHt, H)
    return _update(x_pred, P_pred, z, ~np.isnan(z), meas, measurement, k)


# --------------------------------------------------------------------------
# KF and EKF
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class ExtendedKalmanFilter(_GaussianFilter):
    """Extended Kalman filter with Joseph-form update.

    Parameters
    ----------
    motion, measurement
        Model objects (see :mod:`pursuit.models`).  Missing ``jacobian``
        methods are replaced by central differences.
    fading
        Fading strategy for the predict step, or a number (constant λ).
    gate
        χ² gate probability in (0, 1), keyword only (default: no gate).
    name
        Label used in results and reports (keyword only).
    backend
        Compute backend, keyword only: ``"numpy"``, ``"numba"`` (compiled,
        for linear motion models, the built-in measurement models and a
        constant fading factor; see :mod:`pursuit.compute`) or ``None`` for
        the process default.  Not the Monte Carlo engine's execution backend.
    """

    compiled_path = "gaussian:EKF"

    def _default_name(self) -> str:
        return "EKF"

    def _predict(self, x, P, k, dt):
        F = motion_jacobian(self.motion, x, k, dt)
        mean = np.asarray(call_with_dt(self.motion.f, x, k, dt=dt), dtype=float)
        PFt = P @ _t(F)
        return _Prediction(mean, F @ PFt, np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float), PFt)

    def _measure(self, x_pred, P_pred, k):
        H = measurement_jacobian(self.measurement, x_pred, k)
        zp = np.asarray(self.measurement.h(x_pred, k), dtype=float)
        PHt = P_pred @ _t(H)
        return _Measured(zp, H @ PHt, PHt, H)

    def _predict_one(self, x, P, k, dt):
        fixed = self._motion_one(k, dt)
        if fixed is not None:  # a built-in linear model: f(x) = F x
            F, Q = fixed
            PFt = P.dot(F.T)
            return _OnePrediction(F.dot(x), F.dot(PFt), Q, PFt)
        F = motion_jacobian(self.motion, x, k, dt)
        Q = np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float)
        if F.ndim != 2 or Q.ndim != 2:
            return None
        PFt = P.dot(F.T)
        return _OnePrediction(np.asarray(call_with_dt(self.motion.f, x, k, dt=dt), dtype=float), F.dot(PFt), Q, PFt)

    def _measure_one(self, x_pred, P_pred, k):
        H = measurement_jacobian(self.measurement, x_pred, k)
        if H.ndim != 2:
            return None
        PHt = P_pred.dot(H.T)
        return _OneMeasured(np.asarray(self.measurement.h(x_pred, k), dtype=float), H.dot(PHt), PHt, H)


@dataclass(frozen=True)
class KalmanFilter(ExtendedKalmanFilter):
    """Linear Kalman filter with Joseph-form update.

    Needs a linear motion model (``transition_matrix(k, dt)``) and a linear
    measurement model (``matrix(k)``).  While all runs share one covariance
    (same prior covariance, same missing-measurement pattern, a
    data-independent fading strategy) the Riccati recursion is computed once
    for the whole batch, which is exact and makes large batches cheap.
    """

    def __post_init__(self) -> None:
        super().__post_init__()
        if not callable(getattr(self.motion, "transition_matrix", None)):
            raise TypeError(
                f"KalmanFilter needs a linear motion model with transition_matrix(); "
                f"{type(self.motion).__name__} has none (use ExtendedKalmanFilter)"
            )
        if not callable(getattr(self.measurement, "matrix", None)):
            raise TypeError(
                f"KalmanFilter needs a linear measurement model with matrix(); "
                f"{type(self.measurement).__name__} has none (use ExtendedKalmanFilter)"
            )

    def _default_name(self) -> str:
        return "KF"

    def _predict(self, x, P, k, dt):
        F = np.asarray(call_with_dt(self.motion.transition_matrix, k, dt=dt), dtype=float)
        PFt = P @ F.T
        return _Prediction(mv(F, x), F @ PFt, np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float), PFt)

    def _measure(self, x_pred, P_pred, k):
        H = np.asarray(self.measurement.matrix(k), dtype=float)
        PHt = P_pred @ H.T
        return _Measured(mv(H, x_pred), H @ PHt, PHt, H)

    def _predict_one(self, x, P, k, dt):
        fixed = self._motion_one(k, dt)
        if fixed is None:
            F = np.asarray(call_with_dt(self.motion.transition_matrix, k, dt=dt), dtype=float)
            Q = np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float)
            if F.ndim != 2 or Q.ndim != 2:
                return None
        else:
            F, Q = fixed
        PFt = P.dot(F.T)
        return _OnePrediction(F.dot(x), F.dot(PFt), Q, PFt)

    def _measure_one(self, x_pred, P_pred, k):
        measurement = self.measurement
        # a built-in LinearGaussian's H is fixed and read-only: no call, no conversion
        H = measurement.H if type(measurement) is LinearGaussian else np.asarray(measurement.matrix(k), dtype=float)
        if H.ndim != 2:
            return None
        PHt = P_pred.dot(H.T)
        return _OneMeasured(H.dot(x_pred), H.dot(PHt), PHt, H)



# --------------------------------------------------------------------------
# sigma-point filters
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class _SigmaPointFilter(_GaussianFilter):
    compiled_path = "gaussian:SIGMA"

    def sigma_weights(self, n: int) -> tuple[float, np.ndarray, np.ndarray]:
        """Point scale c and mean / covariance weights ``(c, wm, wc)`` for an n-dimensional state.

        The points are x and x ± c·(columns of chol P), the centre first
        when the count is odd; the compiled step draws the same points.
        """
        raise NotImplementedError

    def _points(self, x, P):
        chi, wm, wc, repaired, _, _ = self._factored_points(x, P)
        return chi, wm, wc, repaired

    def _factored_points(self, x, P):
        """Sigma points and weights, with the Cholesky factor L and the unit points ξ (χ_p = x + L ξ_p)."""
        n = x.shape[-1]
        scale, wm, wc = self.sigma_weights(n)
        L, repaired = cholesky_psd(P)
        cols = scale * np.swapaxes(L, -1, -2)  # row j = scale * column j of L
        cols = np.broadcast_to(cols, (*x.shape[:-1], *cols.shape[-2:]))
        centre = x[..., None, :]
        parts = [centre + cols, centre - cols]
        unit = [scale * np.eye(n), -scale * np.eye(n)]
        if wm.shape[0] % 2:  # an odd count carries the centre point first
            parts.insert(0, centre)
            unit.insert(0, np.zeros((1, n)))
        return np.concatenate(parts, axis=-2), wm, wc, repaired, L, np.vstack(unit)

    def _predict(self, x, P, k, dt):
        fixed = self._motion_one(k, dt)
        if fixed is not None:
            # A built-in linear model, f(x) = F x: the unscented transform of a linear map is exact,
            # so its moments are the Kalman filter's F x, F P Fᵀ and P Fᵀ, without the points: a
            # third of a batched step.  Symmetrised as the points' sum is.
            F, Q = fixed
            PFt = P @ _t(F)
            mean = np.asarray(call_with_dt(self.motion.f, x, k, dt=dt), dtype=float)
            return _Prediction(mean, symmetrize(F @ PFt), Q, PFt)
        chi, wm, wc, repaired = self._points(x, P)
        Y = np.asarray(call_with_dt(self.motion.f, chi, k, dt=dt), dtype=float)
        mean = np.matmul(wm, Y)
        dY = Y - mean[..., None, :]
        dX = chi - x[..., None, :]
        propagated = symmetrize(_t(dY * wc[:, None]) @ dY)
        cross = _t(dX * wc[:, None]) @ dY
        Q = np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float)
        return _Prediction(mean, propagated, Q, cross, repaired)

    def _measure(self, x_pred, P_pred, k):
        chi, wm, wc, repaired, L, xi = self._factored_points(x_pred, P_pred)
        Z = np.asarray(self.measurement.h(chi, k), dtype=float)
        # Average residuals about the first point so that angles are
        # averaged on the circle, not across the ±π cut.
        Z0 = Z[..., :1, :]
        zp = Z0[..., 0, :] + np.matmul(wm, _residual(self.measurement, Z, Z0))
        # Contiguous, so that each run's small GEMMs below see the same layout whatever the batch
        # (a user's h may return runs as the fastest axis; a batch of one is always contiguous).
        dZ = np.ascontiguousarray(_residual(self.measurement, Z, zp[..., None, :]))
        dX = chi - x_pred[..., None, :]
        Pzz = _t(dZ * wc[:, None]) @ dZ
        Pxz = _t(dX * wc[:, None]) @ dZ
        # Statistical linearisation for the Joseph form.  With dX_i = L ξ_i and
        # Σ wc ξ ξᵀ = I:  G = Σ wc ξ_i dZ_iᵀ = L⁻¹ Pxz,  H = Pxzᵀ P⁻⁻¹ = Gᵀ L⁻¹,
        # and the residuals e_i = dZ_i − Gᵀ ξ_i give D = Σ wc e eᵀ = Pzz − H P⁻ Hᵀ
        # as a sum of outer products (positive semidefinite for wc ≥ 0).
        # One small GEMM per run (batch-invariant); a three-operand einsum costs about 6x more here.
        G = np.matmul(_t(xi * wc[:, None]), dZ)
        E = dZ - np.matmul(xi, G)
        D = _t(E * wc[:, None]) @ E
        E_root = E * np.sqrt(wc)[:, None] if np.all(wc >= 0) else None
        return _Measured(zp, Pzz, Pxz, None, repaired, D, L, G, E_root)

    def _points_one(self, x, P):
        """One run's sigma points ``χ (p, n)``, weights, L and the unit points ξ, or None where P does not factor."""
        n = x.shape[0]
        cache = self.__dict__.get("_one_run_points")
        if cache is None or cache[0] != n:
            scale, wm, wc = self.sigma_weights(n)
            unit = [scale * np.eye(n), -scale * np.eye(n)]
            if wm.shape[0] % 2:  # an odd count carries the centre point first
                unit.insert(0, np.zeros((1, n)))
            root = np.sqrt(wc)[:, None] if np.all(wc >= 0) else None
            cache = (n, wm, wc[:, None], np.vstack(unit), root)
            object.__setattr__(self, "_one_run_points", cache)  # per filter and state size: not a field
        _, wm, wc, xi, root = cache
        L = small_cholesky(P)
        if L is None:
            return None  # the general step repairs it and flags the run
        return x + xi.dot(L.T), wm, wc, L, xi, root

    def _predict_one(self, x, P, k, dt):
        fixed = self._motion_one(k, dt)
        if fixed is not None:  # a built-in linear model: exact without the points, as _predict
            F, Q = fixed
            PFt = P.dot(F.T)
            return _OnePrediction(F.dot(x), _sym(F.dot(PFt)), Q, PFt)
        pts = self._points_one(x, P)
        Q = np.asarray(call_with_dt(self.motion.cov, k, dt=dt), dtype=float)
        if pts is None or Q.ndim != 2:
            return None
        chi, wm, wc, _, _, _ = pts  # wc as a column (p, 1)
        Y = np.asarray(call_with_dt(self.motion.f, chi, k, dt=dt), dtype=float)
        mean = wm.dot(Y)
        dY = Y - mean
        dX = chi - x
        return _OnePrediction(mean, _sym((dY * wc).T.dot(dY)), Q, (dX * wc).T.dot(dY))

    def _measure_one(self, x_pred, P_pred, k):
        pts = self._points_one(x_pred, P_pred)
        if pts is None:
            return None
        chi, wm, wc, L, xi, root = pts
        Z = np.asarray(self.measurement.h(chi, k), dtype=float)
        Z0 = Z[:1]  # angles averaged about the first point, as _measure
        zp = Z0[0] + wm.dot(_residual(self.measurement, Z, Z0))
        dZ = _residual(self.measurement, Z, zp)
        dX = chi - x_pred
        G = (xi * wc).T.dot(dZ)
        E = dZ - xi.dot(G)
        return _OneMeasured(zp, (dZ * wc).T.dot(dZ), (dX * wc).T.dot(dZ), None, (E * wc).T.dot(E), L, G, None if root is None else E * root)

    def _linearize(self, pred, k):
        # Statistical linearisation about the unfaded prediction P̄ + Q:
        # H = Pxzᵀ P⁻¹ (exact for linear h).
        P_pred = pred.propagated + pred.Q
        Pxz = self._measure(pred.mean, P_pred, k).Pxz
        P_stack = np.broadcast_to(P_pred, (*Pxz.shape[:-2], *P_pred.shape[-2:]))
        return _t(np.linalg.solve(P_stack, Pxz))


@dataclass(frozen=True)
class UnscentedKalmanFilter(_SigmaPointFilter):
    """Unscented Kalman filter with the scaled unscented transform.

    Parameters
    ----------
    motion, measurement, fading, gate, name, backend
        As :class:`ExtendedKalmanFilter`.
    alpha, beta, kappa
        Sigma-point spread, prior-knowledge and secondary scaling parameters
        (defaults 1, 2, 0: weights are non-negative for any n).  ``kappa``
        must satisfy n + κ > 0 (checked at construction when the motion
        model has ``dim``).  With
        λ_ut = α²(n + κ) − n the points are x ± √(n + λ_ut)·(columns of
        chol P), W₀ᵐ = λ_ut/(n + λ_ut), W₀ᶜ = W₀ᵐ + 1 − α² + β,
        Wᵢ = 1/(2(n + λ_ut)).

    Notes
    -----
    Sigma points are redrawn from the predicted Gaussian before the
    measurement update.  With a built-in linear motion model (the
    kinematic models, :class:`~pursuit.models.LinearMotion`) the prediction
    is F x, F P Fᵀ + Q, which the unscented transform of a linear map gives
    exactly, and no points are drawn for it; a posterior covariance that is
    not positive definite is then repaired (and flagged) where the update's
    points need it, and a step that keeps the prediction keeps the repaired
    one.  A subclass's own ``sigma_weights`` must reproduce the mean and
    covariance (as every sigma-point rule does), since the prediction no
    longer reads them for these models.
    """

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        in_range("alpha", self.alpha, 0.0, 1.0e3, low_open=True)
        nonnegative("beta", self.beta)
        in_range("kappa", self.kappa, -1.0e6, 1.0e6)
        n = getattr(self.motion, "dim", None)  # a user's model may not say; sigma_weights checks again
        if isinstance(n, (int, np.integer)) and not n + self.kappa > 0:
            raise ValueError(
                f"kappa: must exceed -n = {-n} for the {n}-dimensional state (n + kappa > 0 keeps the sigma points real), got {self.kappa!r}"
            )

    def _default_name(self) -> str:
        return "UKF"

    def sigma_weights(self, n):
        lam = self.alpha**2 * (n + self.kappa) - n
        c = n + lam
        if c <= 0:
            raise ValueError(f"UKF: alpha={self.alpha}, kappa={self.kappa} give n + lambda = {c:.3g} <= 0 for n = {n}")
        wm = np.full(2 * n + 1, 0.5 / c)
        wc = wm.copy()
        wm[0] = lam / c
        wc[0] = lam / c + 1.0 - self.alpha**2 + self.beta
        return np.sqrt(c), wm, wc


@dataclass(frozen=True)
class CubatureKalmanFilter(_SigmaPointFilter):
    """Cubature Kalman filter (third-degree spherical-radial rule).

    ``2n`` points x ± √n·(columns of chol P), each with weight 1/(2n).  As
    for :class:`UnscentedKalmanFilter`, a built-in linear motion model is
    predicted exactly (F x, F P Fᵀ + Q) without points.
    """

    def _default_name(self) -> str:
        return "CKF"

    def sigma_weights(self, n):
        w = np.full(2 * n, 0.5 / n)
        return np.sqrt(n), w, w


_ONE_RUN_TYPES = frozenset({KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter, CubatureKalmanFilter})
"""The filters whose step takes the one-run path (a subclass may override a hook: it takes the general step)."""
