"""Motion and measurement models, vectorised over any leading batch axes."""

from .measurement import LinearGaussian, RangeBearing, RangeSensors, TimeOfArrival, gaussian_loglik, wrap_angle
from .maneuver import ConstantTurn, CoordinatedTurn, CurrentStatistical, Jerk, Singer
from .motion import ConstantAcceleration, ConstantVelocity

__all__ = [
    "ConstantVelocity",
    "ConstantAcceleration",
    "Singer",
    "CurrentStatistical",
    "Jerk",
    "ConstantTurn",
    "CoordinatedTurn",
    "LinearGaussian",
    "RangeSensors",
    "RangeBearing",
    "TimeOfArrival",
    "gaussian_loglik",
    "wrap_angle",
]
