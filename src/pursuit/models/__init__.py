"""Motion and measurement models, vectorised over any leading batch axes."""

from .linear_motion import LinearMotion
from .maneuver import ConstantTurn, CoordinatedTurn, CurrentStatistical, Jerk, Singer
from .measurement import LinearGaussian, RangeBearing, RangeSensors, TimeOfArrival, gaussian_loglik, wrap_angle
from .motion import ConstantAcceleration, ConstantVelocity
from .sensors import ObserverBearings
from .toa import PositionFix, l_array, toa_position, trilaterate, trilateration_jacobian

__all__ = [
    "ConstantVelocity",
    "ConstantAcceleration",
    "Singer",
    "CurrentStatistical",
    "Jerk",
    "ConstantTurn",
    "CoordinatedTurn",
    "LinearMotion",
    "PositionFix",
    "l_array",
    "toa_position",
    "trilaterate",
    "trilateration_jacobian",
    "LinearGaussian",
    "RangeSensors",
    "RangeBearing",
    "TimeOfArrival",
    "ObserverBearings",
    "gaussian_loglik",
    "wrap_angle",
]
