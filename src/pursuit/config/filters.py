"""Filter and fading-strategy registrations.

A filter entry in a config is built against the scenario: by default it uses
the scenario's own (matched) motion and measurement models.
"""

from __future__ import annotations

from typing import Any

from .. import registry
from ..filters.fading import MAX_CONSTANT_FADING, Constant
from ..filters.gaussian import (
    CubatureKalmanFilter,
    ExtendedKalmanFilter,
    KalmanFilter,
    UnscentedKalmanFilter,
)
from ..registry import Param, params_from, register


def build_fading(field: str, value: Any):
    """A fading strategy from a number (constant λ) or a table ``{type = ..., ...}``.

    A constant λ above :data:`~pursuit.filters.fading.MAX_CONSTANT_FADING` (2¹³) is refused,
    as in model files: it compounds at every step and breaks float64's updates.
    """
    strategy = _build_fading(field, value)
    lam = getattr(strategy, "lam", None)
    if isinstance(strategy, Constant) and lam > MAX_CONSTANT_FADING:
        where = field if isinstance(value, (int, float)) else f"{field}.lam"
        raise ValueError(
            f"{where}: {lam:g} is beyond 2^13 ≈ {MAX_CONSTANT_FADING:.3g}: a constant fading factor multiplies the "
            "covariance at every step, and beyond that the updates lose positive definiteness in float64 (measured: "
            "1e4 is exact, 1e6 is not)"
        )
    return strategy


def _build_fading(field: str, value: Any):
    if isinstance(value, bool):
        raise ValueError(f"{field}: expected a number or a table, got a boolean")
    if isinstance(value, (int, float)):
        try:
            return Constant(float(value))
        except ValueError as e:
            raise ValueError(f"{field}.{e}") from None
    if not isinstance(value, dict):
        raise ValueError(f"{field}: expected a number (constant λ) or a table with a type, got {value!r}")
    values = dict(value)
    kind = values.pop("type", None)
    if kind is None:
        raise ValueError(f"{field}.type: required (see `pursuit list` for fading strategies)")
    comp = registry.get("fading", kind, f"{field}.type")
    params = comp.resolve(values, field)
    try:
        return comp.build(**params)
    except ValueError as e:
        raise ValueError(f"{field}.{e}") from None


register(
    "fading",
    "constant",
    "Constant fading factor λ; λ = 1 is the plain filter (a bare number means the same)",
    params=params_from(Constant, ["lam"], docs={"lam": "fading factor, at least 1"}),
)(Constant)

TFMKF_LAMBDA = 1.23
"""Paper P2's constant fading factor for TFMKF (from P2's own ref. [12]; docs/spec/03-fading-memory-ekf.md §4.1)."""


@register(
    "fading",
    "tfmkf",
    f"Constant fading factor λ = {TFMKF_LAMBDA} unless given (the TFMKF of Ma & Zheng's underwater TOA paper)",
    params=(Param("lam", "float", TFMKF_LAMBDA, "fading factor, at least 1", own=True),),
    target=Constant,
)
def _tfmkf(lam: float) -> Constant:
    """TFMKF: :class:`~pursuit.filters.fading.Constant` with paper P2's λ = 1.23 as the default."""
    return Constant(lam)

NAME = Param("name", "str", "", "label in tables and figures (default: the filter's short name)")
BACKEND = Param(
    "backend",
    "str",
    None,
    "compute backend: numpy or numba (compiled, pursuit[fast]); default: the CLI's --compute-backend, else numpy",
    choices=("numpy", "numba"),
)
FADING = Param("fading", "any", 1.0, "fading factor λ >= 1, or a table {type = ..., ...}", check=build_fading)


def _gate_probability(field: str, value: float) -> float:
    if not 0.0 < value < 1.0:
        raise ValueError(f"{field}: must lie in (0, 1), e.g. 0.999, got {value!r}")
    return value


GATE = Param(
    "gate", "float", None, "chi-square gate probability: reject a measurement whose NIS exceeds this quantile (default: no gate)", check=_gate_probability
)


def make_filter(cls, scenario, where: str, **kw):
    """Build ``cls(scenario.motion, scenario.measurement, **kw)``, re-anchoring errors under ``where``.

    ``kw`` are the resolved parameters; ``backend = None`` (not set) is left
    out so the class's own default applies.
    """
    if kw.get("backend", "") is None:
        kw.pop("backend")
    try:
        return cls(scenario.motion, scenario.measurement, **kw)
    except TypeError as e:  # the filter cannot use this scenario's models
        raise ValueError(f"{where}.type: {e}") from None
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


@register("filter", "kf", "Linear Kalman filter (Joseph form)", params=(NAME, FADING, GATE, BACKEND), target=KalmanFilter)
def _kf(scenario, where="filter", **kw):
    return make_filter(KalmanFilter, scenario, where, **kw)


@register(
    "filter",
    "ekf",
    "Extended Kalman filter (Joseph form; numerical Jacobians if the model has none)",
    params=(NAME, FADING, GATE, BACKEND),
    target=ExtendedKalmanFilter,
)
def _ekf(scenario, where="filter", **kw):
    return make_filter(ExtendedKalmanFilter, scenario, where, **kw)


@register(
    "filter",
    "ukf",
    "Unscented Kalman filter (scaled sigma points)",
    params=(
        NAME,
        FADING,
        *params_from(
            UnscentedKalmanFilter,
            ["alpha", "beta", "kappa"],
            docs={"alpha": "sigma-point spread", "beta": "prior-knowledge weight (2 is optimal for Gaussians)", "kappa": "secondary scaling"},
        ),
        GATE,
        BACKEND,
    ),
    target=UnscentedKalmanFilter,
)
def _ukf(scenario, where="filter", **kw):
    return make_filter(UnscentedKalmanFilter, scenario, where, **kw)


@register(
    "filter",
    "ckf",
    "Cubature Kalman filter (third-degree spherical-radial rule)",
    params=(NAME, FADING, GATE, BACKEND),
    target=CubatureKalmanFilter,
)
def _ckf(scenario, where="filter", **kw):
    return make_filter(CubatureKalmanFilter, scenario, where, **kw)
