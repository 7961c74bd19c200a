"""Fading-factor strategies for the predict step of the Gaussian filters.

Every Gaussian filter (KF, EKF, UKF, CKF) forms its predicted covariance as

    P⁻_k = λ_k · P̄_k + Q_k,     P̄_k = F P_{k-1} Fᵀ (or its sigma-point analogue),

with λ_k ≥ 1 chosen by a *fading strategy*.  λ = 1 is the plain filter; a
constant λ > 1 is the classic fading-memory filter, which discounts old data
exponentially.  Adaptive strategies (exponentially weighted, strong tracking,
the improved divergence-tested rule of paper P2) choose λ_k from the current
innovation; they plug in here without any change to the filters.

A strategy is any object with

* ``data_independent`` (bool): True when λ does not depend on the
  measurements.  The Kalman filter then keeps one covariance for all runs.
* ``init(batch) -> memory``: the strategy's own state (``None`` if it has
  none);
* ``factor(memory, ctx) -> (Fade, memory)``: λ for this step, from a
  :class:`FadingContext`.

The strategies of paper P2 and the strong tracking filter live beside this
module: :class:`~pursuit.filters.fading_adaptive.ExponentiallyWeighted`
(EWFMKF), :class:`~pursuit.filters.fading_adaptive.StrongTracking` (STF) and
:class:`~pursuit.filters.ifmkf.Improved` (IFMKF).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable, Mapping, Protocol

import numpy as np

from .._validation import in_range
from .jacobians import measurement_jacobian

__all__ = ["Fade", "FadingContext", "FadingStrategy", "Constant", "MAX_CONSTANT_FADING", "NoFading", "CONDITION_LIMIT"]

CONDITION_LIMIT = 1.0 / np.sqrt(np.finfo(float).eps)
"""κ ≈ 6.7e7: the adaptive strategies keep λ·tr(H P̄ Hᵀ) ≤ κ·tr(R) (see :attr:`FadingContext.lam_ceiling`)."""


def diag_sandwich(H: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Diagonal of ``H A Hᵀ``: ``(*b, m, n), (*b, n, n) -> (*b, m)`` (either may be unbatched)."""
    return np.einsum("...ij,...jk,...ik->...i", H, A, H)


@dataclass(frozen=True)
class Fade:
    """A strategy's decision for one step.

    Attributes
    ----------
    lam
        Fading factor λ ≥ 1, a scalar or ``(*batch,)``.
    skip
        Optional ``(*batch,)`` boolean: runs whose measurement update is
        skipped this step (an outlier gate); they only predict, while the
        step info (``innovation``, ``S``, ``nis``, ``dof``, ``loglik``) still
        describes the measurement they rejected.
    info
        Extra per-step diagnostics, copied into the filter's step info.
    """

    lam: np.ndarray | float
    skip: np.ndarray | None = None
    info: Mapping[str, np.ndarray] = field(default_factory=dict)


class FadingContext:
    """What a fading strategy may look at when it chooses λ_k.

    Parameters are filled in by the filter.  ``innovation``, ``jacobian``
    and ``linearization`` are computed on first use only, so a constant
    strategy costs nothing.

    ``linearize`` (optional) returns the filter's own linearisation of the
    measurement function at the prediction; sigma-point filters give their
    statistical linearisation.  Without it, ``linearization`` is the
    Jacobian.
    """

    def __init__(
        self,
        *,
        k: int,
        pred_mean: np.ndarray,
        propagated_cov: np.ndarray,
        process_cov: np.ndarray,
        z: np.ndarray,
        measurement: Any,
        trial_update: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        linearize: Callable[[], np.ndarray] | None = None,
    ) -> None:
        self.k = k
        self.pred_mean = pred_mean
        self.propagated_cov = propagated_cov
        self.process_cov = process_cov
        self.z = z
        self.measurement = measurement
        self._trial_update = trial_update
        self._linearize = linearize

    @cached_property
    def measured(self) -> np.ndarray:
        """``(*batch, m)`` boolean: True where the measurement component is present."""
        return ~np.isnan(self.z)

    @cached_property
    def measurement_cov(self) -> np.ndarray:
        """R_k, ``(m, m)``."""
        return np.asarray(self.measurement.cov(self.k), dtype=float)

    @cached_property
    def predicted_measurement(self) -> np.ndarray:
        """h(x̂⁻_k), ``(*batch, m)``."""
        return self.measurement.h(self.pred_mean, self.k)

    @cached_property
    def innovation(self) -> np.ndarray:
        """z_k − h(x̂⁻_k), ``(*batch, m)``; NaN where z is missing."""
        res = getattr(self.measurement, "residual", None)
        zp = self.predicted_measurement
        return res(self.z, zp) if res is not None else self.z - zp

    @cached_property
    def jacobian(self) -> np.ndarray:
        """H_k = ∂h/∂x at x̂⁻_k: ``(m, n)`` or ``(*batch, m, n)``."""
        return measurement_jacobian(self.measurement, self.pred_mean, self.k)

    @cached_property
    def linearization(self) -> np.ndarray:
        """The filter's H_k at the prediction: ``(m, n)`` or ``(*batch, m, n)``.

        The Jacobian for the KF and EKF; for the UKF and CKF the statistical
        linearisation ``H = P_xzᵀ (P̄ + Q)⁻¹`` from their sigma points, which
        equals the Jacobian when h is linear.
        """
        if self._linearize is None:
            return self.jacobian
        return self._linearize()

    @cached_property
    def lam_ceiling(self) -> np.ndarray:
        """``(*batch,)``: the largest λ the adaptive strategies use, max(1, κ tr R / tr(H P̄ Hᵀ)).

        Traces over every component of the measurement model, measured at
        this step or not (a component missing now must not let its block of
        P̄ grow without bound and meet a precise measurement later), H the
        filter's :attr:`linearization`, κ = :data:`CONDITION_LIMIT` =
        1/√ε ≈ 6.7e7; infinite where tr(H P̄ Hᵀ) = 0.  Below the
        ceiling the faded part of the innovation covariance
        S = λ H P̄ Hᵀ + H Q Hᵀ + R stays within κ of R, the classic limit for
        covariance-form Kalman arithmetic.  At the ceiling the prediction
        already weighs less than 1/κ against the measurement in the measured
        directions, so a larger λ hardly changes the estimate there; it only
        inflates the covariance of what is not measured (a velocity measured
        through positions) until R is lost to round-off and S is singular.
        An innovation-driven λ reaches such values when a filter has lost
        the target or after a short step that follows a long one (measured:
        λ up to 1e10 for STF, position variance 1e12 m² against R = 1e-6 m²).
        """
        batch = self.z.shape[:-1]
        tr_r = np.broadcast_to(np.trace(self.measurement_cov, axis1=-2, axis2=-1), batch)
        tr_m = np.broadcast_to(diag_sandwich(self.linearization, self.propagated_cov).sum(axis=-1), batch)
        bound = np.divide(CONDITION_LIMIT * tr_r, tr_m, out=np.full(batch, np.inf), where=tr_m > 0)
        return np.maximum(bound, 1.0)

    def trial_update(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The filter's update with ``P⁻ = lam·P̄ + Q``: returns (mean, cov)."""
        return self._trial_update(np.asarray(lam, dtype=float))


class FadingStrategy(Protocol):
    """Protocol of a fading strategy (see the module docstring)."""

    data_independent: bool

    def init(self, batch: tuple[int, ...]) -> Any: ...

    def factor(self, memory: Any, ctx: FadingContext) -> tuple[Fade, Any]: ...


MAX_CONSTANT_FADING = 2.0**13
"""The largest constant fading factor the model and experiment files accept (2¹³ ≈ 8.2e3).

A constant λ multiplies the covariance at every step and compounds; measured (WSNRange, EKF):
λ = 1e4 exact, 1e6 broken. Measured, not derived; the library itself accepts any λ ≥ 1.
"""


@dataclass(frozen=True)
class Constant:
    """Constant fading factor λ (TFMKF when λ > 1; the plain filter when λ = 1).

    Parameters
    ----------
    lam
        Fading factor, at least 1.  Paper P2's TFMKF uses 1.23.
    """

    lam: float = 1.0
    data_independent: bool = field(default=True, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "lam", in_range("lam", self.lam, 1.0, np.inf, high_open=True))

    def init(self, batch: tuple[int, ...]) -> None:
        """No memory."""
        return None

    def factor(self, memory: None, ctx: FadingContext) -> tuple[Fade, None]:
        """λ for every run and step."""
        return Fade(np.float64(self.lam)), None


NoFading = Constant(1.0)
"""The plain filter: λ = 1 at every step."""
