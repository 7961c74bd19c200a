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
from ..filters.gaussian import ExtendedKalmanFilter, KalmanFilter
from ..filters.imm import InteractingMultipleModel
from ..models import maneuver as mm
from ..registry import Param, field_default, field_param, params_from, register
from ..scenarios.maneuver import ManeuveringTarget, parse_schedule
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


# the class's default schedule, as the TOML tables that spell it (what `pursuit list -v` shows)
_DEFAULT_TABLES = [
    {"axis": m.axis, "start": m.start, "stop": m.stop, "accel": m.accel} for m in field_default(ManeuveringTarget, "maneuvers")
]


@register(
    "scenario",
    "maneuver-3d",
    "Target maneuvering on a schedule of accelerations and turns in up to 3 axes, position measured per axis; state [x, vx, ax, ...]",
    params=(
        *params_from(
            ManeuveringTarget,
            ["horizon", "dt", "position", "velocity", "R"],
            types={"position": "vector", "velocity": "vector"},
            docs={
                "horizon": "measurement epochs including the two for initialisation (filter steps = horizon - 2)",
                "dt": "sampling period, s",
                "position": "initial position per axis, m (1 to 3 axes)",
                "velocity": "initial velocity per axis, m/s",
                "R": "measurement noise variance per axis, m^2",
            },
        ),
        Param(
            "maneuvers",
            "any",
            _DEFAULT_TABLES,
            "[[scenario.maneuvers]] tables: {axis, start, stop, accel} or {plane, start, stop, rate (deg/s)}; default: a schedule of accelerations on all three axes (see docs/maneuvering.md)",
            check=_schedule,
        ),
        *params_from(
            ManeuveringTarget,
            ["init", "init_accel_std"],
            choices={"init": ("two-point", "sampled")},
            docs={
                "init": "prior: two-point differencing or sampled from N(truth, P0)",
                "init_accel_std": "prior standard deviation of the acceleration, m/s^2",
            },
        ),
    ),
    target=ManeuveringTarget,
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


def _singer_axes(scenario: Any, where: str) -> int:
    """Axes of a [p, v, a]-per-axis scenario for the Singer filters: measured per axis, or nonlinear (bearings) with ``axes``."""
    if callable(getattr(scenario.measurement, "matrix", None)):
        return _axes_of(scenario, where)
    axes = getattr(scenario, "axes", None)
    if not axes or len(getattr(scenario, "state_labels", ())) != 3 * len(axes):
        raise ValueError(f"{where}.type: needs a scenario with a [p, v, a] state per axis (e.g. maneuver-3d, bearings)")
    return len(axes)


def _singer_filter(model: Any, scenario: Any, **kw) -> Any:
    """A Kalman filter for a linear measurement, an EKF for a nonlinear one (bearings)."""
    cls = KalmanFilter if callable(getattr(scenario.measurement, "matrix", None)) else ExtendedKalmanFilter
    return cls(model, scenario.measurement, **kw)


@register(
    "filter",
    "cs",
    "Standard current-statistical (CS) model Kalman filter, per axis",
    params=(
        NAME,
        *params_from(
            CurrentStatisticalFilter,
            ["alpha", "a_max", "a_neg_max", "sigma_min", "mean"],
            choices={"mean": ("current", "zero")},
            docs={
                "alpha": "maneuver frequency alpha, 1/s (paper: 0.001)",
                "a_max": "acceleration limit, m/s^2 (paper: 100)",
                "a_neg_max": "negative acceleration limit (magnitude); default a_max",
                "sigma_min": "floor on sigma_a, m/s^2",
                "mean": "current: a_bar = a(k|k) (CS); zero: Singer prediction",
            },
        ),
        GATE,
    ),
    target=CurrentStatisticalFilter,
)
def _cs(scenario, where="filter", **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: CurrentStatisticalFilter(scenario.measurement, dt=scenario.dt, **kw))


@register(
    "filter",
    "apcs",
    "Parameter-adaptive current-statistical filter (Fang & Yang, \"Maneuvering target tracking algorithm based on parameter-adaptive CS model\"): displacement-based variance, chi-square maneuver detection, fading and alpha",
    params=(
        NAME,
        *params_from(
            AdaptiveCSFilter,
            ["alpha0", "a_max", "threshold", "false_alarm", "variance", "c_a", "sigma_a", "sigma_min", "sigma_max", "fading", "rho", "beta_s", "alpha_rule", "alpha_cap", "mean"],
            choices={
                "variance": ("displacement", "linear", "rayleigh", "fixed"),
                "fading": ("stf", "ratio", "none"),
                "alpha_rule": ("ratio", "fading", "none"),
                "mean": ("current", "zero"),
            },
            docs={
                "alpha0": "maneuver frequency without maneuver, 1/s",
                "a_max": "initial acceleration limit, m/s^2",
                "threshold": "detection threshold M on D (paper: 3)",
                "false_alarm": "alternatively the false-alarm probability p (M from chi-square, 1 dof)",
                "variance": "sigma_a^2 law",
                "c_a": "slope of the linear law, m/s^2",
                "sigma_a": "sigma_a of the fixed law, m/s^2",
                "sigma_min": "floor on sigma_a, m/s^2",
                "sigma_max": "ceiling on sigma_a, m/s^2 (default none)",
                "fading": "fading coefficient on detection",
                "rho": "STF forgetting factor",
                "beta_s": "STF weakening factor (>= 1)",
                "alpha_rule": "alpha on detection: alpha0*D/M, lambda*alpha0 or unchanged",
                "alpha_cap": "upper limit of alpha, 1/s",
                "mean": "current (CS) or zero (Singer prediction)",
            },
        ),
        GATE,
    ),
    target=AdaptiveCSFilter,
)
def _apcs(scenario, where="filter", **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: AdaptiveCSFilter(scenario.measurement, dt=scenario.dt, **kw))


@register(
    "filter",
    "ms",
    "Modified Singer filter: alpha and sigma estimated online from the acceleration autocorrelation",
    params=(
        NAME,
        *params_from(
            ModifiedSingerFilter,
            ["alpha_init", "sigma_init", "warmup", "tau_min", "sigma_min", "forgetting"],
            docs={
                "alpha_init": "alpha during the warm-up, 1/s",
                "sigma_init": "sigma_m during the warm-up, m/s^2",
                "warmup": "measured steps before the estimates are used",
                "tau_min": "shortest maneuver time constant, s",
                "sigma_min": "floor on sigma_m, m/s^2",
                "forgetting": "forgetting factor of the running averages (default: 1/k averaging)",
            },
        ),
        GATE,
    ),
    target=ModifiedSingerFilter,
)
def _ms(scenario, where="filter", **kw):
    _axes_of(scenario, where)
    return _reanchor(where, lambda: ModifiedSingerFilter(scenario.measurement, dt=scenario.dt, **kw))


def _singer_sigma(where: str, sigma, a_max, p_max, p_zero) -> float:
    if sigma is not None:
        return sigma
    try:
        return float(np.sqrt(mm.singer_sigma2(a_max, p_max, p_zero)))
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


# sigma and Singer's rule are the builder's: the model needs sigma, the rule gives it from a_max, p_max, p_zero
_SINGER_PARAMS = (
    field_param(mm.Singer, "alpha", doc="maneuver frequency 1/tau, 1/s"),
    Param("sigma", "float", None, "acceleration standard deviation, m/s^2 (default: Singer's rule from a_max, p_max, p_zero)", own=True),
    Param("a_max", "float", 100.0, "Singer's rule: largest acceleration, m/s^2", own=True),
    Param("p_max", "float", 0.1, "Singer's rule: probability of +-a_max", own=True),
    Param("p_zero", "float", 0.5, "Singer's rule: probability of no acceleration", own=True),
)


@register(
    "filter",
    "singer",
    "Kalman filter with the Singer model on every axis (an EKF for a nonlinear measurement such as bearings)",
    params=(Param("name", "str", "Singer", NAME.doc, own=True), *_SINGER_PARAMS, GATE),
    target=KalmanFilter,
)
def _singer(scenario, where="filter", *, name: str, alpha: float, sigma: float | None, a_max: float, p_max: float, p_zero: float, gate):
    axes = _singer_axes(scenario, where)
    s = _singer_sigma(where, sigma, a_max, p_max, p_zero)
    return _reanchor(
        where,
        lambda: _singer_filter(mm.Singer(alpha=alpha, sigma=s, ndim=axes, dt=scenario.dt), scenario, name=name or "Singer", gate=gate),
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


_IMM_PARAMS = (
    field_param(InteractingMultipleModel, "transition", doc="staying probability p_ii, or the full Markov matrix", check=_transition),
    field_param(InteractingMultipleModel, "initial_probs", type="vector", doc="initial mode probabilities (default uniform)"),
    IMM_GATE,
)


@register(
    "filter",
    "imm-singer",
    "IMM over Singer-model Kalman filters (EKFs for bearings) with different (alpha, sigma) (Tan et al.)",
    params=(
        Param("name", "str", "IMM-Singer", NAME.doc, own=True),
        Param("models", "matrix", [[1 / 60, 5.0], [1 / 20, 20.0], [1 / 5, 60.0]], "one [alpha (1/s), sigma (m/s^2)] row per model", own=True),
        *_IMM_PARAMS,
    ),
    target=InteractingMultipleModel,
)
def _imm_singer(scenario, where="filter", *, name: str, models, transition, initial_probs, gate):
    axes = _singer_axes(scenario, where)
    rows = np.atleast_2d(np.asarray(models, dtype=float))
    if rows.ndim != 2 or rows.shape[1] != 2:
        raise ValueError(f"{where}.models: expected rows [alpha, sigma], got shape {rows.shape}")
    filters = []
    for i, (a, s) in enumerate(rows):
        model = _reanchor(f"{where}.models[{i}]", lambda: mm.Singer(alpha=a, sigma=s, ndim=axes, dt=scenario.dt))
        # the mode's name in legends: the time constant reads better than α = 0.0166667 (1/s)
        label = f"Singer τ = {1 / a:.3g} s, σ = {s:.3g} m/s²" if a > 0 else f"Singer α = 0, σ = {s:.3g} m/s²"
        filters.append(_singer_filter(model, scenario, name=label))
    return _reanchor(where, lambda: InteractingMultipleModel(filters, transition, initial_probs, name=name or "IMM-Singer", gate=gate))


@register(
    "filter",
    "imm",
    "IMM over any filters built for the scenario (each [[...models]] entry is a filter table)",
    params=(
        field_param(InteractingMultipleModel, "name", doc=NAME.doc),
        Param("models", "any", registry.REQUIRED, "list of filter tables {type = ..., ...}", own=True),
        *_IMM_PARAMS,
    ),
    target=InteractingMultipleModel,
)
def _imm(scenario, where="filter", *, name: str, models, transition, initial_probs, gate):
    if not isinstance(models, list) or not models or not all(isinstance(m, dict) for m in models):
        raise ValueError(f"{where}.models: expected a list of filter tables")
    filters = [build_filter(entry, scenario, f"{where}.models[{i}]") for i, entry in enumerate(models)]
    return _reanchor(where, lambda: InteractingMultipleModel(filters, transition, initial_probs, name=name, gate=gate))
