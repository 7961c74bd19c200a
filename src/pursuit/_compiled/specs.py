"""Which models the compiled backend knows, as plain arrays for the kernels (no numba import here).

The compiled kernels cannot call a model's Python methods; they evaluate the
built-in models from their parameters.  A model is compiled only when its
*exact* type is one of these (a subclass may override a method, so it is
not trusted):

Motion
    :class:`~pursuit.models.ConstantVelocity`,
    :class:`~pursuit.models.ConstantAcceleration` and
    :class:`~pursuit.models.LinearMotion` (``x_k = F x + G ξ``), and
    :class:`~pursuit.models.UNGMMotion`.
Measurement
    :class:`~pursuit.models.LinearGaussian` (``H x``),
    :class:`~pursuit.models.RangeSensors` and
    :class:`~pursuit.models.TimeOfArrival` (ranges to anchors, divided by c),
    :class:`~pursuit.models.RangeBearing` (bearing innovations wrapped) and
    :class:`~pursuit.models.UNGMMeasurement` (``x² / s``).

Everything else (a user's model, a maneuvering-target model) is computed
with NumPy: the ``*_spec`` functions return a reason string instead of a
spec, which the filter puts in its :class:`pursuit.compute.CompiledBackendWarning`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..models.linear_motion import LinearMotion
from ..models.measurement import LinearGaussian, RangeBearing, RangeSensors, TimeOfArrival
from ..models.motion import ConstantAcceleration, ConstantVelocity
from ..models.ungm import UNGMMeasurement, UNGMMotion

__all__ = ["MotionSpec", "MeasurementSpec", "motion_spec", "measurement_spec"]

# motion kinds
LINEAR = 0
UNGM = 1
# measurement kinds
M_LINEAR = 0
M_UNGM = 1
M_RANGE = 2
M_RANGE_BEARING = 3


@dataclass(frozen=True, eq=False)
class MotionSpec:
    """A built-in motion model as arrays: ``kind``, and per step ``F``, ``G`` and scalars ``par``."""

    kind: int
    model: Any

    def arrays(self, k: int, dt: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(F (n, n), G (n, q), par)`` for step ``k``.

        Linear models: x_k = F x + G ξ with ξ ~ N(0, I_q) (the model's own
        noise factor, so the draws are those of ``model.sample``).  UNGM:
        ``par = [a, b, c cos(ω (k − 1)), √Q]`` and ``F``, ``G`` are 1 × 1
        placeholders.
        """
        m = self.model
        if self.kind == UNGM:
            forcing = m._forcing(k)
            par = np.array([m.a, m.b, forcing, np.sqrt(m.q) if m.q != 1.0 else 1.0])
            one = np.ones((1, 1))
            return one, one, par
        if isinstance(m, LinearMotion):
            F, G = m.F, m._G
        else:
            F, _, G = m._matrices(dt)
        return np.ascontiguousarray(F), np.ascontiguousarray(G), np.zeros(1)

    def cov(self, k: int, dt: float | None) -> np.ndarray:
        """Process-noise covariance Q of step ``k``."""
        return np.asarray(self.model.cov(k) if dt is None else self.model.cov(k, dt=dt), dtype=float)


@dataclass(frozen=True, eq=False)
class MeasurementSpec:
    """A built-in measurement model as arrays.

    Attributes
    ----------
    kind
        ``M_LINEAR``, ``M_UNGM``, ``M_RANGE`` or ``M_RANGE_BEARING``.
    A
        ``(m, n)`` H for linear; ``(s, d)`` anchors for ranges; ``(1, 2)``
        sensor position for range-bearing; ``(1, 1)`` otherwise.
    idx
        Position indices in the state (ranges, range-bearing).
    scale
        Divisor: c for time of arrival (1 for ranges), s for UNGM.
    R
        ``(m, m)`` noise covariance.
    diagonal
        Whether R is diagonal.
    angle
        Whether component 1 is an angle (innovations wrapped).
    """

    kind: int
    A: np.ndarray
    idx: np.ndarray
    scale: float
    R: np.ndarray
    diagonal: bool
    angle: bool

    @property
    def dim(self) -> int:
        """Measurement dimension m."""
        return self.R.shape[0]


def motion_spec(motion: Any) -> MotionSpec | str:
    """The compiled form of a motion model, or the reason there is none."""
    t = type(motion)
    if t is UNGMMotion:
        return MotionSpec(UNGM, motion)
    if t in (ConstantVelocity, ConstantAcceleration, LinearMotion):
        return MotionSpec(LINEAR, motion)
    return f"motion model {t.__name__} (compiled: ConstantVelocity, ConstantAcceleration, LinearMotion, UNGMMotion)"


def measurement_spec(measurement: Any) -> MeasurementSpec | str:
    """The compiled form of a measurement model, or the reason there is none."""
    t = type(measurement)
    R = np.ascontiguousarray(np.asarray(measurement.cov(None), dtype=float)) if hasattr(measurement, "cov") else None
    diagonal = R is not None and np.count_nonzero(R - np.diag(np.diag(R))) == 0
    none_i = np.zeros(1, dtype=np.int64)
    if t is LinearGaussian:
        return MeasurementSpec(M_LINEAR, np.ascontiguousarray(measurement.H), none_i, 1.0, R, diagonal, False)
    if t is UNGMMeasurement:
        return MeasurementSpec(M_UNGM, np.ones((1, 1)), none_i, float(measurement.scale), R, diagonal, False)
    if t in (RangeSensors, TimeOfArrival):
        c = float(measurement.c) if t is TimeOfArrival else 1.0
        idx = np.asarray(measurement.position_indices, dtype=np.int64)
        return MeasurementSpec(M_RANGE, np.ascontiguousarray(measurement.anchors), idx, c, R, diagonal, False)
    if t is RangeBearing:
        idx = np.asarray(measurement.position_indices, dtype=np.int64)
        return MeasurementSpec(M_RANGE_BEARING, np.asarray(measurement.sensor, dtype=float).reshape(1, 2), idx, 1.0, R, diagonal, True)
    return (
        f"measurement model {t.__name__} (compiled: LinearGaussian, RangeSensors, TimeOfArrival, RangeBearing, "
        "UNGMMeasurement)"
    )


def model_specs(motion: Any, measurement: Any, need_diagonal: bool) -> tuple[MotionSpec, MeasurementSpec] | str:
    """Both specs, or the first reason why the pair is not compiled."""
    ms = motion_spec(motion)
    if isinstance(ms, str):
        return ms
    hs = measurement_spec(measurement)
    if isinstance(hs, str):
        return hs
    if need_diagonal and not hs.diagonal:
        return "a non-diagonal measurement covariance R"
    return ms, hs
