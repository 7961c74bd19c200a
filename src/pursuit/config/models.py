"""Models listed by ``pursuit list`` (scenarios build them; listed for reference)."""

from __future__ import annotations

from ..models import measurement, motion
from ..models.linear_motion import LinearMotion
from ..models.toa import PositionFix
from ..registry import register

_MODELS = {
    "cv": ("Constant velocity in 1-3 D (discrete or continuous white-noise acceleration)", motion.ConstantVelocity),
    "ca": ("Constant acceleration in 1-3 D (discrete Wiener-process or continuous white-noise jerk)", motion.ConstantAcceleration),
    "linear": ("Linear measurement z = Hx + v", measurement.LinearGaussian),
    "range": ("Ranges to fixed anchors", measurement.RangeSensors),
    "range-bearing": ("Range and bearing from one 2-D sensor", measurement.RangeBearing),
    "toa": ("Times of arrival (range / c) at fixed anchors", measurement.TimeOfArrival),
    "linear-motion": ("Linear motion x_k = F x_(k-1) + w, w ~ N(0, Q), from given F and Q", LinearMotion),
    "position-fix": ("Position fix z = p + v with step-dependent R (closed-form TOA positioning)", PositionFix),
}

for _name, (_summary, _cls) in _MODELS.items():
    register("model", _name, f"{_summary} [{_cls.__module__}.{_cls.__qualname__}]")(_cls)
