"""Registrations for maneuvering-target tracking: models, the ``maneuver-3d`` scenario, CS-family and IMM filters.

The experiment kind ``maneuver`` (paper P4) lives in
:mod:`pursuit.experiments.maneuver`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import registry
from ..filters.cs import (
    AdaptiveCSFilter,
    CurrentStatisticalFilter,
    ModifiedSingerFilter,
)
from ..filters.gaussian import KalmanFilter
from ..filters.imm import InteractingMultipleModel
from ..models import maneuver as mm
from ..registry import Param, register
from ..scenarios.maneuver import DEFAULT_SCHEDULE, ManeuveringTarget, parse_schedule
from .build import build_filter
from .filters import GATE, NAME

# --------------------------------------------------------------------------
# models (listed by `pursuit list models`)
# --------------------------------------------------------------------------
_MODELS = {
    "singer": ("Singer: exponentially correlated acceleration per axis [p, v, a]", mm.Singer),
    "cs": ("Current statistical (Zhou): Singer about the current acceleration, Rayleigh variance", mm.CurrentStatistical),
    "jerk": ("Jerk (Mehrotra-Mahapatra): exponentially correlated jerk per axis [p, v, a, j]", mm.Jerk),
    "ct": ("Constant turn at a known rate in the x-y plane", mm.ConstantTurn),
    "coordinated-turn": ("Nearly coordinated turn with the rate in the state (EKF/UKF/CKF)", mm.CoordinatedTurn),
}
for _name, (_summary, _cls) in _MODELS.items():
    register("model", _name, f"{_summary} [{_cls.__module__}.{_cls.__qualname__}]")(_cls)


def _reanchor(where: str, build):
    try:
        return build()
    except TypeError as e:
        raise ValueError(f"{where}.type: {e}") from None
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


# --------------------------------------------------------------------------
# scenario
# --------------------------------------------------------------------------
def _schedule(field: str, value: Any):
    return parse_schedule(value, field)


_DEFAULT_TABLES = [{"axis": m.axis, "start": m.start, "stop": m.stop, "accel": m.accel} for m in DEFAULT_SCHEDULE]


@register(
    "scenario",
    "maneuver-3d",
    "Target maneuvering on a schedule of accelerations and turns in up to 3 axes, position measured per axis; state [x, vx, ax, ...]",
    params=(
        Param("horizon", "int", 100, "measurement epochs including the two for initialisation (filter steps = horizon - 2)"),
        Param("dt", "float", 1.0, "sampling period, s"),
        Param("position", "vector", [200e3, 200e3, 200e3], "initial position per axis, m (1 to 3 axes)"),
        Param("velocity", "vector", [0.0, 400.0, 10.0], "initial velocity per axis, m/s"),
        Param("R", "float", 20.0, "measurement noise variance per axis, m^2"),
        Param(
            "maneuvers",
            "any",
            _DEFAULT_TABLES,
            "[[scenario.maneuvers]] tables: {axis, start, stop, accel} or {plane, start, stop, rate (deg/s)}; default: a schedule of accelerations on all three axes (see docs/maneuvering.md)",
            check=_schedule,
        ),
        Param("init", "str", "two-point", "prior: two-point differencing or sampled from N(truth, P0)", choices=("two-point", "sampled")),
        Param("init_accel_std", "float", 100.0 / 3.0, "prior standard deviation of the acceleration, m/s^2"),
    ),
)
def _maneuver_scenario(where: str = "scenario", **kw) -> ManeuveringTarget:
    try:
        return ManeuveringTarget(**kw)
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


# --------------------------------------------------------------------------
# filters
# --------------------------------------------------------------------------
def _axes_of(scenario: Any, where: str) -> int:
    H = np.asarray(scenario.measurement.matrix(None)) if callable(getattr(scenario.measurement, "matrix", None)) else None
    if H is None or H.shape[1] != 3 * H.shape[0]:
        raise ValueError(f"{where}.type: needs a scenario with a [p, v, a] state per measured axis (e.g. maneuver-3d)")
    return H.shape[0]


_CS_PARAMS = (
    NAME,
    Param("alpha", "float", 0.001, "maneuver frequency alpha, 1/s (paper: 0.001)"),
    Param("a_max", "float", 100.0, "acceleration limit, m/s^2 (paper: 100)"),
    Param("a_neg_max", "float", None, "negative acceleration limit (magnitude); default a_max"),
    Param("sigma_min", "float", 0.0, "floor on sigma_a, m/s^2"),
    Param("mean", "str", "current", "current: a_bar = a(k|k) (CS); zero: Singer prediction", choices=("current", "zero")),
    GATE,
)


@register("filter", "cs", "Standard current-statistical (CS) model Kalman filter, per axis", params=_CS_PARAMS)
def _cs(scenario, where="filter", name=None, **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: CurrentStatisticalFilter(scenario.measurement, dt=scenario.dt, name=name or "", **kw))


@register(
    "filter",
    "apcs",
    "Parameter-adaptive current-statistical filter (Fang & Yang, \"Maneuvering target tracking algorithm based on parameter-adaptive CS model\"): displacement-based variance, chi-square maneuver detection, fading and alpha",
    params=(
        NAME,
        Param("alpha0", "float", 0.001, "maneuver frequency without maneuver, 1/s"),
        Param("a_max", "float", 100.0, "initial acceleration limit, m/s^2"),
        Param("threshold", "float", 3.0, "detection threshold M on D (paper: 3)"),
        Param("false_alarm", "float", None, "alternatively the false-alarm probability p (M from chi-square, 1 dof)"),
        Param("variance", "str", "displacement", "sigma_a^2 law", choices=("displacement", "linear", "rayleigh", "fixed")),
        Param("c_a", "float", 1.0, "slope of the linear law, m/s^2"),
        Param("sigma_a", "float", 1.0, "sigma_a of the fixed law, m/s^2"),
        Param("sigma_min", "float", 0.1, "floor on sigma_a, m/s^2"),
        Param("sigma_max", "float", None, "ceiling on sigma_a, m/s^2 (default none)"),
        Param("fading", "str", "stf", "fading coefficient on detection", choices=("stf", "ratio", "none")),
        Param("rho", "float", 0.95, "STF forgetting factor"),
        Param("beta_s", "float", 1.0, "STF weakening factor (>= 1)"),
        Param("alpha_rule", "str", "ratio", "alpha on detection: alpha0*D/M, lambda*alpha0 or unchanged", choices=("ratio", "fading", "none")),
        Param("alpha_cap", "float", 1.0, "upper limit of alpha, 1/s"),
        Param("mean", "str", "current", "current (CS) or zero (Singer prediction)", choices=("current", "zero")),
        GATE,
    ),
)
def _apcs(scenario, where="filter", name=None, **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: AdaptiveCSFilter(scenario.measurement, dt=scenario.dt, name=name or "", **kw))


@register(
    "filter",
    "ms",
    "Modified Singer filter: alpha and sigma estimated online from the acceleration autocorrelation",
    params=(
        NAME,
        Param("alpha_init", "float", 0.05, "alpha during the warm-up, 1/s"),
        Param("sigma_init", "float", 10.0, "sigma_m during the warm-up, m/s^2"),
        Param("warmup", "int", 5, "measured steps before the estimates are used"),
        Param("tau_min", "float", 1.0, "shortest maneuver time constant, s"),
        Param("sigma_min", "float", 0.1, "floor on sigma_m, m/s^2"),
        Param("forgetting", "float", None, "forgetting factor of the running averages (default: 1/k averaging)"),
        GATE,
    ),
)
def _ms(scenario, where="filter", name=None, **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: ModifiedSingerFilter(scenario.measurement, dt=scenario.dt, name=name or "", **kw))


def _singer_sigma(where: str, sigma, a_max, p_max, p_zero) -> float:
    if sigma is not None:
        return sigma
    try:
        return float(np.sqrt(mm.singer_sigma2(a_max, p_max, p_zero)))
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


_SINGER_PARAMS = (
    Param("alpha", "float", 0.05, "maneuver frequency 1/tau, 1/s"),
    Param("sigma", "float", None, "acceleration standard deviation, m/s^2 (default: Singer's rule from a_max, p_max, p_zero)"),
    Param("a_max", "float", 100.0, "Singer's rule: largest acceleration, m/s^2"),
    Param("p_max", "float", 0.1, "Singer's rule: probability of +-a_max"),
    Param("p_zero", "float", 0.5, "Singer's rule: probability of no acceleration"),
)


@register("filter", "singer", "Kalman filter with the Singer model on every axis", params=(NAME, *_SINGER_PARAMS, GATE))
def _singer(scenario, where="filter", name=None, alpha=0.05, sigma=None, a_max=100.0, p_max=0.1, p_zero=0.5, gate=None):
    axes = _axes_of(scenario, where)
    s = _singer_sigma(where, sigma, a_max, p_max, p_zero)
    return _reanchor(
        where,
        lambda: KalmanFilter(
            mm.Singer(alpha=alpha, sigma=s, ndim=axes, dt=scenario.dt), scenario.measurement, name=name or "Singer", gate=gate
        ),
    )


IMM_GATE = Param(
    "gate",
    "float",
    None,
    "chi-square gate probability: reject a measurement outside every mode's gate (NIS above this quantile in all modes; default: no gate)",
    check=GATE.check,
)


def _transition(field: str, value: Any):
    if isinstance(value, bool) or not isinstance(value, (int, float, list)):
        raise ValueError(f"{field}: expected a staying probability or a matrix (list of rows)")
    return value


@register(
    "filter",
    "imm-singer",
    "IMM over Singer-model Kalman filters with different (alpha, sigma) (Tan et al.)",
    params=(
        NAME,
        Param("models", "matrix", [[1 / 60, 5.0], [1 / 20, 20.0], [1 / 5, 60.0]], "one [alpha (1/s), sigma (m/s^2)] row per model"),
        Param("transition", "any", 0.95, "staying probability p_ii, or the full Markov matrix", check=_transition),
        Param("initial_probs", "vector", None, "initial mode probabilities (default uniform)"),
        IMM_GATE,
    ),
)
def _imm_singer(scenario, where="filter", name=None, models=None, transition=0.95, initial_probs=None, gate=None):
    axes = _axes_of(scenario, where)
    rows = np.atleast_2d(np.asarray(models, dtype=float))
    if rows.ndim != 2 or rows.shape[1] != 2:
        raise ValueError(f"{where}.models: expected rows [alpha, sigma], got shape {rows.shape}")
    filters = []
    for i, (a, s) in enumerate(rows):
        model = _reanchor(f"{where}.models[{i}]", lambda: mm.Singer(alpha=a, sigma=s, ndim=axes, dt=scenario.dt))
        # the mode's name in legends: the time constant reads better than α = 0.0166667 (1/s)
        label = f"Singer τ = {1 / a:.3g} s, σ = {s:.3g} m/s²" if a > 0 else f"Singer α = 0, σ = {s:.3g} m/s²"
        filters.append(KalmanFilter(model, scenario.measurement, name=label))
    return _reanchor(where, lambda: InteractingMultipleModel(filters, transition, initial_probs, name=name or "IMM-Singer", gate=gate))


@register(
    "filter",
    "imm",
    "IMM over any filters built for the scenario (each [[...models]] entry is a filter table)",
    params=(
        NAME,
        Param("models", "any", registry.REQUIRED, "list of filter tables {type = ..., ...}"),
        Param("transition", "any", 0.95, "staying probability p_ii, or the full Markov matrix", check=_transition),
        Param("initial_probs", "vector", None, "initial mode probabilities (default uniform)"),
        IMM_GATE,
    ),
)
def _imm(scenario, where="filter", name=None, models=None, transition=0.95, initial_probs=None, gate=None):
    if not isinstance(models, list) or not models or not all(isinstance(m, dict) for m in models):
        raise ValueError(f"{where}.models: expected a list of filter tables")
    filters = [build_filter(entry, scenario, f"{where}.models[{i}]") for i, entry in enumerate(models)]
    return _reanchor(where, lambda: InteractingMultipleModel(filters, transition, initial_probs, name=name or "IMM", gate=gate))
