"""Scenario registrations."""

from __future__ import annotations

import numpy as np

from ..registry import params_from, register
from ..scenarios.linear import LinearCV
from ..scenarios.wsn import WSNRange


def _checked(field: str, build):
    try:
        return build()
    except ValueError as e:  # re-anchor the model's field name under the config's
        raise ValueError(f"{field}.{e}") from None


_PRIOR_MEAN_DOC = "initial estimate: drawn from N(x0, P0) or x0 itself"


@register(
    "scenario",
    "wsn-range",
    "2-D constant-velocity target ranged by fixed WSN anchors; state [x, vx, y, vy]",
    params=params_from(
        WSNRange,
        ["anchors", "sigma", "steps", "dt", "q", "noise", "x0", "P0", "prior_mean", "sensing_radius", "p_detect"],
        types={"anchors": "matrix", "P0": "matrix"},
        docs={
            "anchors": "anchor positions [[x, y], ...], m",
            "sigma": "range noise standard deviation, m",
            "steps": "number of measurement steps",
            "dt": "sampling interval, s",
            "q": "acceleration noise variance, (m/s^2)^2",
            "noise": "white-noise acceleration model",
            "x0": "true initial state [x, vx, y, vy]",
            "P0": "prior covariance (matrix or diagonal)",
            "prior_mean": _PRIOR_MEAN_DOC,
            "sensing_radius": "a node measures only a target within this range, m (inf: always); else its range is NaN",
            "p_detect": "probability that a node within range detects the target at a step, (0, 1]",
        },
    ),
    target=WSNRange,
)
def _wsn(where: str = "scenario", **kw) -> WSNRange:
    kw["anchors"] = np.atleast_2d(kw["anchors"])
    return _checked(where, lambda: WSNRange(**kw))


@register(
    "scenario",
    "cv-position",
    "Constant-velocity target in 1-3 D with linear position measurements (KF-exact reference)",
    params=params_from(
        LinearCV,
        ["ndim", "dt", "q", "sigma", "steps", "x0", "P0", "prior_mean"],
        types={"P0": "matrix"},
        choices={"prior_mean": ("sampled", "truth")},
        docs={
            "ndim": "spatial axes (1, 2 or 3)",
            "dt": "sampling interval, s",
            "q": "acceleration noise variance, (m/s^2)^2",
            "sigma": "position noise standard deviation, m",
            "steps": "number of measurement steps",
            "x0": "true initial state (default: at rest at the origin moving 1 m/s per axis)",
            "P0": "prior covariance (default identity)",
            "prior_mean": _PRIOR_MEAN_DOC,
        },
    ),
    target=LinearCV,
)
def _cv_position(where: str = "scenario", **kw) -> LinearCV:
    return _checked(where, lambda: LinearCV(**kw))
