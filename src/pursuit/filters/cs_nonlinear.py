"""Current-statistical (CS) model filter for nonlinear measurements (bearings), with APCS and limit adaptation.

The per-axis filters of :mod:`pursuit.filters.cs` need each axis measured in
position on its own.  An angle couples the axes, so here the axes are stacked
into one joint state ``[x, vx, ax, y, vy, ay(, z, vz, az)]`` and one
extended (EKF) or unscented (UKF) update takes the whole measurement
(docs/spec/04-adaptive-cs-model.md §4.5).  The prediction is the CS one on every
axis block: with ā = â(k|k), ``x⁻ = F x + U ā`` (the constant-acceleration
extrapolation) and ``P⁻ = λ F P Fᵀ + Q``, F, U and ``Q = 2ασ_a² q`` block
diagonal over the axes (docs/spec/04-adaptive-cs-model.md §1).

**Adaptation** (``adaptation``), each step:

1. Nominal prediction with α0, λ = 1 and the nominal σ_a²; its update gives
   ``D = νᵀ S0⁻¹ ν`` (ν wrapped for angles), χ²(m) for a matched model.
2. ``D > M`` is a maneuver; then, with ``r = D/M``:

``"none"``
    The standard CS filter: α = α0, λ = 1, σ_a² = (4 − π)/π (a_max − |ā|)²
    from the fixed limit (docs/spec/04-adaptive-cs-model.md §1).
``"apcs"``
    The rules of the per-axis APCS filter (docs/spec/04-adaptive-cs-model.md §2),
    with the joint D: λ from ``fading``, α from ``alpha_rule``, σ_a² per axis
    from the displacement correction of that axis's position (``variance``).
``"limit"``
    This module's reading of the abstract of §4.5 ("the residual adjusts the
    maneuver frequency and the acceleration limit in real time") [RECON]:
    α = min(α0 r, α_cap) (``alpha_rule``), a_max(k) = min(a_max √r,
    a_max_cap) and σ_a² = (4 − π)/π (a_max(k) − |ā|)² per axis, λ from
    ``fading``; without a maneuver α = α0 and a_max(k) = a_max.  √r because
    σ_a² ∝ a_max² then grows like D/M, as λ does under ``fading="ratio"``.

**Bounds.**  α always lies in [α0, α_cap] and the limit in [a_max,
a_max_cap]; λ ≥ 1; σ_a of ``"apcs"`` in [σ_min, σ_max].

λ on detection, ``fading="stf"``: the strong-tracking trace ratio
``max(1, tr N / tr M̃)``, ``N = V − H Q0 Hᵀ − β_s R``, ``M̃ = H F0 P F0ᵀ Hᵀ``,
V the memory ``(ρ V + ν νᵀ)/(1 + ρ)`` of fully measured steps and H the
measurement Jacobian at the prediction (also for the UKF).  For a single
axis measured in position all of this is the per-axis APCS filter.

State: :class:`pursuit.filters.cs.AxisState` (mean, cov, k, memory).  Info
keys: the standard ones, plus ``fading`` (*b,), ``faded`` (*b,), ``alpha``
(*b, A), ``sigma_a2`` (*b, A), ``a_limit`` (*b,) (the acceleration limit
used), ``maneuver`` (*b, A) and ``maneuver_stat`` (*b, A) (the joint flag
and D, repeated on every axis as the maneuver experiment expects; not with
``adaptation="none"``, which has no detector), ``gated``, ``repaired``, ``pred_mean``, ``pred_cov``,
``cross_cov``.

**Compiled backend.**  With ``backend="numba"`` and a built-in measurement
model (:class:`~pursuit.models.sensors.ObserverBearings` included) both
measurement updates of a step, the nominal one of the residual test and the
final one, run the compiled EKF/UKF update kernels
(``compiled_path = "gaussian:CS"``); the CS prediction and the adaptation
rules stay vectorised NumPy, shared with the NumPy step
(:meth:`NonlinearCSFilter.numpy_step` with its ``correct`` argument).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import in_range, measurement_for_step, nonnegative, positive, time_step
from ..compute import compiled_specs
from ..gaussian import Gaussian
from ..models.maneuver import CS_VARIANCE_FACTOR, CurrentStatistical, cs_variance
from ..rng import RNGLike
from .base import FilterBase, as_gaussian, prior_batch
from .cs import AxisState, _matrices, _matrices_for, check_adaptation_params, chi2_threshold
from .gating import apply_gate
from .gaussian import ExtendedKalmanFilter, UnscentedKalmanFilter, _update
from .jacobians import measurement_jacobian

__all__ = ["NonlinearCSFilter", "ADAPTATIONS"]

ADAPTATIONS = ("none", "apcs", "limit")
_UPDATES = ("ekf", "ukf")
_VARIANCE_LAWS = ("displacement", "linear", "rayleigh", "fixed")
_FADING_RULES = ("stf", "ratio", "none")
_ALPHA_RULES = ("ratio", "fading", "none")


def _t(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


def _full(blocks: np.ndarray, A: int) -> np.ndarray:
    """Block-diagonal ``(*b, 3A, 3A)`` from per-axis blocks ``(*b, A, 3, 3)``."""
    n = 3 * A
    out = np.zeros((*blocks.shape[:-3], n, n))
    for a in range(A):  # A ≤ 3 blocks, not a loop over runs
        out[..., 3 * a : 3 * a + 3, 3 * a : 3 * a + 3] = blocks[..., a, :, :]
    return out


@dataclass(frozen=True)
class NonlinearCSFilter(FilterBase):
    """CS-model filter with a joint state and an EKF or UKF update, for angle (or any nonlinear) measurements.

    Parameters
    ----------
    measurement
        Measurement model with ``h``, ``cov`` (and ``jacobian``,
        ``residual`` for angles), e.g. :class:`pursuit.models.sensors.ObserverBearings`
        or a linear position measurement.
    dt
        Sampling period T (s).
    axes
        Number of axes A (state ``[x, vx, ax, y, ...]``, n = 3A); 0: the
        length of the measurement's ``position_indices``, else the rows of
        its ``matrix()``.
    update
        ``"ekf"`` (linearised at the prediction) or ``"ukf"`` (scaled
        unscented transform, α = 1, β = 2, κ = 0).
    adaptation
        ``"none"`` (fixed CS), ``"apcs"`` (docs/spec/04-adaptive-cs-model.md §2 rules) or
        ``"limit"`` (α and a_max from the residual test, §4.5 [RECON]); see
        the module notes.
    alpha0
        Maneuver frequency without a maneuver (1/s); the fixed α of ``"none"``.
    a_max
        Acceleration limit (m/s²): the fixed limit of ``"none"``, the lower
        bound of ``"limit"``, the start-up σ_a² of ``"apcs"``.
    a_max_cap
        Upper bound of the adapted limit (m/s², ``"limit"``); default
        ``4 a_max``.
    threshold
        Detection threshold M on D (default 3, the paper's, for one angle).
    false_alarm
        Alternatively the false-alarm probability p: M = χ²_m⁻¹(1 − p), m
        the measurement dimension.
    variance, c_a, sigma_a, sigma_min, sigma_max
        The σ_a² law of ``"apcs"`` (as :class:`pursuit.filters.cs.AdaptiveCSFilter`);
        ``sigma_min`` also floors σ_a of ``"none"`` and ``"limit"``.
    fading
        λ on detection: ``"stf"`` (trace ratio), ``"ratio"`` (D/M) or
        ``"none"``.  Ignored by ``"none"``.
    rho, beta_s
        Strong-tracking forgetting and weakening factors.
    alpha_rule
        α on detection: ``"ratio"`` (α0 D/M), ``"fading"`` (λ α0) or
        ``"none"``; capped at ``alpha_cap``.
    alpha_cap
        Upper bound of α (1/s).
    mean
        ``"current"`` (ā = â(k|k), CS) or ``"zero"`` (Singer prediction).
    gate, name, backend
        Keyword only: χ² gate probability (default none), label, backend.
    """

    measurement: Any
    dt: float = 1.0
    axes: int = 0
    update: str = "ekf"
    adaptation: str = "limit"
    alpha0: float = 0.001
    a_max: float = 100.0
    a_max_cap: float | None = None
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
    gate: float | None = field(default=None, kw_only=True)

    measurement_needs = ("h", "cov")
    compiled_path = "gaussian:CS"
    compiled_step_sensor = True  # the compiled updates pack the sensor of step k (a moving observer)

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", positive("dt", self.dt))
        for name, allowed in (
            ("update", _UPDATES),
            ("adaptation", ADAPTATIONS),
            ("variance", _VARIANCE_LAWS),
            ("fading", _FADING_RULES),
            ("alpha_rule", _ALPHA_RULES),
            ("mean", ("current", "zero")),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name}: must be one of {', '.join(map(repr, allowed))}, got {getattr(self, name)!r}")
        object.__setattr__(self, "alpha0", positive("alpha0", self.alpha0))
        object.__setattr__(self, "a_max", positive("a_max", self.a_max))
        cap = 4.0 * self.a_max if self.a_max_cap is None else positive("a_max_cap", self.a_max_cap)
        if cap < self.a_max:
            raise ValueError(f"a_max_cap: must be at least a_max = {self.a_max}, got {cap}")
        object.__setattr__(self, "a_max_cap", float(cap))
        check_adaptation_params(self)
        if self.gate is not None:
            object.__setattr__(self, "gate", in_range("gate", self.gate, 0.0, 1.0, low_open=True, high_open=True))
        super().__post_init__()  # model checks: h and cov exist
        A = self._infer_axes()
        m = np.shape(self.measurement.cov(None))[-1]
        if self.false_alarm is not None:
            object.__setattr__(self, "threshold", chi2_threshold(self.false_alarm, m))
        object.__setattr__(self, "threshold", positive("threshold", self.threshold))
        object.__setattr__(self, "axes", A)
        # The EKF or UKF whose measurement step this filter uses; its motion model (the nominal CS
        # model of the same state) is never stepped.
        nominal = CurrentStatistical(alpha=self.alpha0, a_max=self.a_max, ndim=A, dt=self.dt)
        cls = ExtendedKalmanFilter if self.update == "ekf" else UnscentedKalmanFilter
        object.__setattr__(self, "_inner", cls(nominal, self.measurement, backend="numpy"))

    def _model_specs(self) -> Any:
        # no motion model to compile: the CS prediction is this filter's own (NumPy)
        return compiled_specs(None, self.measurement, need_diagonal=False, step_sensor=True)

    @property
    def update_filter(self) -> ExtendedKalmanFilter | UnscentedKalmanFilter:
        """The NumPy EKF or UKF whose measurement update (and sigma points) this filter uses; its motion model is never stepped."""
        return self._inner

    @property
    def detection_dof(self) -> int:
        """Degrees of freedom of the residual statistic D: the measurement dimension m."""
        return int(np.shape(self.measurement.cov(None))[-1])

    def _state_dim(self) -> int:
        """``3 * axes``: the stacked ``[x, vx, ax, y, ...]`` state (there is no motion model to ask)."""
        return 3 * self.axes

    def _infer_axes(self) -> int:
        A = self.axes
        idx = getattr(self.measurement, "position_indices", None)
        if not A and idx is not None:
            A = len(idx)
        if not A and callable(getattr(self.measurement, "matrix", None)):
            A = np.asarray(self.measurement.matrix(None)).shape[0]
        if isinstance(A, bool) or not isinstance(A, (int, np.integer)) or not 1 <= A <= 3:
            raise ValueError(f"axes: expected 1 to 3 axes (or 0 to infer them from the measurement), got {A!r}")
        if idx is not None and tuple(idx)[:A] != tuple(3 * a for a in range(A))[: len(idx)]:
            raise ValueError(
                f"measurement: position_indices {tuple(idx)} do not match the [x, vx, ax, y, ...] layout "
                f"(positions at {tuple(3 * a for a in range(A))})"
            )
        return int(A)

    def _default_name(self) -> str:
        base = {"none": "CS", "apcs": "APCS", "limit": "ACS"}[self.adaptation]
        return f"{base}-{self.update.upper()}"

    # -- protocol -------------------------------------------------------------
    def init(self, prior: Gaussian, batch: tuple[int, ...] = (), rng: RNGLike = None) -> AxisState:
        """Initial state from a Gaussian prior (the joint covariance is kept)."""
        prior = as_gaussian(prior)
        batch = prior_batch(prior, batch)
        if prior.dim != 3 * self.axes:
            raise ValueError(f"prior: state dimension {prior.dim} does not match 3 x {self.axes} axes")
        mean, cov = prior.broadcast(batch)
        m = np.shape(self.measurement.cov(None))[-1]
        acc = mean[..., 2::3]
        if self.variance == "fixed":
            s2 = np.full(acc.shape, self.sigma_a**2)
        else:
            s2 = self._clip(cs_variance(acc, self.a_max))
        memory = {"sigma2": s2, "V": np.full((*batch, m, m), np.nan)}
        return AxisState(np.array(mean, dtype=float), np.array(cov, dtype=float), 0, memory)

    def step(
        self, state: AxisState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[AxisState, dict[str, np.ndarray]]:
        """One predict-update cycle with measurement ``z`` (``(*b, m)``; NaN = missing)."""
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        z = measurement_for_step(z, state.batch, self.detection_dof, k)
        if self._specs is not None:
            return self._compiled_step(state, z, k, dt)
        return self.numpy_step(state, z, k, dt)

    def numpy_step(
        self, state: AxisState, z: np.ndarray, k: int, dt: float | None, correct: Any = None
    ) -> tuple[AxisState, dict[str, np.ndarray]]:
        """The step in NumPy (``z`` already checked), with the measurement updates by ``correct`` when given.

        ``correct(x_pred, P_pred, z, k) -> (mean, cov, info)`` is the
        measurement update at a prediction, ``info`` with the standard keys
        and ``repaired``; default :meth:`measurement_update`.  The compiled
        path passes its kernels; everything else is this step's.
        """
        correct = self.measurement_update if correct is None else correct
        T = float(self.dt if dt is None else dt)
        batch = state.batch
        R = np.asarray(self.measurement.cov(k), dtype=float)
        m = R.shape[-1]
        A = self.axes
        x, P = state.mean, state.cov
        xa = x.reshape(*batch, A, 3)
        a_bar = xa[..., 2] if self.mean == "current" else np.zeros(xa.shape[:-1])

        # 1. nominal prediction (α0, λ = 1, nominal σ_a²) and its residual test
        sigma2_nom = self._nominal_sigma2(state.memory, xa)
        F0, U0, q0 = _matrices(self.alpha0, T)
        F0f = np.kron(np.eye(A), F0)
        FPFt0 = F0f @ P @ F0f.T
        Q0 = _full(2.0 * self.alpha0 * sigma2_nom[..., None, None] * q0, A)
        x0 = (np.einsum("ij,...aj->...ai", F0, xa) + U0 * a_bar[..., None]).reshape(*batch, 3 * A)
        P0 = FPFt0 + Q0
        P0 = 0.5 * (P0 + _t(P0))
        valid = ~np.isnan(z)
        if self.adaptation == "none":
            detect = np.zeros(batch, dtype=bool)
            D = np.full(batch, np.nan)
            V = state.memory["V"]
        else:
            _, _, info0 = correct(x0, P0, z, k)
            nu = np.where(valid, info0["innovation"], 0.0)
            # D = νᵀ S0⁻¹ ν, solved per run: the shared update's NIS (a batched quadratic form) may
            # differ in the last bit with the batch size, and D decides the adaptation.
            S0 = np.broadcast_to(info0["S"], (*batch, m, m))
            D = np.sum(nu * np.linalg.solve(S0, nu[..., None])[..., 0], axis=-1)
            D = np.where(info0["dof"] > 0, D, np.nan)
            detect = (info0["dof"] > 0) & (D > self.threshold)
            V_old = state.memory["V"]
            nn = nu[..., :, None] * nu[..., None, :]
            V = np.where(np.isnan(V_old), nn, (self.rho * V_old + nn) / (1.0 + self.rho))
            full = valid.all(axis=-1)[..., None, None]
            V = np.where(full, V, V_old)

        # 2. the adapted parameters
        ratio = np.where(detect, D / self.threshold, 1.0)
        lam = self._fading(detect, ratio, V, x0, FPFt0, Q0, R, k)
        if self.adaptation == "none" or self.alpha_rule == "none":
            alpha = np.full(batch, self.alpha0)
        elif self.alpha_rule == "ratio":
            alpha = np.minimum(self.alpha0 * ratio, self.alpha_cap)
        else:
            alpha = np.minimum(self.alpha0 * lam, self.alpha_cap)
        limit = np.full(batch, self.a_max)
        if self.adaptation == "limit":
            limit = np.minimum(self.a_max * np.sqrt(ratio), self.a_max_cap)
            sigma2 = np.maximum(cs_variance(xa[..., 2], limit[..., None]), self.sigma_min**2)
        else:
            sigma2 = sigma2_nom

        # 3. the prediction used and the update
        F, U, q = _matrices_for(alpha, T)  # (*b, 3, 3), (*b, 3), (*b, 3, 3)
        Fa = np.broadcast_to(F[..., None, :, :], (*batch, A, 3, 3))
        Ff = _full(Fa, A)
        x_pred = (np.einsum("...ij,...aj->...ai", F, xa) + U[..., None, :] * a_bar[..., None]).reshape(*batch, 3 * A)
        FPFt = Ff @ P @ _t(Ff)
        Q = _full((2.0 * alpha[..., None] * sigma2)[..., None, None] * q[..., None, :, :], A)
        P_pred = lam[..., None, None] * FPFt + Q
        P_pred = 0.5 * (P_pred + _t(P_pred))
        mean, cov, info = correct(x_pred, P_pred, z, k)
        gated = np.zeros(batch, dtype=bool)
        if self.gate is not None:
            mean, cov, gated = apply_gate(self.gate, info, x_pred, P_pred, mean, cov)
        info = dict(info)

        # 4. memory for the next step (a rejected or missing measurement teaches nothing)
        learned = (np.asarray(info["dof"]) > 0) & ~gated
        memory = {
            "sigma2": self._learn_sigma2(state.memory["sigma2"], x_pred, mean, learned, T, A),
            "V": np.where(learned[..., None, None], V, state.memory["V"]),
        }
        info["fading"] = lam
        info["faded"] = lam > 1.0
        info["alpha"] = np.broadcast_to(alpha[..., None], (*batch, A))
        info["sigma_a2"] = np.broadcast_to(sigma2, (*batch, A))
        info["a_limit"] = limit
        if self.adaptation != "none":  # the fixed filter has no detector
            info["maneuver"] = np.broadcast_to(detect[..., None], (*batch, A))
            info["maneuver_stat"] = np.broadcast_to(D[..., None], (*batch, A))
        info["gated"] = gated
        info["repaired"] = np.zeros(batch, dtype=bool) | np.broadcast_to(info["repaired"], batch)
        info["pred_mean"] = x_pred
        info["pred_cov"] = P_pred
        info["cross_cov"] = P @ _t(Ff)
        return AxisState(mean, np.broadcast_to(cov, (*batch, *cov.shape[-2:])).copy(), k, memory), info

    def measurement_update(
        self, x_pred: np.ndarray, P_pred: np.ndarray, z: np.ndarray, k: int
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """The EKF or UKF update at the prediction ``(x_pred, P_pred)`` in NumPy: ``(mean, cov, info)``, info with ``repaired``."""
        meas, P_pred = self._inner._measure_factored(x_pred, P_pred, k)
        mean, cov, info = _update(x_pred, P_pred, z, ~np.isnan(z), meas, self.measurement, k)
        info = dict(info)
        info["repaired"] = np.broadcast_to(meas.repaired if meas.repaired is not None else False, x_pred.shape[:-1])
        return mean, cov, info

    # -- pieces ---------------------------------------------------------------
    def _clip(self, s2: np.ndarray) -> np.ndarray:
        hi = np.inf if self.sigma_max is None else self.sigma_max**2
        return np.clip(s2, self.sigma_min**2, hi)

    def _nominal_sigma2(self, memory: dict[str, np.ndarray], xa: np.ndarray) -> np.ndarray:
        """σ_a² of the nominal prediction, ``(*b, A)``."""
        if self.adaptation == "apcs":
            if self.variance == "rayleigh":
                return self._clip(cs_variance(xa[..., 2], self.a_max))
            return memory["sigma2"]
        return np.maximum(cs_variance(xa[..., 2], self.a_max), self.sigma_min**2)

    def _fading(self, detect, ratio, V, x0, FPFt0, Q0, R, k) -> np.ndarray:
        """λ ≥ 1 on detection (1 elsewhere), ``(*b,)``."""
        if self.adaptation == "none" or self.fading == "none" or not detect.any():
            return np.ones(detect.shape)
        if self.fading == "ratio":
            return ratio
        H = np.asarray(measurement_jacobian(self.measurement, x0, k), dtype=float)
        HPH = H @ FPFt0 @ _t(H)
        HQH = H @ Q0 @ _t(H)
        N = np.trace(V, axis1=-2, axis2=-1) - np.trace(HQH, axis1=-2, axis2=-1) - self.beta_s * np.trace(R)
        M = np.trace(HPH, axis1=-2, axis2=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(M > 0, N / M, 1.0)
        return np.where(detect, np.maximum(1.0, np.nan_to_num(lam, nan=1.0)), 1.0)

    def _learn_sigma2(self, sigma2, x_pred, x_upd, learned, T, A) -> np.ndarray:
        """σ_a² for the next step of ``"apcs"``: each axis's displacement correction (docs/spec/04-adaptive-cs-model.md §2.1)."""
        if self.adaptation != "apcs" or self.variance in ("rayleigh", "fixed"):
            return sigma2
        da = 2.0 * (x_upd[..., 0::3] - x_pred[..., 0::3]) / (T * T)
        s2 = CS_VARIANCE_FACTOR * da * da if self.variance == "displacement" else self.c_a * np.abs(da)
        return np.where(learned[..., None], self._clip(s2), sigma2)
