"""Multi-target registrations: the built-in scenarios (``mt-*``) and the trackers (``gnn``, ``jpda``).

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

from ..multitarget.gnn import GNNTracker
from ..multitarget.epmht import EPMHTTracker
from ..multitarget.gmphd import BIRTH_MODES, GMPHDTracker
from ..multitarget.jpda import JPDATracker
from ..multitarget.pmht import PMHTTracker
from ..registry import Param, params_from, register
from ..scenarios.multitarget import MultiTargetScenario, crossing, maneuvering_radar, williams15
from .build import build_filter


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
