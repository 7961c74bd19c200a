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
    :class:`~pursuit.models.RangeBearing` (bearing innovations wrapped),
    :class:`~pursuit.models.UNGMMeasurement` (``x² / s``) and
    :class:`~pursuit.models.ObserverBearings` (a moving observer's angles,
    all wrapped): its spec is *per step* (``moving``), packed with the
    observer's position of step k by ``kernel_args(k)``, so only the filters
    whose compiled step packs the sensor each step take it (the Kalman
    family and the CS-model filter; ``model_specs(..., step_sensor=True)``).

Everything else (a user's model, a maneuvering-target model) is computed
with NumPy: the ``*_spec`` functions return a reason string instead of a
spec, which the filter puts in its :class:`pursuit.compute.CompiledBackendWarning`.

The tables :data:`MOTIONS` and :data:`MEASUREMENTS` are the registrations:
a model type is compiled exactly when it is a key there.  The kernels
receive a spec packed as :class:`~pursuit._compiled.kernel_args.Motion` /
:class:`~pursuit._compiled.kernel_args.Sensor` and evaluate it in
:mod:`pursuit._compiled.model_math`, which dispatches on the ``kind`` code
below (docs/compiled-backend.md, "Adding a compiled sensor").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..models.linear_motion import LinearMotion
from ..models.measurement import LinearGaussian, RangeBearing, RangeSensors, TimeOfArrival
from ..models.motion import ConstantAcceleration, ConstantVelocity
from ..models.sensors import ObserverBearings
from ..models.ungm import UNGMMeasurement, UNGMMotion
from .kernel_args import Motion, Sensor

__all__ = ["MotionSpec", "MeasurementSpec", "frozen", "motion_spec", "measurement_spec", "MOTIONS", "MEASUREMENTS"]

# motion kinds (model_math dispatches on them; compiled code freezes them as constants)
LINEAR = 0
UNGM = 1
# measurement kinds (sensor codes)
M_LINEAR = 0
M_UNGM = 1
M_RANGE = 2
M_RANGE_BEARING = 3
M_OBSERVER_BEARINGS = 4

#: The motion models with a compiled form: exact type -> motion kind.
MOTIONS: dict[type, int] = {
    ConstantVelocity: LINEAR,
    ConstantAcceleration: LINEAR,
    LinearMotion: LINEAR,
    UNGMMotion: UNGM,
}


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
        # writable C copies where the model's own are read-only: the sequence kernels slice F, G of
        # writable stacks, and numba compiles a kernel once more for a read-only argument
        return np.require(F, np.float64, ("C", "W")), np.require(G, np.float64, ("C", "W")), np.zeros(1)

    def cov(self, k: int, dt: float | None) -> np.ndarray:
        """Process-noise covariance Q of step ``k``."""
        return np.asarray(self.model.cov(k) if dt is None else self.model.cov(k, dt=dt), dtype=float)

    def kernel_args(self, k: int, dt: float | None) -> Motion:
        """Step ``k`` packed for the kernels."""
        return Motion(self.kind, *self.arrays(k, dt))

    def sequence_args(self, steps: int) -> Motion:
        """Steps 1 … ``steps`` (the model's own ``dt``) packed for the sequence kernels: F, G, par stacked on a first axis."""
        parts = zip(*(self.arrays(k, None) for k in range(1, steps + 1)))
        return Motion(self.kind, *(np.ascontiguousarray(np.stack(p)) for p in parts))


@dataclass(frozen=True, eq=False)
class MeasurementSpec:
    """A built-in measurement model as arrays.

    Attributes
    ----------
    kind
        ``M_LINEAR``, ``M_UNGM``, ``M_RANGE``, ``M_RANGE_BEARING`` or
        ``M_OBSERVER_BEARINGS``.
    A
        ``(m, n)`` H for linear; ``(s, d)`` anchors for ranges; ``(1, 2)``
        sensor position for range-bearing; ``(1, 1)`` otherwise (a moving
        observer's position of the step replaces it in ``kernel_args(k)``).
    idx
        Position indices in the state (ranges, range-bearing).
    scale
        Divisor: c for time of arrival (1 for ranges), s for UNGM.
    R
        ``(m, m)`` noise covariance.
    diagonal
        Whether R is diagonal.
    angle
        Whether component 1 is an angle (innovations wrapped); every
        component of ``M_OBSERVER_BEARINGS`` is (``model_math.wraps``).
    observer
        The moving observer's model (its ``observer_at(k)``) for a sensor
        that depends on the step, else None.
    """

    kind: int
    A: np.ndarray
    idx: np.ndarray
    scale: float
    R: np.ndarray
    diagonal: bool
    angle: bool
    observer: Any = None

    @property
    def dim(self) -> int:
        """Measurement dimension m."""
        return self.R.shape[0]

    @property
    def moving(self) -> bool:
        """Whether the sensor depends on the step (a moving observer): pack it with ``kernel_args(k)``."""
        return self.observer is not None

    def kernel_args(self, k: int | None = None) -> Sensor:
        """The spec packed for the kernels; for a moving observer, at step ``k`` (its position of that step in ``A``)."""
        A = self.A
        if self.observer is not None:
            if k is None:
                raise ValueError("k: a moving observer's sensor is packed per step")
            A = np.asarray(self.observer.observer_at(k), dtype=float).reshape(1, -1)
        return Sensor(
            int(self.kind), frozen(A, np.float64), frozen(self.idx, np.int64), float(self.scale),
            frozen(self.R, np.float64), bool(self.angle),
        )


def frozen(a: np.ndarray, dtype: type) -> np.ndarray:
    """A read-only, C-contiguous view of ``a`` as ``dtype`` (a copy only where the layout or dtype differ).

    numba types a read-only array apart from a writable one, and compiles a
    kernel again for every combination it meets: a model's own arrays are
    often read-only (``R``, anchors), a step's observer position or a built
    ``R`` is not.  Packing every sensor array read-only gives each kernel one
    signature; the kernels only read them, so the bits are the same.
    """
    view = np.ascontiguousarray(a, dtype=dtype).view()
    view.flags.writeable = False
    return view


def motion_spec(motion: Any) -> MotionSpec | str:
    """The compiled form of a motion model, or the reason there is none."""
    t = type(motion)
    kind = MOTIONS.get(t)
    if kind is None:
        return f"motion model {t.__name__} (compiled: {', '.join(c.__name__ for c in MOTIONS)})"
    return MotionSpec(kind, motion)


# ---------------------------------------------------------------------------
# measurement models: one builder per model type, registered in MEASUREMENTS
# ---------------------------------------------------------------------------
_NO_INDEX = np.zeros(1, dtype=np.int64)


def _linear_spec(h: LinearGaussian, R: np.ndarray, diagonal: bool) -> MeasurementSpec:
    return MeasurementSpec(M_LINEAR, np.ascontiguousarray(h.H), _NO_INDEX, 1.0, R, diagonal, False)


def _ranges_spec(h: RangeSensors | TimeOfArrival, R: np.ndarray, diagonal: bool) -> MeasurementSpec:
    c = float(h.c) if type(h) is TimeOfArrival else 1.0
    idx = np.asarray(h.position_indices, dtype=np.int64)
    return MeasurementSpec(M_RANGE, np.ascontiguousarray(h.anchors), idx, c, R, diagonal, False)


def _range_bearing_spec(h: RangeBearing, R: np.ndarray, diagonal: bool) -> MeasurementSpec:
    idx = np.asarray(h.position_indices, dtype=np.int64)
    return MeasurementSpec(M_RANGE_BEARING, np.asarray(h.sensor, dtype=float).reshape(1, 2), idx, 1.0, R, diagonal, True)


def _observer_bearings_spec(h: ObserverBearings, R: np.ndarray, diagonal: bool) -> MeasurementSpec:
    idx = np.asarray(h.position_indices, dtype=np.int64)
    d = idx.shape[0]
    return MeasurementSpec(M_OBSERVER_BEARINGS, np.zeros((1, d)), idx, 1.0, R, diagonal, True, observer=h)


def _ungm_spec(h: UNGMMeasurement, R: np.ndarray, diagonal: bool) -> MeasurementSpec:
    return MeasurementSpec(M_UNGM, np.ones((1, 1)), _NO_INDEX, float(h.scale), R, diagonal, False)


#: The measurement models with a compiled form: exact type -> spec builder ``(model, R, diagonal) -> spec``.
#: A new compiled sensor adds its builder here and its maths to :mod:`pursuit._compiled.model_math`.
MEASUREMENTS: dict[type, Callable[[Any, np.ndarray, bool], MeasurementSpec]] = {
    LinearGaussian: _linear_spec,
    RangeSensors: _ranges_spec,
    TimeOfArrival: _ranges_spec,
    RangeBearing: _range_bearing_spec,
    UNGMMeasurement: _ungm_spec,
    ObserverBearings: _observer_bearings_spec,
}


def measurement_spec(measurement: Any) -> MeasurementSpec | str:
    """The compiled form of a measurement model, or the reason there is none."""
    t = type(measurement)
    build = MEASUREMENTS.get(t)
    if build is None:
        return f"measurement model {t.__name__} (compiled: {', '.join(c.__name__ for c in MEASUREMENTS)})"
    R = np.ascontiguousarray(np.asarray(measurement.cov(None), dtype=float))
    diagonal = np.count_nonzero(R - np.diag(np.diag(R))) == 0
    return build(measurement, R, bool(diagonal))


def model_specs(
    motion: Any, measurement: Any, need_diagonal: bool, step_sensor: bool = False
) -> tuple[MotionSpec | None, MeasurementSpec] | str:
    """Both specs, or the first reason why the pair is not compiled.

    ``motion=None``: a filter that predicts with its own model (the CS-model
    filter) and needs only the measurement's spec.  ``step_sensor``: the
    caller packs the sensor per step, so a moving observer is accepted.
    """
    ms = None if motion is None else motion_spec(motion)
    if isinstance(ms, str):
        return ms
    hs = measurement_spec(measurement)
    if isinstance(hs, str):
        return hs
    if need_diagonal and not hs.diagonal:
        return "a non-diagonal measurement covariance R"
    if hs.moving and not step_sensor:
        return (
            f"measurement model {type(measurement).__name__} in this filter (a moving observer: compiled "
            "in the Kalman-family and CS-model filters, which pack it per step)"
        )
    return ms, hs
