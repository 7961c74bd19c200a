"""Motion models of a MODEL.toml: ``[motion]`` (cv, ca, ct, singer) and ``[imm]`` over mixed motions.

``[motion]`` names one model; ``[imm]`` names several (its ``[[imm.modes]]``
tables take the same keys as ``[motion]`` except ``ndim`` and ``dt``, which
the modes share) and runs the ``[filter]`` type on each inside an
interacting multiple model filter.  Modes of different sizes share the
state of the largest one (the first of the largest): a mode without
accelerations sees the common state's position and velocity, and its
estimate enters the mixture with zero acceleration of zero variance
(:func:`pursuit.filters.imm.kinematic_map`, the textbook augmentation).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..filters.imm import InteractingMultipleModel, kinematic_map
from ..models.maneuver import ConstantTurn, Singer
from ..models.motion import ConstantAcceleration, ConstantVelocity
from ..registry import REQUIRED, Component, Param

__all__ = ["MOTION_TYPES", "MODE_PARAMS", "IMM_PARAMS", "IMM_FILTERS", "build_motion", "build_imm"]

MOTION_TYPES = ("cv", "ca", "ct", "singer")
IMM_FILTERS = ("kf", "ekf", "ukf", "ckf")
"""``[filter]`` types that can run each mode of an ``[imm]`` (they take the mode's motion model)."""

# which keys each motion type takes, beyond type (and ndim, dt, noise for all)
_KEYS = {"cv": ("q",), "ca": ("q",), "ct": ("q", "omega"), "singer": ("alpha", "sigma")}
_UNIT = {"q": "noise intensity", "omega": "turn rate", "alpha": "maneuver frequency", "sigma": "acceleration standard deviation"}


def _positive(field: str, v: float) -> float:
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{field}: must be a positive number, got {v!r}")
    return v


def _finite(field: str, v: float) -> float:
    if not np.isfinite(v):
        raise ValueError(f"{field}: must be a finite number, got {v!r}")
    return v


MOTION_EXTRA_PARAMS = (
    Param("omega", "float", None, "ct: turn rate, rad/s (positive turns counter-clockwise)", check=_finite),
    Param("alpha", "float", None, "singer: maneuver frequency 1/tau, 1/s", check=_positive),
    Param("sigma", "float", None, "singer: acceleration standard deviation, m/s^2", check=_positive),
)

MODE_PARAMS = (
    Param("type", "str", REQUIRED, "motion model of this mode", choices=MOTION_TYPES),
    Param("q", "float", None, "acceleration (cv, ct) or jerk (ca) noise intensity", check=_positive),
    Param("noise", "str", "discrete", "white-noise model (cv, ca)", choices=("discrete", "continuous")),
    *MOTION_EXTRA_PARAMS,
)


def _transition(field: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float, list)):
        raise ValueError(f"{field}: expected a staying probability or a matrix (list of rows)")
    return value


IMM_PARAMS = (
    Param("ndim", "int", 2, "spatial axes shared by the modes (1, 2 or 3; ct needs 2 or 3)"),
    Param("dt", "float", 1.0, "nominal interval, s: the first step's dt when [prior] has no time", check=_positive),
    Param("transition", "any", 0.95, "staying probability p_ii, or the full Markov matrix (rows sum to 1)", check=_transition),
    Param("initial_probs", "vector", None, "initial mode probabilities (default uniform)"),
    Param("modes", "any", REQUIRED, "[[imm.modes]] tables: type and its parameters, as in [motion]"),
)


def build_motion(vals: dict[str, Any], where: str, ndim: int, dt: float) -> tuple[Any, tuple[str, ...]]:
    """A motion model and its state labels from resolved ``[motion]`` (or mode) values.

    Raises ``ValueError`` naming ``where.<field>`` for a missing parameter,
    one the type does not take, or a combination the model cannot do.
    """
    kind = vals["type"]
    for key in ("q", "omega", "alpha", "sigma"):
        if vals.get(key) is not None and key not in _KEYS[kind]:
            owners = [k for k, keys in _KEYS.items() if key in keys]
            raise ValueError(f"{where}.{key}: a {kind!r} motion has no {_UNIT[key]} (only {', '.join(owners)})")
    for key in _KEYS[kind]:
        if vals.get(key) is None:
            raise ValueError(f"{where}.{key}: required for a {kind!r} motion ({_UNIT[key]})")
    if kind in ("ct", "singer") and vals.get("noise", "discrete") != "discrete":
        raise ValueError(f"{where}.noise: a {kind!r} motion has its own process noise; only 'discrete' applies to cv and ca")
    axes = "xyz"[:ndim]
    if kind in ("cv", "ca"):
        cls = ConstantVelocity if kind == "cv" else ConstantAcceleration
        with np.errstate(over="ignore", invalid="ignore"):  # a q that overflows Q is refused by model._check_magnitudes
            motion = cls(ndim=ndim, dt=dt, q=vals["q"], noise=vals["noise"])
    elif kind == "ct":
        if ndim not in (2, 3):
            raise ValueError(f"{where}.type: a 'ct' motion turns in the x-y plane: it needs ndim = 2 or 3, got {ndim}")
        motion = ConstantTurn(omega=vals["omega"], q=vals["q"], ndim=ndim, dt=dt)
    else:
        motion = Singer(alpha=vals["alpha"], sigma=vals["sigma"], ndim=ndim, dt=dt)
    per_axis = ("{a}", "v{a}") if kind in ("cv", "ct") else ("{a}", "v{a}", "a{a}")
    return motion, tuple(p.format(a=a) for a in axes for p in per_axis)


def _resolve(table: Any, name: str, params: tuple[Param, ...]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise ValueError(f"{name}: expected a table")
    return Component("section", name, "", params, dict).resolve(table, name)


def imm_motions(table: Any) -> tuple[dict[str, Any], list[Any], Any, tuple[str, ...]]:
    """``[imm]``: its values, the mode motions, and the common motion with its labels."""
    vals = _resolve(table, "imm", IMM_PARAMS)
    if not 1 <= vals["ndim"] <= 3:
        raise ValueError(f"imm.ndim: must be 1, 2 or 3, got {vals['ndim']}")
    modes = vals["modes"]
    if not isinstance(modes, list) or len(modes) < 2 or not all(isinstance(m, dict) for m in modes):
        raise ValueError("imm.modes: expected two or more [[imm.modes]] tables")
    built = [
        build_motion(_resolve(m, f"imm.modes[{i}]", MODE_PARAMS), f"imm.modes[{i}]", vals["ndim"], vals["dt"])
        for i, m in enumerate(modes)
    ]
    largest = max(range(len(built)), key=lambda i: (built[i][0].dim, -i))
    common, labels = built[largest]
    return vals, [m for m, _ in built], common, labels


def build_imm(vals: dict[str, Any], motions: list[Any], common: Any, build_mode: Callable[[Any, int], Any], gate: float | None, name: str) -> InteractingMultipleModel:
    """The IMM over one filter per mode; ``build_mode(motion, i)`` builds mode i's filter."""
    filters, maps = [], []
    for i, motion in enumerate(motions):
        filters.append(build_mode(motion, i))
        try:
            maps.append(None if motion is common else kinematic_map(motion, common))
        except ValueError as e:  # pragma: no cover - every MOTION_TYPES pair fits in the largest
            raise ValueError(f"imm.modes[{i}].type: {e}") from None
    try:
        return InteractingMultipleModel(filters, vals["transition"], vals["initial_probs"], maps, name=name or "IMM", gate=gate)
    except ValueError as e:
        msg = str(e)
        field = msg.split(":", 1)[0]
        raise ValueError(f"imm.{msg}" if field in ("transition", "initial_probs") else f"imm: {msg}") from None
