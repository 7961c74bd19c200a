"""Current-statistical (CS) model filters: standard CS, parameter-adaptive CS (APCS), modified Singer (MS).

All three filter every axis separately, as paper P4 does: the state is a
stack of ``[p, v, a]`` axes (``[x, vx, ax, y, vy, ay, ...]``), each measured
in position by one row of a linear measurement model with diagonal noise.
Per step each axis forms its own prediction, with a process noise, maneuver
frequency α or fading coefficient λ chosen from the data, and then goes
through the shared Kalman update of :func:`pursuit.filters.gaussian.linear_update`
(Joseph form, missing components, the standard info keys).  The axes are a
batch axis: the filters are vectorised over runs *and* axes.

Info keys beyond the standard ones (innovation, S, nis, dof, loglik, which
cover all axes together, S being diagonal):

``fading`` (*b,)
    Largest λ over the axes; ``axis_fading`` (*b, A) per axis.
``alpha`` (*b, A)
    Maneuver frequency used in the prediction.
``sigma_a2`` (*b, A)
    Acceleration variance used in Q.
``maneuver``, ``maneuver_stat`` (*b, A)
    APCS only: the detection flag and D = ν²/S of the nominal prediction.
``gated`` (*b,)
    True where the χ² gate (``gate=p``) rejected the step's measurement.
``repaired`` (*b,)
    Always False: these filters factorise no covariance, so there is
    nothing to repair (the key is there for uniformity).

**Gating.**  With ``gate=p`` a step whose NIS (summed over the measured
axes) exceeds the χ²(dof) quantile ``p``, dof the number of measured axes,
is not used: as in every Gaussian filter the estimate is the prediction
(``pred_mean``, ``pred_cov``) and ``innovation``, ``S``, ``nis``, ``dof``,
``loglik`` describe the rejected measurement.  The adaptive quantities learn
nothing from it: APCS keeps its σ_a² and strong-tracking memory V, MS its
autocorrelations, as for a missing measurement.  The gate acts on the
innovation of the prediction actually used, after APCS's adaptation: on a
detected axis the strong-tracking λ makes S about as large as the memory V,
which has just taken in ν², so that axis's NIS stays below about 1 + ρ and
the gate rejects little there (an outlier and a maneuver onset look the same
in one step).

The CS prediction ``F x + U ā`` with ā = â(k|k) is exactly the
constant-acceleration extrapolation, while the covariance is propagated with
the Singer F: ``P⁻ = λ F P Fᵀ + Q``.  ``cross_cov`` is ``P Fᵀ``.

**One run without a batch axis** (batch ``()``, a target stepped from
Python) takes :meth:`_AxisFilter._one_run_step`: the same hooks on ``(A, 3)``
stacks, the scalar update of each axis written out, and F, U, q for α that
differ between axes from :func:`_matrices_one_run`.  It agrees with the
general step to round-off; every batch, ``(1,)`` included, takes the general
step, so that a run has the same bits alone as inside a larger batch.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from math import factorial
from typing import Any

import numpy as np

from .._chi2 import chi2_isf
from .._linalg import symmetrize
from .._validation import in_range, measurement_for_step, nonnegative, positive, time_step
from ..gaussian import Gaussian
from ..models.maneuver import (
    _PHI_TERMS,
    _Q_SERIES_MAX,
    _Q_TERMS,
    CS_VARIANCE_FACTOR,
    _q_series_coefficients,
    cs_variance,
    exp_correlated_input,
    exp_correlated_noise,
    exp_correlated_transition,
)
from ..rng import RNGLike
from .base import FilterBase, as_gaussian, prior_batch
from .gating import gate_exceeded
from .gaussian import _checked_measurement, _sandwich, linear_update

__all__ = [
    "AxisState",
    "CurrentStatisticalFilter",
    "AdaptiveCSFilter",
    "ModifiedSingerFilter",
    "chi2_threshold",
]

_H_AXIS = np.array([[1.0, 0.0, 0.0]])
_H_AXIS.setflags(write=False)
_LOG_2PI = float(np.log(2.0 * np.pi))


def check_adaptation_params(f: Any) -> None:
    """Check (and store converted) the APCS adaptation parameters of ``f``, a frozen dataclass.

    ``c_a``, ``sigma_a``, ``sigma_min``, ``sigma_max``, ``rho``, ``beta_s``, ``alpha_cap`` (at least
    ``alpha0``): shared by :class:`AdaptiveCSFilter` and the joint
    :class:`~pursuit.filters.cs_nonlinear.NonlinearCSFilter`; raises ``ValueError`` naming the field.
    """
    object.__setattr__(f, "c_a", positive("c_a", f.c_a))
    object.__setattr__(f, "sigma_a", nonnegative("sigma_a", f.sigma_a))
    object.__setattr__(f, "sigma_min", nonnegative("sigma_min", f.sigma_min))
    if f.sigma_max is not None:
        object.__setattr__(f, "sigma_max", positive("sigma_max", f.sigma_max))
        if f.sigma_max < f.sigma_min:
            raise ValueError(f"sigma_max: must be at least sigma_min = {f.sigma_min}, got {f.sigma_max}")
    object.__setattr__(f, "rho", in_range("rho", f.rho, 0.0, 1.0))
    object.__setattr__(f, "beta_s", in_range("beta_s", f.beta_s, 1.0, np.inf, high_open=True))
    object.__setattr__(f, "alpha_cap", positive("alpha_cap", f.alpha_cap))
    if f.alpha_cap < f.alpha0:
        raise ValueError(f"alpha_cap: must be at least alpha0 = {f.alpha0}, got {f.alpha_cap}")


def chi2_threshold(p: float, dof: int = 1) -> float:
    """The χ² threshold M with P{D > M} = p for D ~ χ²(dof) (p = 0.1, 1 dof: 2.706)."""
    in_range("false_alarm", p, 0.0, 1.0, low_open=True, high_open=True)
    return float(chi2_isf(p, dof))


@dataclass(frozen=True)
class AxisState:
    """State of a per-axis CS-family filter.

    Attributes
    ----------
    mean, cov
        ``(*b, n)`` and ``(*b, n, n)``, block diagonal over the axes.
    k
        Last step processed.
    memory
        The filter's adaptive quantities, arrays of shape ``(*b, A)``.
    """

    mean: np.ndarray
    cov: np.ndarray
    k: int = 0
    memory: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def batch(self) -> tuple[int, ...]:
        """Batch shape."""
        return self.mean.shape[:-1]


@dataclass(frozen=True)
class _AxisNoise:
    """Measurement noise of A independent scalar position measurements, ``(A, 1, 1)``."""

    R: np.ndarray

    def cov(self, k: int | None = None) -> np.ndarray:
        return self.R


@lru_cache(maxsize=256)
def _matrices(alpha: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, U and unit q for one (α, T), cached for the filters with a fixed α."""
    out = (exp_correlated_transition(3, alpha, dt), exp_correlated_input(3, alpha, dt), exp_correlated_noise(3, alpha, dt))
    for a in out:
        a.setflags(write=False)
    return out


def _matrices_for(alpha: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, U, q for an array of α: cached when all are equal (the usual case), else computed per element."""
    alpha = np.asarray(alpha, dtype=float)
    flat = alpha.reshape(-1)
    if flat.size and np.all(flat == flat[0]):
        F, U, q = _matrices(float(flat[0]), dt)
        return (
            np.broadcast_to(F, (*alpha.shape, 3, 3)),
            np.broadcast_to(U, (*alpha.shape, 3)),
            np.broadcast_to(q, (*alpha.shape, 3, 3)),
        )
    return exp_correlated_transition(3, alpha, dt), exp_correlated_input(3, alpha, dt), exp_correlated_noise(3, alpha, dt)


@lru_cache(maxsize=1)
def _series_tables() -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of φ_p(−x), p = 0..3, and of q / T^E as polynomials in x, lowest power first.

    ``(_PHI_TERMS, 4)`` with entries ``(−1)^m / (m + p)!`` and ``(_Q_TERMS, 9)``
    (the series of :mod:`pursuit.models.maneuver`, flattened).
    """
    C = np.array([[(-1.0) ** m / factorial(m + p) for p in range(4)] for m in range(_PHI_TERMS)])
    coef, _ = _q_series_coefficients(3)
    Cq = np.ascontiguousarray(coef[::-1].reshape(_Q_TERMS, 9))
    for a in (C, Cq):
        a.setflags(write=False)
    return C, Cq


@lru_cache(maxsize=64)
def _period_tables(dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What F, U and q take from T alone: the integrator chain, ``T^p_i`` (p = 2, 1, 0), ``T^E`` and the powers 0..39."""
    _, E = _q_series_coefficients(3)
    chain = np.array([[1.0, dt, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    out = (chain, dt ** np.array([2.0, 1.0, 0.0]), (dt**E).reshape(9), np.arange(_PHI_TERMS, dtype=float))
    for a in out:
        a.setflags(write=False)
    return out


def _matrices_one_run(alpha: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_matrices_for` of the axes of one run, ``alpha`` ``(A,)``, without a Python loop over series terms.

    Equal α: the cached matrices, shared.  Different α with every αT ≤ 1
    (the series range of q; APCS's detections and MS's estimates with the
    default caps): the series of :mod:`pursuit.models.maneuver` evaluated as
    one product of the powers of αT with the coefficient tables, instead of
    a Horner loop of NumPy calls per term; round-off apart the same numbers
    (a few ulps: the series alternate with fast-falling terms).  Larger αT:
    :func:`_matrices_for`.
    """
    a = alpha.tolist()
    if a.count(a[0]) == len(a):
        return _matrices(float(a[0]), dt)
    x = alpha * dt
    if max(a) * dt > _Q_SERIES_MAX:
        return _matrices_for(alpha, dt)
    C, Cq = _series_tables()
    chain, Tp, TE, m = _period_tables(dt)
    pw = np.power(x[:, None], m)  # (A, 40): x^m
    phi = pw.dot(C)  # φ_p(−x), (A, 4)
    F = np.empty((x.shape[0], 3, 3))
    F[:] = chain
    F[:, :, 2] = phi[:, 2::-1] * Tp  # T^p_i φ_p_i
    U = phi[:, 3:0:-1] * Tp * x[:, None]  # T^p_i x φ_(p_i + 1)
    q = (pw[:, :_Q_TERMS].dot(Cq) * TE).reshape(-1, 3, 3)
    return F, U, 0.5 * (q + _t(q))


def _t(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


@lru_cache(maxsize=1)
def _eye3() -> np.ndarray:
    out = np.eye(3)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class _AxisFilter(FilterBase):
    """Shared machinery: axis layout from the measurement model, split and join, info.

    NumPy only: ``backend="numba"`` warns and computes with NumPy.
    """

    measurement: Any
    dt: float = 1.0
    gate: float | None = field(default=None, kw_only=True)

    warn_on_default_backend = False  # no compiled path at all: a process-wide numba default is not a request

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", positive("dt", self.dt))
        if self.gate is not None:
            object.__setattr__(self, "gate", in_range("gate", self.gate, 0.0, 1.0, low_open=True, high_open=True))
        matrix = getattr(self.measurement, "matrix", None)
        if not callable(matrix) or not callable(getattr(self.measurement, "cov", None)):
            raise TypeError(
                f"{type(self).__name__} needs a linear position measurement with matrix() and cov(); "
                f"{type(self.measurement).__name__} has none"
            )
        H = np.asarray(matrix(None), dtype=float)
        if H.ndim != 2:
            raise ValueError(f"measurement: H must be a matrix, got shape {H.shape}")
        m, n = H.shape
        pos = []
        for r, row in enumerate(H):
            nz = np.flatnonzero(row)
            if nz.size != 1 or row[nz[0]] != 1.0:
                raise ValueError(
                    f"measurement: row {r} of H must select one position component with coefficient 1 "
                    "(CS-model filters measure each axis's position)"
                )
            pos.append(int(nz[0]))
        idx = np.array([[p, p + 1, p + 2] for p in pos])
        if n != 3 * m or sorted(idx.reshape(-1).tolist()) != list(range(n)):
            raise ValueError(
                f"measurement: the state must be [p, v, a] per measured axis (n = 3·m); "
                f"H is {m}x{n} and measures components {pos}"
            )
        self._check_R(np.asarray(self.measurement.cov(None), dtype=float))
        object.__setattr__(self, "_idx", idx)
        super().__post_init__()

    @staticmethod
    def _check_R(R: np.ndarray) -> np.ndarray:
        d = np.diag(R)
        if np.count_nonzero(R - np.diag(d)) or np.any(d <= 0):
            raise ValueError("measurement: R must be diagonal with positive variances (axes are filtered separately)")
        return d

    @property
    def axes(self) -> int:
        """Number of axes A."""
        return self._idx.shape[0]

    # -- layout -------------------------------------------------------------
    def _split(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = self._idx
        # Contiguous copies: einsum's summation order follows the memory
        # layout, and fancy indexing returns a transposed one; a run's
        # result must not depend on the batch it is in.
        return (
            np.ascontiguousarray(mean[..., idx]),
            np.ascontiguousarray(cov[..., idx[:, :, None], idx[:, None, :]]),
        )

    def _join(self, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = self._idx
        n = idx.size
        mean = np.empty((*x.shape[:-2], n))
        mean[..., idx] = x
        cov = np.zeros((*x.shape[:-2], n, n))
        cov[..., idx[:, :, None], idx[:, None, :]] = P
        return mean, cov

    # -- protocol -------------------------------------------------------------
    def init(self, prior: Gaussian, batch: tuple[int, ...] = (), rng: RNGLike = None) -> AxisState:
        """Initial state from a Gaussian prior; covariances between axes are ignored."""
        prior = as_gaussian(prior)
        batch = prior_batch(prior, batch)
        if prior.dim != self._idx.size:
            raise ValueError(f"prior: state dimension {prior.dim} does not match the measurement's {self._idx.size}")
        mean, cov = prior.broadcast(batch)
        x, P = self._split(mean, cov)
        mean, cov = self._join(x, P)
        return AxisState(mean, cov, 0, self._init_memory(x, P))

    def step(
        self, state: AxisState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[AxisState, dict[str, np.ndarray]]:
        """One predict-update cycle on every axis with measurement ``z`` (``(*b, A)``; NaN = missing)."""
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        T = float(self.dt if dt is None else dt)
        if not state.batch and type(self)._predict.__module__ == __name__:
            # One run without a batch axis.  A batch (1,) keeps the general step: its bits must equal
            # those of the same run in a larger batch (a Monte Carlo chunk of one run, an IMM's mixture),
            # and the one-run maths agrees with them to round-off only.  A subclass with its own
            # _predict hook keeps the general step too: the one-run step passes the hook an argument
            # (the matrices' routine) that a hook written for the general step does not take.
            return self._one_run_step(state, z, k, T)
        return self._general_step(state, z, k, T)

    def _general_step(
        self, state: AxisState, z: np.ndarray, k: int, T: float
    ) -> tuple[AxisState, dict[str, np.ndarray]]:
        """:meth:`step` for any batch: the axes are a batch axis of :func:`linear_update`."""
        batch = state.batch
        z = measurement_for_step(z, batch, self.axes, k)
        r = self._check_R(np.asarray(self.measurement.cov(k), dtype=float))
        x, P = self._split(state.mean, state.cov)
        za = z[..., :, None]
        measured = ~np.isnan(z)

        pred = self._predict(state.memory, x, P, z, measured, r, T)
        x_upd, P_upd, ainfo = linear_update(pred.mean, pred.cov, za, _H_AXIS, _AxisNoise(r[:, None, None]), k)
        info = _combine_axes(ainfo, batch)
        gated = np.zeros(batch, dtype=bool)
        if self.gate is not None:
            gated = gate_exceeded(self.gate, info["nis"], info["dof"], self.axes)
            if gated.any():  # the prediction, in the axes' layout
                x_upd = np.where(gated[..., None, None], pred.mean, x_upd)
                P_upd = np.where(gated[..., None, None, None], pred.cov, P_upd)
        memory = self._learn(pred.memory, x, pred.mean, x_upd, measured & ~gated[..., None], T)

        mean, cov = self._join(x_upd, P_upd)
        pred_mean, pred_cov = self._join(pred.mean, pred.cov)
        lam = np.broadcast_to(pred.lam, (*batch, self.axes))
        info["fading"] = lam.max(axis=-1)
        info["axis_fading"] = lam
        info["alpha"] = np.broadcast_to(pred.alpha, (*batch, self.axes))
        info["sigma_a2"] = np.broadcast_to(pred.sigma2, (*batch, self.axes))
        info["gated"] = gated
        info["repaired"] = np.zeros(batch, dtype=bool)  # nothing here factorises a covariance
        info.update(pred.info)
        info["pred_mean"] = pred_mean
        info["pred_cov"] = pred_cov
        info["cross_cov"] = self._join(x, P @ _t(pred.F))[1]
        return AxisState(mean, cov, k, memory), info

    def _one_run_step(
        self, state: AxisState, z: np.ndarray, k: int, T: float
    ) -> tuple[AxisState, dict[str, np.ndarray]]:
        """:meth:`_general_step` for one run without a batch axis: the same maths on ``(A, 3)`` and ``(A, 3, 3)`` stacks.

        The prediction and the adaptation are the subclass's own hooks
        (with :func:`_matrices_one_run` for α that differ between axes); the
        update of each axis's scalar position measurement is written out
        (S = P⁻₀₀ + r, K = P⁻[:, 0] / S, the Joseph form through
        :func:`~pursuit.filters.gaussian._sandwich` as in
        :func:`linear_update`), without :func:`linear_update`'s masks and
        broadcasts.  Same info keys, shapes and dtypes, same numbers to
        round-off.
        """
        if not _checked_measurement(z, (), self.measurement):
            z = measurement_for_step(z, (), self.axes, k)
        r = _axis_variances(np.asarray(self.measurement.cov(k), dtype=float))
        idx = self._idx
        x, P = state.mean[idx], state.cov[idx[:, :, None], idx[:, None, :]]
        measured = ~np.isnan(z)

        pred = self._predict(state.memory, x, P, z, measured, r, T, _matrices_one_run)
        x_pred, P_pred = pred.mean, pred.cov
        # A missing axis: zero innovation and gain, unit variance (as linear_update's masks).
        S = np.where(measured, P_pred[:, 0, 0] + r, 1.0)
        nu_full = z - x_pred[:, 0]
        nu = np.where(measured, nu_full, 0.0)
        K = P_pred[:, :, 0] * (measured / S)[:, None]
        x_upd = x_pred + K * nu[:, None]
        I_KH = np.empty_like(P_pred)
        I_KH[:] = _eye3()
        I_KH[:, :, 0] -= K
        P_upd = _sandwich(I_KH, P_pred) + (r * K)[:, :, None] * K[:, None, :]
        P_upd = symmetrize(np.where(measured[:, None, None], P_upd, P_pred))
        nis_a = nu * nu / S
        dof = measured.sum()
        nis = np.where(measured, nis_a, 0.0).sum() if dof else np.float64(np.nan)
        loglik = np.where(measured, -0.5 * (nis_a + np.log(S) + _LOG_2PI), 0.0).sum()
        gated = np.array(False)
        if self.gate is not None:
            gated = gate_exceeded(self.gate, nis, dof, self.axes)
            if gated:  # the prediction, in the axes' layout
                x_upd, P_upd = x_pred, P_pred
        memory = self._learn(pred.memory, x, x_pred, x_upd, measured & ~gated, T)

        mean, cov = self._join(x_upd, P_upd)
        pred_mean, pred_cov = self._join(x_pred, P_pred)
        A = self.axes
        lam = _per_axis(pred.lam, A)
        S_mat = np.zeros((A, A))
        S_mat.flat[:: A + 1] = S
        info = {
            "innovation": np.where(measured, nu_full, np.nan),
            "S": S_mat,
            "nis": np.asarray(nis),
            "dof": np.asarray(dof),
            "loglik": np.asarray(loglik),
            "fading": lam.max(),
            "axis_fading": lam,
            "alpha": _per_axis(pred.alpha, A),
            "sigma_a2": _per_axis(pred.sigma2, A),
            "gated": gated,
            "repaired": np.array(False),
            **pred.info,
            "pred_mean": pred_mean,
            "pred_cov": pred_cov,
            "cross_cov": self._join(x, P @ _t(pred.F))[1],
        }
        return AxisState(mean, cov, k, memory), info

    # -- hooks --------------------------------------------------------------------
    def _init_memory(self, x: np.ndarray, P: np.ndarray) -> dict[str, np.ndarray]:
        return {}

    def _predict(self, memory, x, P, z, measured, r, T, matrices=None) -> "_AxisPrediction":
        """The prediction of every axis; ``matrices(alpha, T)`` gives F, U, q for per-axis α (default :func:`_matrices_for`)."""
        raise NotImplementedError

    def _learn(self, memory, x_prev, x_pred, x_upd, measured, T) -> dict[str, np.ndarray]:
        """Memory for the next step; ``measured`` (*b, A) is False where the axis had no (accepted) measurement."""
        return memory


def _per_axis(v: Any, A: int) -> np.ndarray:
    """``np.broadcast_to(v, (A,))`` of one run without the broadcast machinery for an ``(A,)`` array."""
    return v if type(v) is np.ndarray and v.shape == (A,) else np.full(A, v)


def _axis_variances(R: np.ndarray) -> np.ndarray:
    """:meth:`_AxisFilter._check_R` of one ``(A, A)`` matrix, remembered by its bytes (R is usually one constant matrix)."""
    if R.ndim != 2:
        return _AxisFilter._check_R(R)
    return _axis_variances_of(R.tobytes(), R.shape[0])


@lru_cache(maxsize=64)
def _axis_variances_of(data: bytes, A: int) -> np.ndarray:
    r = _AxisFilter._check_R(np.frombuffer(data).reshape(A, A)).copy()
    r.setflags(write=False)
    return r


@dataclass(frozen=True)
class _AxisPrediction:
    mean: np.ndarray  # (*b, A, 3)
    cov: np.ndarray  # (*b, A, 3, 3)
    F: np.ndarray  # the Singer F used for P (for cross_cov)
    lam: np.ndarray
    alpha: np.ndarray
    sigma2: np.ndarray
    memory: dict[str, np.ndarray]
    info: dict[str, np.ndarray] = field(default_factory=dict)


def _combine_axes(ainfo: dict[str, np.ndarray], batch: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Per-axis info ``(*b, A, ...)`` to the standard keys of the whole measurement.

    The axes are independent and R is diagonal, so S is diagonal, NIS and
    log-likelihood are sums over the measured axes.
    """
    dof_a = np.broadcast_to(ainfo["dof"], (*batch, ainfo["dof"].shape[-1]))
    measured = dof_a > 0
    dof = dof_a.sum(axis=-1)
    nis = np.where(measured, ainfo["nis"], 0.0).sum(axis=-1)
    S_diag = ainfo["S"][..., 0, 0]
    S = np.zeros((*S_diag.shape, S_diag.shape[-1]))
    i = np.arange(S_diag.shape[-1])
    S[..., i, i] = S_diag
    return {
        "innovation": ainfo["innovation"][..., 0],
        "S": S,
        "nis": np.where(dof > 0, nis, np.nan),
        "dof": dof,
        "loglik": ainfo["loglik"].sum(axis=-1),
    }


def _acceleration_mean(x: np.ndarray, mean: str) -> np.ndarray:
    return x[..., 2] if mean == "current" else np.zeros(x.shape[:-1])


def _check_mean(mean: str) -> None:
    if mean not in ("current", "zero"):
        raise ValueError(f"mean: must be 'current' (CS, ā = â(k|k)) or 'zero' (Singer), got {mean!r}")


def _propagate(F, U, q, x, P, a_bar, sigma2, alpha, lam=1.0):
    """x⁻ = F x + U ā and P⁻ = λ F P Fᵀ + 2ασ² q on stacks of axes."""
    x_pred = np.einsum("...ij,...j->...i", F, x) + U * a_bar[..., None]
    FPFt = F @ P @ _t(F)
    Q = (2.0 * np.asarray(alpha) * sigma2)[..., None, None] * q
    lam = np.asarray(lam, dtype=float)
    P_pred = (lam[..., None, None] if lam.ndim else lam) * FPFt + Q
    return x_pred, 0.5 * (P_pred + _t(P_pred)), FPFt, Q


# --------------------------------------------------------------------------
# standard CS filter
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class CurrentStatisticalFilter(_AxisFilter):
    """The standard current-statistical (CS) model Kalman filter (Zhou Hongren), per axis.

    Each step, with ā = â(k|k):
    ``σ_a² = (4 − π)/π (a_max − ā)²`` (ā > 0; ``(a_−max + ā)²`` for ā < 0,
    ``a_max²`` at 0), ``x⁻ = F x + U ā``, ``P⁻ = F P Fᵀ + 2ασ_a² q``, then the
    Kalman update.

    Parameters
    ----------
    measurement
        Linear position measurement of each axis (rows of H select the
        positions of ``[p, v, a]`` axes; R diagonal).
    dt
        Sampling period T (s).
    alpha
        Maneuver frequency α (1/s); paper P4 uses 0.001.
    a_max, a_neg_max
        Acceleration limits (m/s²), magnitudes; ``a_neg_max`` defaults to
        ``a_max``.
    sigma_min
        Floor on σ_a (m/s²); the default 0 applies the formula as written.
    mean
        ``"current"``: ā = â(k|k) (the CS model); ``"zero"``: ā = 0 (a
        Singer filter with the CS variance).
    name
        Label in results (keyword only).
    gate
        χ² gate probability in (0, 1), keyword only: a step whose NIS
        exceeds the χ²(dof) quantile ``gate`` only predicts and is flagged
        in ``gated`` (see the module notes).  Default: no gate.
    backend
        Keyword only; NumPy only (``"numba"`` warns and computes with NumPy).
    """

    alpha: float = 0.001
    a_max: float = 100.0
    a_neg_max: float | None = None
    sigma_min: float = 0.0
    mean: str = "current"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "alpha", positive("alpha", self.alpha))
        object.__setattr__(self, "a_max", positive("a_max", self.a_max))
        if self.a_neg_max is not None:
            object.__setattr__(self, "a_neg_max", positive("a_neg_max", self.a_neg_max))
        object.__setattr__(self, "sigma_min", nonnegative("sigma_min", self.sigma_min))
        _check_mean(self.mean)

    def _default_name(self) -> str:
        return "CS"

    def _predict(self, memory, x, P, z, measured, r, T, matrices=_matrices_for):
        a_bar = _acceleration_mean(x, self.mean)
        sigma2 = np.maximum(cs_variance(x[..., 2], self.a_max, self.a_neg_max), self.sigma_min**2)
        F, U, q = _matrices(self.alpha, T)
        x_pred, P_pred, _, _ = _propagate(F, U, q, x, P, a_bar, sigma2, self.alpha)
        return _AxisPrediction(x_pred, P_pred, F, np.float64(1.0), np.float64(self.alpha), sigma2, memory)


# --------------------------------------------------------------------------
# parameter-adaptive CS filter (paper P4)
# --------------------------------------------------------------------------
_VARIANCE_LAWS = ("displacement", "linear", "rayleigh", "fixed")
_FADING_RULES = ("stf", "ratio", "none")
_ALPHA_RULES = ("ratio", "fading", "none")


@dataclass(frozen=True)
class AdaptiveCSFilter(_AxisFilter):
    """Parameter-adaptive CS filter (APCS) of paper P4, per axis.

    Per step and axis (docs/spec/04-adaptive-cs-model.md §2.5):

    1. ā = â(k|k); x⁻ = F x + U ā (the constant-acceleration extrapolation).
    2. Nominal prediction with α0, λ = 1 and Q from the current σ_a²:
       ``D = ν² / S0`` (ν = z − x⁻_p, ``S0 = (F P Fᵀ + Q0)_pp + r``).
    3. ``D > M`` means a strong maneuver: λ from the strong-tracking rule and
       α raised (``min(α0 D/M, α_cap)``); else λ = 1, α = α0.  Then
       ``P⁻ = λ F(α) P F(α)ᵀ + Q(α, σ_a²)`` and the Kalman update.
    4. σ_a² for the next step from the displacement correction
       ``Δx = x̂(k|k)_p − x̂(k|k−1)_p``: ``(4 − π)/π (2Δx/T²)²`` clipped to
       ``[σ_min², σ_max²]``.  The STF memory V is updated every measured step.

    Parameters
    ----------
    measurement, dt, name, gate, backend
        As :class:`CurrentStatisticalFilter`.
    alpha0
        Maneuver frequency without a maneuver (paper: 0.001 1/s).
    a_max
        Initial acceleration limit (m/s²): σ_a² at start-up is the CS
        variance at â(0|0).  Also the limit of ``variance="rayleigh"``.
    threshold
        Detection threshold M on D (paper: 3).  Ignored when
        ``false_alarm`` is given.
    false_alarm
        Alternatively, the false-alarm probability p; M = χ²₁⁻¹(1 − p).
    variance
        σ_a² law: ``"displacement"`` (default, (4 − π)/π Δa²),
        ``"linear"`` (``c_a * abs(Δa)``), ``"rayleigh"`` (the standard CS variance
        at ā, i.e. no displacement adaptation), ``"fixed"`` (``sigma_a²``).
    c_a
        Slope of the ``"linear"`` law (m/s²).
    sigma_a
        σ_a of the ``"fixed"`` law (m/s²).
    sigma_min, sigma_max
        Clipping of σ_a (m/s²); ``sigma_max=None`` means no upper limit.
    fading
        λ on detection: ``"stf"`` (strong-tracking trace ratio, the
        default), ``"ratio"`` (D/M) or ``"none"`` (λ = 1).
    rho, beta_s
        STF forgetting factor and weakening factor.
    alpha_rule
        α on detection: ``"ratio"`` (α0 D/M, default), ``"fading"``
        (λ α0) or ``"none"`` (α0).
    alpha_cap
        Upper limit of α (1/s).
    mean
        ``"current"`` (CS) or ``"zero"`` (Singer prediction, no input).
    """

    alpha0: float = 0.001
    a_max: float = 100.0
    threshold: float = 3.0
    false_alarm: float | None = None
    variance: str = "displacement"
    c_a: float = 1.0
    sigma_a: float = 1.0
    sigma_min: float = 0.1
    sigma_max: float | None = None
    fading: str = "stf"
    rho: float = 0.95
    beta_s: float = 1.0
    alpha_rule: str = "ratio"
    alpha_cap: float = 1.0
    mean: str = "current"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "alpha0", positive("alpha0", self.alpha0))
        object.__setattr__(self, "a_max", positive("a_max", self.a_max))
        if self.false_alarm is not None:
            object.__setattr__(self, "threshold", chi2_threshold(self.false_alarm))
        object.__setattr__(self, "threshold", positive("threshold", self.threshold))
        for name, allowed in (("variance", _VARIANCE_LAWS), ("fading", _FADING_RULES), ("alpha_rule", _ALPHA_RULES)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: must be one of {', '.join(map(repr, allowed))}, got {getattr(self, name)!r}")
        check_adaptation_params(self)
        _check_mean(self.mean)

    def _default_name(self) -> str:
        return "APCS"

    def _clip(self, s2: np.ndarray) -> np.ndarray:
        hi = np.inf if self.sigma_max is None else self.sigma_max**2
        return np.clip(s2, self.sigma_min**2, hi)

    def _init_memory(self, x, P):
        if self.variance == "fixed":
            s2 = np.full(x.shape[:-1], self.sigma_a**2)
        else:
            s2 = self._clip(cs_variance(x[..., 2], self.a_max))
        return {"sigma2": s2, "V": np.full(x.shape[:-1], np.nan)}

    def _predict(self, memory, x, P, z, measured, r, T, matrices=_matrices_for):
        a_bar = _acceleration_mean(x, self.mean)
        if self.variance == "rayleigh":
            sigma2 = self._clip(cs_variance(x[..., 2], self.a_max))
        else:
            sigma2 = memory["sigma2"]
        F0, U0, q0 = _matrices(self.alpha0, T)
        x0, P0, FPFt0, Q0 = _propagate(F0, U0, q0, x, P, a_bar, sigma2, self.alpha0)
        nu = np.where(measured, z - x0[..., 0], 0.0)
        D = np.where(measured, nu * nu / (P0[..., 0, 0] + r), np.nan)
        detect = measured & (D > self.threshold)

        # Strong-tracking memory V of ν², kept every measured step (stored by _learn, so that a
        # measurement the gate rejects leaves no trace).
        V_old = memory["V"]
        V = np.where(np.isnan(V_old), nu * nu, (self.rho * V_old + nu * nu) / (1.0 + self.rho))
        V = np.where(measured, V, V_old)

        ratio = np.where(detect, D / self.threshold, 1.0)
        # The scalar STF of paper P4, per axis and only on detection.  Not
        # fading_adaptive.StrongTracking: that one averages as (1 − d)V + dν² (other
        # rounding than (ρV + ν²)/(1 + ρ) above) and bounds λ by λ_max and the
        # conditioning ceiling, so sharing it would change APCS's results.
        if self.fading == "stf":
            N = V - Q0[..., 0, 0] - self.beta_s * r
            lam = np.where(detect, np.maximum(1.0, N / FPFt0[..., 0, 0]), 1.0)
        elif self.fading == "ratio":
            lam = ratio
        else:
            lam = np.ones_like(ratio)
        if self.alpha_rule == "ratio":
            alpha = np.minimum(self.alpha0 * ratio, self.alpha_cap)
        elif self.alpha_rule == "fading":
            alpha = np.minimum(self.alpha0 * lam, self.alpha_cap)
        else:
            alpha = np.full(ratio.shape, self.alpha0)

        if matrices is _matrices_one_run and not detect.any():
            # Nothing adapted (λ = 1, α = α0): the nominal prediction is the prediction, bit for bit.  Only
            # in the step of one run: a batch's F is a broadcast view, whose products may round otherwise.
            F, x_pred, P_pred = F0, x0, P0
        else:
            F, U, q = matrices(alpha, T)
            x_pred, P_pred, _, _ = _propagate(F, U, q, x, P, a_bar, sigma2, alpha, lam)
        memory = {**memory, "V_step": V}
        info = {"maneuver": detect, "maneuver_stat": D}
        return _AxisPrediction(x_pred, P_pred, F, lam, alpha, sigma2, memory, info)

    def _learn(self, memory, x_prev, x_pred, x_upd, measured, T):
        V = np.where(measured, memory["V_step"], memory["V"])
        if self.variance in ("rayleigh", "fixed"):
            return {"sigma2": memory["sigma2"], "V": V}
        da = 2.0 * (x_upd[..., 0] - x_pred[..., 0]) / (T * T)
        if self.variance == "displacement":
            s2 = CS_VARIANCE_FACTOR * da * da
        else:
            s2 = self.c_a * np.abs(da)
        s2 = np.where(measured, self._clip(s2), memory["sigma2"])
        return {"sigma2": s2, "V": V}


# --------------------------------------------------------------------------
# modified Singer filter
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class ModifiedSingerFilter(_AxisFilter):
    """Modified Singer (MS) filter: Singer model with α and σ_m² estimated online, per axis.

    The acceleration estimate is treated as an AR(1) sequence
    ``a_k = β a_{k−1} + w``, β = e^{−αT}.  Running autocorrelations of the
    filtered accelerations,

    ``r0 ← r0 + (â_k² − r0)/n``, ``r1 ← r1 + (â_k â_{k−1} − r1)/n``,

    give ``β̂ = clip(r1/r0, e^{−T/τ_min}, 1 − 1e−6)``, ``α̂ = −ln β̂ / T`` and
    ``σ̂_m² = r0``; the prediction is the Singer one with Q = 2α̂σ̂_m² q(α̂).
    The first ``warmup`` steps use ``alpha_init`` and ``sigma_init``.

    Parameters
    ----------
    measurement, dt, name, gate, backend
        As :class:`CurrentStatisticalFilter`.
    alpha_init, sigma_init
        Singer parameters before the estimates are used (1/s, m/s²).
    warmup
        Number of measured steps before switching to the estimates.
    tau_min
        Smallest maneuver time constant allowed (s): β̂ ≥ e^{−T/τ_min}.
    sigma_min
        Floor on σ̂_m (m/s²).
    forgetting
        None: the 1/n running mean of the reconstruction; a number ρ in
        (0, 1): weights ``max(1/n, 1 − ρ)``, forgetting old data.
    """

    alpha_init: float = 0.05
    sigma_init: float = 10.0
    warmup: int = 5
    tau_min: float = 1.0
    sigma_min: float = 0.1
    forgetting: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "alpha_init", positive("alpha_init", self.alpha_init))
        object.__setattr__(self, "sigma_init", positive("sigma_init", self.sigma_init))
        if isinstance(self.warmup, bool) or not isinstance(self.warmup, (int, np.integer)) or self.warmup < 0:
            raise ValueError(f"warmup: must be a non-negative integer, got {self.warmup!r}")
        object.__setattr__(self, "tau_min", positive("tau_min", self.tau_min))
        object.__setattr__(self, "sigma_min", nonnegative("sigma_min", self.sigma_min))
        if self.forgetting is not None:
            object.__setattr__(self, "forgetting", in_range("forgetting", self.forgetting, 0.0, 1.0, low_open=True, high_open=True))

    def _default_name(self) -> str:
        return "MS"

    def _init_memory(self, x, P):
        shape = x.shape[:-1]
        return {"r0": np.zeros(shape), "r1": np.zeros(shape), "count": np.zeros(shape), "a_prev": x[..., 2].copy()}

    def _estimates(self, memory, T):
        r0, r1 = memory["r0"], memory["r1"]
        beta_min, beta_max = np.exp(-T / self.tau_min), 1.0 - 1e-6
        beta = np.clip(np.divide(r1, r0, out=np.full(r0.shape, beta_max), where=r0 > 0), beta_min, beta_max)
        alpha = -np.log(beta) / T
        sigma2 = np.maximum(r0, self.sigma_min**2)
        warm = memory["count"] < self.warmup
        return np.where(warm, self.alpha_init, alpha), np.where(warm, self.sigma_init**2, sigma2)

    def _predict(self, memory, x, P, z, measured, r, T, matrices=_matrices_for):
        alpha, sigma2 = self._estimates(memory, T)
        F, U, q = matrices(alpha, T)
        x_pred, P_pred, _, _ = _propagate(F, U, q, x, P, np.zeros(x.shape[:-1]), sigma2, alpha)
        return _AxisPrediction(x_pred, P_pred, F, np.float64(1.0), alpha, sigma2, memory)

    def _learn(self, memory, x_prev, x_pred, x_upd, measured, T):
        a = x_upd[..., 2]
        count = memory["count"] + measured
        w = 1.0 / np.maximum(count, 1.0)
        if self.forgetting is not None:
            w = np.maximum(w, 1.0 - self.forgetting)
        w = np.where(measured, w, 0.0)
        r0 = memory["r0"] + w * (a * a - memory["r0"])
        r1 = memory["r1"] + w * (a * memory["a_prev"] - memory["r1"])
        return {"r0": r0, "r1": r1, "count": count, "a_prev": a}
