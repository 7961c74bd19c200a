"""``[prior] from = "measurements"``: the prior built from the first steps that fix a position.

With no ``[prior]`` table, or one that says ``from = "measurements"``, the
track starts from the data themselves (:mod:`pursuit.initiation`):

1. each step until then is turned into a position with its covariance, from
   whatever it measured (first rule that applies):

   * ``position`` fixes: used directly (several fixes at one time are
     combined, each weighted by its inverse covariance);
   * ranges (``range``, or ``toa`` times ``c``) to at least ``ndim + 1``
     anchors: least-squares multilateration
     (:func:`pursuit.initiation.multilaterate`);
   * a ``range`` and a ``bearing`` sensor at the same position (2-D): the
     standard polar-to-Cartesian conversion
     (:func:`pursuit.initiation.polar_to_cartesian`);

   a step that fixes no position is not used (a warning names its lines);
2. the first position gives an estimate at its time by
   :func:`~pursuit.initiation.one_point` (velocity unknown: mean 0, standard
   deviation ``velocity_sigma``);
3. the second position gives the prior at its time by two-point
   differencing (:func:`~pursuit.initiation.two_point`), written as the
   second estimate; the filter runs from there on.

Both initiation estimates carry the flag ``init``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Generator, Iterable

import numpy as np

from .._validation import MAX_MEASUREMENT
from ..filters.gaussian import check_prior_against_noise
from ..gaussian import Gaussian
from ..initiation import ACCELERATION_SIGMA, VELOCITY_SIGMA, multilaterate, one_point, polar_to_cartesian, two_point
from ..registry import Param
from .steps import INPUT_WAITS, Dropped, Step

__all__ = ["Initiation", "INITIATION_PARAMS", "NoFix", "position_from_step", "initiate"]


def _positive(field: str, v: float) -> float:
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{field}: must be a positive number, got {v!r}")
    return v


INITIATION_PARAMS = (
    Param("from", "str", "measurements", "where the prior comes from", choices=("measurements",)),
    Param("velocity_sigma", "float", VELOCITY_SIGMA, "m/s: standard deviation of the velocity before two positions are known", check=_positive),
    Param("acceleration_sigma", "float", ACCELERATION_SIGMA, "m/s^2: standard deviation of the (unmeasured) acceleration", check=_positive),
)


@dataclass(frozen=True)
class Initiation:
    """How to build the prior from the measurements.

    Attributes
    ----------
    velocity_sigma
        Standard deviation (m/s) of the velocity at the first position.
    acceleration_sigma
        Standard deviation (m/s²) of an acceleration in the state.
    """

    velocity_sigma: float = VELOCITY_SIGMA
    acceleration_sigma: float = ACCELERATION_SIGMA


class NoFix(Exception):
    """A step whose measurements do not fix a position; the message says what is missing."""


def position_from_step(step: Step, model: Any) -> tuple[np.ndarray, np.ndarray]:
    """The position ``(d,)`` and its covariance ``(d, d)`` that one step's measurements fix.

    Raises
    ------
    NoFix
        When the step has no position fix, too few ranges and no
        range-bearing pair, or its measurements give no finite position
        with a positive definite covariance (a range of 0 at the bearing's
        site, ranges no position agrees with).
    """
    try:
        with np.errstate(all="ignore"):  # a failed solution is detected below, not warned about
            p, C = _position(step, model)
    except np.linalg.LinAlgError:
        raise NoFix("its measurements give no position with a positive definite covariance") from None
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(C))):
        raise NoFix("its measurements give no finite position")
    if np.any(np.abs(p) > MAX_MEASUREMENT):  # the filters refuse such values too: they are squared
        raise NoFix(f"its position {p.tolist()} is beyond ±2^500, too large for the filters to square")
    try:
        Gaussian(p, C)  # the same check the prior will get
    except ValueError:
        raise NoFix("its measurements give no position with a positive definite covariance") from None
    return p, C


def _position(step: Step, model: Any) -> tuple[np.ndarray, np.ndarray]:
    d = len(model.position_indices)
    R = np.asarray(model.measurement.cov(None), dtype=float)
    fixes, ranges, bearings = [], [], []
    for s in model.sensors.values():
        z = step.z[s.block]
        if not np.all(np.isfinite(z)):
            continue
        Rs = R[s.block, s.block]
        if s.type == "position":
            fixes.append((z, Rs))
        elif s.type in ("range", "toa"):
            scale = 1.0 if s.type == "range" else float(s.c)
            ranges.append((tuple(s.position), float(z[0]) * scale, float(np.sqrt(Rs[0, 0])) * scale))
        elif s.type == "bearing":
            bearings.append((tuple(s.position), float(z[0]), float(np.sqrt(Rs[0, 0]))))
    if fixes:
        info = sum(np.linalg.inv(Rs) for _, Rs in fixes)
        C = np.linalg.inv(info)
        return C @ sum(np.linalg.solve(Rs, z) for z, Rs in fixes), 0.5 * (C + C.T)
    if len({a for a, _, _ in ranges}) >= d + 1:
        anchors = np.array([a for a, _, _ in ranges])
        try:
            return multilaterate(anchors, np.array([r for _, r, _ in ranges]), np.array([sg for _, _, sg in ranges]))
        except ValueError as e:
            raise NoFix(str(e)) from None
    for origin, b, sb in bearings:
        for a, r, sr in ranges:
            if a == origin:
                return polar_to_cartesian(r, b, sr, sb, origin)
    raise NoFix(
        f"it has no position fix, ranges to {len(ranges)} anchor(s) (a position in {d}-D needs {d + 1}) "
        "and no range and bearing from one site"
    )


def initiate(steps: Iterable[Any], model: Any, estimate: Any) -> Generator[Any, None, Any]:
    """Consume steps until two positions give the prior; yield the initiation estimates.

    Parameters
    ----------
    steps
        Steps and notices from :func:`pursuit.io.assemble_steps` (notices
        are passed on).
    model
        The track model, with ``initiation`` set and no prior.
    estimate
        ``estimate(step, gaussian, flags)`` makes the output record of a
        step from a Gaussian (the tracker's :class:`~pursuit.io.Estimate`).

    Returns
    -------
    TrackModel or None
        (the generator's return value) the model with its prior at the
        second position's time, or None if the input ended first.
    """
    init = model.initiation
    first = None
    for event in steps:
        if event is INPUT_WAITS:
            continue  # nothing is held back here: every estimate of initiation is yielded at once
        if not isinstance(event, Step):
            yield event  # bad records and dropped-record notices pass through
            continue
        try:
            p, C = position_from_step(event, model)
        except NoFix as e:
            for line in event.lines:
                yield Dropped(line, f"not used to start the track: this step (time {event.time!r}) fixes no position: {e}")
            continue
        if first is None:
            first = (event.time, p, C)
            g = one_point(p, C, model.motion, init.velocity_sigma, init.acceleration_sigma)
            yield estimate(event, g, ("init",))
            continue
        t1, p1, C1 = first
        try:
            with np.errstate(all="ignore"):
                prior = two_point(p1, C1, p, C, event.time - t1, model.motion, init.acceleration_sigma)
        except ValueError as e:  # dt so small that (p2 - p1)/dt or C/dt² overflows
            for line in event.lines:
                yield Dropped(line, f"not used to start the track: two-point differencing from time {t1!r} fails ({e})")
            continue
        try:  # the check a [prior] gets when the model file loads (pursuit.io.model._check_magnitudes)
            check_prior_against_noise(model.measurement, prior.mean, prior.cov)
        except ValueError as e:
            for line in event.lines:
                yield Dropped(line, f"not used to start the track: the two-point prior from time {t1!r} is unusable: {e}")
            continue
        yield estimate(event, prior, ("init",))
        return replace(model, prior=prior, prior_time=event.time)
    return None
