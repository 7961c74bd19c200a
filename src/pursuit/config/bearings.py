"""Registrations for bearings-only maneuvering-target tracking: the ``bearings`` scenario and the ``cs-nonlinear`` filter."""

from __future__ import annotations

from typing import Any

from ..filters.cs_nonlinear import NonlinearCSFilter
from ..registry import Param, params_from, register
from ..scenarios.bearings import BearingsOnlyTarget
from ..scenarios.maneuver import parse_schedule
from .filters import GATE, NAME


def _reanchor(where: str, build):
    try:
        return build()
    except TypeError as e:
        raise ValueError(f"{where}.type: {e}") from None
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


def _schedule(field: str, value: Any):
    return None if value is None else parse_schedule(value, field)


@register(
    "scenario",
    "bearings",
    "Bearings-only (azimuth, or azimuth and elevation) tracking of a maneuvering target from a weaving observer, "
    "sigma 1 mrad, 13-19 km; weak or strong maneuvers; state [x, vx, ax, y, vy, ay(, z, vz, az)]",
    params=(
        *params_from(
            BearingsOnlyTarget,
            ["dims", "strength"],
            choices={"dims": (2, 3), "strength": ("weak", "strong")},
            docs={
                "dims": "2: azimuth; 3: azimuth and elevation",
                "strength": "default schedule: weak (up to 2 m/s^2) or strong (up to 20 m/s^2) maneuvers",
            },
        ),
        Param(
            "maneuvers",
            "any",
            None,
            "[[scenario.maneuvers]] tables {axis, start, stop, accel} or {plane, start, stop, rate}; default: the strength's schedule",
            check=_schedule,
        ),
        *params_from(
            BearingsOnlyTarget,
            [
                "horizon",
                "dt",
                "sigma",
                "position",
                "velocity",
                "observer_position",
                "observer_velocity",
                "weave_amplitude",
                "weave_period",
                "prior_std",
            ],
            types={k: "vector" for k in ("position", "velocity", "observer_position", "observer_velocity", "prior_std")},
            docs={
                "horizon": "measurement epochs including the two before filtering starts (filter steps = horizon - 2)",
                "dt": "sampling period, s",
                "sigma": "angle noise standard deviation, rad",
                "position": "target position at t = 0, m",
                "velocity": "target velocity at t = 0, m/s",
                "observer_position": "observer position at t = 0, m",
                "observer_velocity": "observer base velocity, m/s",
                "weave_amplitude": "observer's x weave A sin(2 pi t / P), m (0: straight line, range unobservable)",
                "weave_period": "weave period P, s",
                "prior_std": "prior standard deviations of position, velocity, acceleration per axis (m, m/s, m/s^2)",
            },
        ),
    ),
    target=BearingsOnlyTarget,
)
def _bearings(where: str = "scenario", **kw) -> BearingsOnlyTarget:
    return _reanchor(where, lambda: BearingsOnlyTarget(**kw))


@register(
    "filter",
    "cs-nonlinear",
    "Current-statistical (CS) model filter with a joint [p, v, a]-per-axis state and an EKF or UKF update, for bearings "
    "or any nonlinear sensor; fixed, APCS-adaptive, or with alpha and the acceleration limit adapted from the residual test",
    params=(
        NAME,
        *params_from(
            NonlinearCSFilter,
            [
                "update",
                "adaptation",
                "alpha0",
                "a_max",
                "a_max_cap",
                "threshold",
                "false_alarm",
                "variance",
                "c_a",
                "sigma_a",
                "sigma_min",
                "sigma_max",
                "fading",
                "rho",
                "beta_s",
                "alpha_rule",
                "alpha_cap",
                "mean",
            ],
            choices={
                "update": ("ekf", "ukf"),
                "adaptation": ("none", "apcs", "limit"),
                "variance": ("displacement", "linear", "rayleigh", "fixed"),
                "fading": ("stf", "ratio", "none"),
                "alpha_rule": ("ratio", "fading", "none"),
                "mean": ("current", "zero"),
            },
            docs={
                "update": "measurement update: extended (ekf) or unscented (ukf)",
                "adaptation": "none: fixed CS; apcs: the per-axis APCS rules; limit: alpha and a_max raised by the residual test",
                "alpha0": "maneuver frequency without a maneuver (the fixed alpha of 'none'), 1/s",
                "a_max": "acceleration limit, m/s^2 (fixed for 'none', the lower bound for 'limit')",
                "a_max_cap": "upper bound of the adapted limit, m/s^2 (default 4 a_max)",
                "threshold": "detection threshold M on the residual statistic D (default 3)",
                "false_alarm": "alternatively the false-alarm probability (M from chi-square with the measurement's dof)",
                "variance": "sigma_a^2 law of 'apcs'",
                "c_a": "slope of the linear law, m/s^2",
                "sigma_a": "sigma_a of the fixed law, m/s^2",
                "sigma_min": "floor on sigma_a, m/s^2",
                "sigma_max": "ceiling on sigma_a of 'apcs', m/s^2 (default none)",
                "fading": "fading coefficient on detection",
                "rho": "strong-tracking forgetting factor",
                "beta_s": "strong-tracking weakening factor (>= 1)",
                "alpha_rule": "alpha on detection: alpha0*D/M, lambda*alpha0 or unchanged",
                "alpha_cap": "upper bound of alpha, 1/s",
                "mean": "current (CS) or zero (Singer prediction)",
            },
        ),
        GATE,
    ),
    target=NonlinearCSFilter,
)
def _cs_nonlinear(scenario, where="filter", **kw):
    axes = getattr(scenario, "axes", None)
    n = len(axes) if axes else 0
    return _reanchor(where, lambda: NonlinearCSFilter(scenario.measurement, dt=scenario.dt, axes=n, **kw))
