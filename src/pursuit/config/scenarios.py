"""Scenario registrations."""

from __future__ import annotations

import numpy as np

from ..registry import Param, register
from ..scenarios.linear import LinearCV
from ..scenarios.wsn import WSNRange


def _checked(field: str, build):
    try:
        return build()
    except ValueError as e:  # re-anchor the model's field name under the config's
        raise ValueError(f"{field}.{e}") from None


@register(
    "scenario",
    "wsn-range",
    "2-D constant-velocity target ranged by fixed WSN anchors; state [x, vx, y, vy]",
    params=(
        Param("anchors", "matrix", [[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]], "anchor positions [[x, y], ...], m"),
        Param("sigma", "float", 1.0, "range noise standard deviation, m"),
        Param("steps", "int", 100, "number of measurement steps"),
        Param("dt", "float", 1.0, "sampling interval, s"),
        Param("q", "float", 0.01, "acceleration noise variance, (m/s^2)^2"),
        Param("noise", "str", "discrete", "white-noise acceleration model", choices=("discrete", "continuous")),
        Param("x0", "vector", [10.0, 0.5, 40.0, 0.8], "true initial state [x, vx, y, vy]"),
        Param("P0", "matrix", [4.0, 0.25, 4.0, 0.25], "prior covariance (matrix or diagonal)"),
        Param("prior_mean", "str", "sampled", "initial estimate: drawn from N(x0, P0) or x0 itself", choices=("sampled", "truth")),
    ),
)
def _wsn(where: str = "scenario", **kw) -> WSNRange:
    kw["anchors"] = np.atleast_2d(kw["anchors"])
    return _checked(where, lambda: WSNRange(**kw))


@register(
    "scenario",
    "cv-position",
    "Constant-velocity target in 1-3 D with linear position measurements (KF-exact reference)",
    params=(
        Param("ndim", "int", 2, "spatial axes (1, 2 or 3)"),
        Param("dt", "float", 1.0, "sampling interval, s"),
        Param("q", "float", 0.01, "acceleration noise variance, (m/s^2)^2"),
        Param("sigma", "float", 1.0, "position noise standard deviation, m"),
        Param("steps", "int", 100, "number of measurement steps"),
        Param("x0", "vector", None, "true initial state (default: at rest at the origin moving 1 m/s per axis)"),
        Param("P0", "matrix", None, "prior covariance (default identity)"),
        Param("prior_mean", "str", "sampled", "initial estimate: drawn from N(x0, P0) or x0 itself", choices=("sampled", "truth")),
    ),
)
def _cv_position(where: str = "scenario", **kw) -> LinearCV:
    return _checked(where, lambda: LinearCV(**kw))
