"""Scenario simulators: seeded truth and measurements for Monte Carlo runs."""

from .base import Simulation, simulate_markov
from .bearings import BearingsOnlyTarget
from .linear import LinearCV
from .maneuver import Maneuver, ManeuveringTarget
from .multitarget import Leg, MultiTargetScenario, Target, crossing, maneuvering_radar, williams15
from .underwater import UnderwaterTOA
from .wsn import WSNRange

__all__ = ["Simulation", "simulate_markov", "WSNRange", "LinearCV", "ManeuveringTarget", "Maneuver", "UnderwaterTOA",
           "BearingsOnlyTarget", "MultiTargetScenario", "Target", "Leg", "crossing", "williams15", "maneuvering_radar"]
