"""Multi-target registrations: the built-in scenarios (``mt-*``), the trackers and the ``imm-cv`` per-track filter.

A tracker table names its per-track filter as a filter table built against
the scenario's matched models (``filter = {type = "kf"}``, the default), and
takes the detection probability and clutter density from the scenario unless
it sets its own (a mismatched tracker).  Built against a model of recorded
data instead (anything with ``motion`` and ``measurement``, as
``pursuit track --multi`` passes), it must set ``p_detect``,
``clutter_density`` and ``max_speed`` itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..filters.gaussian import CubatureKalmanFilter, ExtendedKalmanFilter, KalmanFilter, UnscentedKalmanFilter
from ..filters.imm import InteractingMultipleModel
from ..models.maneuver import ConstantTurn
from ..models.motion import ConstantVelocity
from ..multitarget.gnn import GNNTracker
from ..multitarget.epmht import EPMHTTracker
from ..multitarget.gmphd import BIRTH_MODES, GMPHDTracker
from ..multitarget.jpda import JPDATracker
from ..multitarget.mmpmht import MMPMHTTracker
from ..multitarget.pmht import PMHTTracker
from ..registry import Param, field_param, params_from, register
from ..scenarios.multitarget import MultiTargetScenario, crossing, maneuvering_radar, williams15
from .build import build_filter
from .filters import GATE


def _checked(where: str, build):
    try:
        return build()
    except ValueError as e:  # re-anchor the object's field name under the config's
        raise ValueError(f"{where}.{e}") from None


def _p_detect(field: str, value: float) -> float:
    if not 0.0 < value <= 1.0:
        raise ValueError(f"{field}: must lie in (0, 1], got {value!r}")
    return value


def _rate(field: str, value: float) -> float:
    if not value >= 0.0:
        raise ValueError(f"{field}: must be a non-negative number of false alarms per scan, got {value!r}")
    return value


CLUTTER = Param("clutter_rate", "float", 10.0, "mean number of false alarms per scan (Poisson), uniform over the region", own=True, check=_rate)
P_DETECT = Param("p_detect", "float", 0.9, "probability that a present target is detected in a scan", own=True, check=_p_detect)


@register(
    "scenario",
    "mt-crossing",
    "Two 2-D constant-velocity targets crossing in clutter, position fixes (Stone Soup tutorials' set-up)",
    params=(
        Param("clutter_rate", "float", 5.0, "mean number of false alarms per scan (Poisson), uniform over the region", own=True, check=_rate),
        P_DETECT,
        Param("steps", "int", 20, "number of scans", own=True),
    ),
    target=MultiTargetScenario,
)
def _crossing(where: str = "scenario", **kw) -> MultiTargetScenario:
    return _checked(where, lambda: crossing(**kw))


@register(
    "scenario",
    "mt-williams",
    "Williams (2015): four 2-D CV targets that meet mid-scenario, 10 false alarms per scan over 300 m x 300 m, 81 scans",
    params=(CLUTTER, P_DETECT),
    target=MultiTargetScenario,
)
def _williams(where: str = "scenario", **kw) -> MultiTargetScenario:
    return _checked(where, lambda: williams15(**kw))


@register(
    "scenario",
    "mt-maneuvering",
    "Maneuvering targets at radar scale (turns, accelerations), range-bearing radar, clutter",
    params=(Param("clutter_rate", "float", 20.0, "mean number of false alarms per scan (Poisson), uniform over the region", own=True, check=_rate), P_DETECT),
    target=MultiTargetScenario,
)
def _maneuvering(where: str = "scenario", **kw) -> MultiTargetScenario:
    return _checked(where, lambda: maneuvering_radar(**kw))


def _filter_table(field: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ValueError(f"{field}: expected a filter table such as {{type = \"kf\"}}, got {value!r}")
    return value


def _confirm(field: str, value: Any) -> tuple[int, int]:
    if len(value) != 2 or any(float(v) != int(v) or v < 1 for v in value):
        raise ValueError(f"{field}: expected [M, N], two positive integers with M <= N, got {list(value)!r}")
    m, n = int(value[0]), int(value[1])
    if m > n:
        raise ValueError(f"{field}: M must not exceed N, got [{m}, {n}]")
    return (m, n)


def _tracker_params(cls) -> tuple[Param, ...]:
    return (
        Param("name", "str", "", "label in tables and figures (default: GNN-<filter> / JPDA-<filter>)"),
        Param("filter", "any", {"type": "kf"}, "the per-track filter table {type = ...}, built against the scenario's models", own=True, check=_filter_table),
        Param("p_detect", "float", None, "detection probability the tracker assumes (default: the scenario's)", own=True, check=_p_detect),
        Param("clutter_density", "float", None, "false alarms per scan per unit measurement volume the tracker assumes (default: the scenario's)", own=True),
        *params_from(
            cls,
            ["gate", "capacity", "confirm", "max_misses", "max_speed"],
            types={"confirm": "vector"},
            checks={"confirm": _confirm},
            docs={
                "gate": "chi-square gate probability in (0, 1)",
                "capacity": "track slots per run",
                "confirm": "[M, N]: a tentative track is confirmed after M hits in N scans",
                "max_misses": "consecutive misses that delete a track",
                "max_speed": "largest target speed for two-point initiation (default: the scenario's)",
            },
        ),
    )


def _build_tracker(cls, scenario: Any, where: str, *, filter: dict[str, Any], p_detect, clutter_density, max_speed, **kw):
    simulated = isinstance(scenario, MultiTargetScenario)
    if not simulated and not (hasattr(scenario, "motion") and hasattr(scenario, "measurement")):
        raise ValueError(f"{where}.type: a tracker needs a multi-target scenario (scenario.type = \"mt-...\")")
    filt = build_filter(filter, scenario, f"{where}.filter")
    # Recorded data (`pursuit track --multi`: a model with .motion and .measurement) has no scenario to take
    # the detection and clutter model from, so the table must state them.
    if not simulated:
        for key, value in (("p_detect", p_detect), ("clutter_density", clutter_density), ("max_speed", max_speed)):
            if value is None:
                raise ValueError(f"{where}.{key}: required for recorded detections (there is no scenario to take it from)")
    p_detect = scenario.p_detect if p_detect is None else p_detect
    clutter_density = scenario.clutter_density if clutter_density is None else clutter_density
    if not clutter_density > 0:
        why = "the scenario has no clutter: set a small density" if clutter_density == 0 and simulated else f"got {clutter_density!r}"
        raise ValueError(f"{where}.clutter_density: must be positive ({why})")
    if max_speed is None:
        max_speed = scenario.max_speed
        if max_speed is None:
            raise ValueError(f"{where}.max_speed: required (the scenario states no largest target speed)")
    return _checked(where, lambda: cls(filt, p_detect, clutter_density, max_speed=max_speed, **kw))


@register("tracker", "gnn", "Global nearest neighbour: 2-D assignment per scan within a chi-square gate", params=_tracker_params(GNNTracker), target=GNNTracker)
def _gnn(scenario, where: str = "tracker", **kw):
    return _build_tracker(GNNTracker, scenario, where, **kw)


@register(
    "tracker",
    "jpda",
    "Joint probabilistic data association: exact joint events within clusters, moment-matched update",
    params=(*_tracker_params(JPDATracker), *params_from(JPDATracker, ["max_events"], docs={"max_events": "largest number of joint events enumerated exactly in one cluster"})),
    target=JPDATracker,
)
def _jpda(scenario, where: str = "tracker", **kw):
    return _build_tracker(JPDATracker, scenario, where, **kw)


_PMHT_DOCS = {
    "batch": "scans per EM window (sliding by one scan)",
    "max_iter": "largest number of EM iterations per window",
    "tol": "stop EM when the log-likelihood's relative change is at most this",
    "estimate_priors": "re-estimate the assignment priors at each M-step (default: fixed, from the expected counts)",
    "hit_weight": "a track's weight W at the newest scan at or above which the scan counts as a hit",
}


def _volume_for(scenario: Any, kw: dict[str, Any]) -> dict[str, Any]:
    # PMHT's clutter prior needs V; a simulated scenario knows it (recorded data must give estimate_priors=false)
    if kw.get("estimate_priors") and getattr(scenario, "clutter_volume", None) is not None:
        kw["volume"] = scenario.clutter_volume
    return kw


@register(
    "tracker",
    "pmht",
    "Probabilistic multi-hypothesis tracker: EM over a sliding window of scans, a smoother per track (KF per-track filter)",
    params=(*_tracker_params(PMHTTracker), *params_from(PMHTTracker, list(_PMHT_DOCS), docs=_PMHT_DOCS)),
    target=PMHTTracker,
)
def _pmht(scenario, where: str = "tracker", **kw):
    return _build_tracker(PMHTTracker, scenario, where, **_volume_for(scenario, kw))


@register(
    "tracker",
    "epmht",
    "PMHT for maneuvering targets: the maneuver input as a Markov chain estimated inside EM (levels per axis)",
    params=(
        *_tracker_params(EPMHTTracker),
        *params_from(EPMHTTracker, list(_PMHT_DOCS), docs=_PMHT_DOCS),
        *params_from(
            EPMHTTracker,
            ["levels", "stay"],
            types={"levels": "vector"},
            docs={"levels": "the maneuver input's levels per axis (acceleration units)", "stay": "the Markov chain's probability of keeping its level"},
        ),
    ),
    target=EPMHTTracker,
)
def _epmht(scenario, where: str = "tracker", **kw):
    if "levels" in kw:
        kw["levels"] = tuple(float(v) for v in kw["levels"])
    return _build_tracker(EPMHTTracker, scenario, where, **_volume_for(scenario, kw))


@register(
    "tracker",
    "mmpmht",
    "Multiple-model PMHT: process-noise levels (exact EM) or coordinated turns (an IMM smoother in the M-step) as a Markov chain",
    params=(
        *_tracker_params(MMPMHTTracker),
        *params_from(MMPMHTTracker, list(_PMHT_DOCS), docs=_PMHT_DOCS),
        *params_from(
            MMPMHTTracker,
            ["noise_scales", "turn_rates", "stay", "transition"],
            types={"noise_scales": "vector", "turn_rates": "vector", "transition": "matrix"},
            docs={
                "noise_scales": "the modes' process noise as multiples of the motion model's Q (default [1, 100]; all 1 with turn_rates)",
                "turn_rates": "the modes' turn rates in rad/s (0: constant velocity), one per mode; the M-step is then an IMM smoother",
                "stay": "the Markov chain's probability of keeping its mode",
                "transition": "the full Markov matrix of the modes (list of rows) instead of stay",
            },
        ),
    ),
    target=MMPMHTTracker,
)
def _mmpmht(scenario, where: str = "tracker", **kw):
    for key in ("noise_scales", "turn_rates"):
        if kw.get(key) is not None:
            kw[key] = tuple(float(v) for v in kw[key])
    if kw.get("transition") is not None:
        kw["transition"] = tuple(tuple(float(v) for v in row) for row in kw["transition"])
    return _build_tracker(MMPMHTTracker, scenario, where, **_volume_for(scenario, kw))


@register(
    "tracker",
    "gmphd",
    "Gaussian-mixture PHD filter (Vo & Ma 2006): pruning, merging, estimates of weight >= extract, labels by tags",
    params=(
        Param("name", "str", "", "label in tables and figures (default: GMPHD-<filter>)"),
        Param("filter", "any", {"type": "kf"}, "the component filter table {type = ...}, built against the scenario's models", own=True, check=_filter_table),
        Param("p_detect", "float", None, "detection probability the filter assumes (default: the scenario's)", own=True, check=_p_detect),
        Param("clutter_density", "float", None, "false alarms per scan per unit measurement volume the filter assumes (default: the scenario's)", own=True),
        *params_from(
            GMPHDTracker,
            ["p_survive", "birth", "birth_rate", "max_speed", "velocity_sigma", "prune", "merge", "max_components", "extract", "capacity"],
            choices={"birth": BIRTH_MODES},
            types={"birth": "str"},
            docs={
                "p_survive": "probability that a target survives from one scan to the next",
                "birth": "adaptive births from the detections: two-point (pairs of scans) or one-point (velocity spread)",
                "birth_rate": "expected number of new targets per scan, shared over the detections",
                "max_speed": "largest target speed for two-point births (default: the scenario's)",
                "velocity_sigma": "velocity standard deviation of a one-point birth",
                "prune": "components lighter than this are dropped",
                "merge": "components closer than this (squared Mahalanobis distance) are merged",
                "max_components": "most components kept per run",
                "extract": "a component of at least this weight gives an estimate",
                "capacity": "estimate slots per run",
            },
        ),
    ),
    target=GMPHDTracker,
)
def _gmphd(scenario, where: str = "tracker", *, filter, p_detect, clutter_density, max_speed, **kw):
    filt = build_filter(filter, scenario, f"{where}.filter")
    p_detect = scenario.p_detect if p_detect is None else p_detect
    clutter_density = scenario.clutter_density if clutter_density is None else clutter_density
    if max_speed is None:
        max_speed = getattr(scenario, "max_speed", None)
    return _checked(where, lambda: GMPHDTracker(filt, p_detect, clutter_density, max_speed=max_speed, **kw))


# --------------------------------------------------------------------------
# an IMM per track over the scenario's constant-velocity state
# --------------------------------------------------------------------------
_MODE_FILTERS = {"kf": KalmanFilter, "ekf": ExtendedKalmanFilter, "ukf": UnscentedKalmanFilter, "ckf": CubatureKalmanFilter}
_MODE_KEYS = ("q", "omega")


def _modes(field: str, value: Any) -> list[dict[str, float]]:
    if not isinstance(value, list) or not value or not all(isinstance(m, dict) for m in value):
        raise ValueError(f"{field}: expected a list of mode tables such as [{{q = 1.0}}, {{omega = 0.05}}]")
    out = []
    for i, mode in enumerate(value):
        for key, v in mode.items():
            if key not in _MODE_KEYS:
                raise ValueError(f"{field}[{i}].{key}: unknown key for a mode (known: {', '.join(_MODE_KEYS)})")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise ValueError(f"{field}[{i}].{key}: expected a finite number, got {v!r}")
        if mode.get("q", 0.0) < 0:
            raise ValueError(f"{field}[{i}].q: must be a non-negative acceleration variance, got {mode['q']!r}")
        out.append({k: float(v) for k, v in mode.items()})
    return out


def _mode_filter(cls, motion: Any, measurement: Any, name: str, where: str) -> Any:
    try:
        return cls(motion, measurement, name=name)
    except TypeError as e:  # a KF on a nonlinear sensor
        raise ValueError(f"{where}: {e}") from None


def _mode_label(mode: dict[str, float], motion: ConstantVelocity) -> str:
    q = mode.get("q", motion.q)
    omega = mode.get("omega", 0.0)
    return f"CV q={q:g}" if omega == 0.0 else f"CT {omega:+g} rad/s q={q:g}"


def _imm_transition(field: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float, list)):
        raise ValueError(f"{field}: expected a staying probability or a matrix (list of rows), got {value!r}")
    return value


def _cv_layout(scenario: Any, where: str) -> Any:
    """The scenario's motion model, refused (naming the field) unless it is a constant-velocity one."""
    motion = getattr(scenario, "motion", None)
    if not isinstance(motion, ConstantVelocity):
        raise ValueError(
            f"{where}.type: imm-cv needs a scenario with a constant-velocity motion model (state [x, vx, y, vy, ...]), "
            f"got {type(motion).__name__}"
        )
    return motion


def _cv_mode(motion: ConstantVelocity, mode: dict[str, float]) -> Any:
    """One mode's motion model on the scenario's CV state (errors name the mode's key)."""
    q = mode.get("q", motion.q)
    omega = mode.get("omega", 0.0)
    if omega == 0.0:
        return ConstantVelocity(ndim=motion.ndim, dt=motion.dt, q=q, noise=motion.noise, layout=motion.layout)
    if motion.ndim not in (2, 3):
        raise ValueError(f"omega: a turn needs a 2-D or 3-D state, the scenario's has {motion.ndim} axes")
    if motion.layout != "axis":
        raise ValueError(f"omega: a turning mode needs the state per axis [x, vx, y, vy, ...], the scenario's CV has layout {motion.layout!r}")
    if motion.noise != "discrete":
        raise ValueError(f"omega: a turning mode has discrete white-noise acceleration only; the scenario's CV is {motion.noise!r}")
    return ConstantTurn(omega=omega, q=q, ndim=motion.ndim, dt=motion.dt)


@register(
    "filter",
    "imm-cv",
    "IMM over modes on the scenario's constant-velocity state: CV with its own q, or a constant turn at rate omega (rad/s)",
    params=(
        field_param(InteractingMultipleModel, "name", doc="label in tables and figures (default: IMM)"),
        Param(
            "modes",
            "any",
            [{}, {"omega": 0.05}, {"omega": -0.05}],
            "one table per mode: {q = acceleration variance (default: the scenario's), omega = turn rate in rad/s (default 0: CV)}",
            own=True,
            check=_modes,
        ),
        Param("mode_filter", "str", "ekf", "the filter of every mode (ekf: also exact for a linear sensor)", own=True, choices=tuple(_MODE_FILTERS)),
        field_param(InteractingMultipleModel, "transition", doc="staying probability p_ii, or the full Markov matrix", check=_imm_transition),
        field_param(InteractingMultipleModel, "initial_probs", type="vector", doc="initial mode probabilities (default uniform)"),
        field_param(InteractingMultipleModel, "gate", doc="chi-square gate probability: reject a measurement outside every mode's gate (default: no gate)", check=GATE.check),
    ),
    target=InteractingMultipleModel,
)
def _imm_cv(scenario, where: str = "filter", *, name: str, modes, mode_filter: str, transition, initial_probs, gate):
    motion = _cv_layout(scenario, where)
    cls = _MODE_FILTERS[mode_filter]
    filters = []
    for i, mode in enumerate(modes):
        model = _checked(f"{where}.modes[{i}]", lambda: _cv_mode(motion, mode))
        filters.append(_mode_filter(cls, model, scenario.measurement, f"{mode_filter.upper()}-{_mode_label(mode, motion)}", f"{where}.mode_filter"))
    return _checked(where, lambda: InteractingMultipleModel(filters, transition, initial_probs, name=name, gate=gate))
