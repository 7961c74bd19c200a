"""Bearings-only tracking of a maneuvering target from a maneuvering observer (docs/spec/04-adaptive-cs-model.md §4.5).

An electro-optical sensor measures the azimuth (2-D) or the azimuth and
elevation (3-D) of the target with σ = 1 mrad.  A bearings-only target is
unobservable in range from an observer on a straight line, so the observer
weaves: it flies along +y at constant speed while its x follows
``A sin(2π t / P)``.  The target is paper P4's kind of target (constant
acceleration segments on a schedule, exact kinematics, no process noise;
:class:`pursuit.scenarios.maneuver.ManeuveringTarget` integrates it) placed
at (10, 10) km from the observer and flying alongside it, so its range stays
in about 13–19 km.  The spec gives no schedule: :data:`STRONG_SCHEDULE` and
:data:`WEAK_SCHEDULE` are invented [DEFAULT]: P4's pattern of segments (the
strongest on y), shifted 40 s later so that the range estimate settles
first, with accelerations up to 20 m/s² (about 2 g) and a tenth of that.
Measured while choosing them (30 runs, EKFs): with P4's own 40–60 m/s² and
no settling time every CS-EKF lost the range in most runs — a single
observer weaving at about 32 m/s² cannot resolve a target that out-maneuvers
it.

Timing as in the maneuver scenario: epochs t_1 … t_horizon, filtering from
t_3 (``steps = horizon − 2``).  Bearings cannot start a filter by
differencing, so each run's prior mean at t_2 is drawn from N(x(t_2), P0)
with P0 diagonal (``prior_std`` of position, velocity and acceleration per
axis) [DEFAULT].
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_vector, positive, positive_int
from ..gaussian import Gaussian
from ..models.measurement import wrap_angle
from ..models.motion import ConstantAcceleration
from ..models.sensors import ObserverBearings
from ..rng import RNGLike, RunStreams, as_rng
from .base import Simulation
from .maneuver import Maneuver, ManeuveringTarget, parse_schedule

__all__ = ["BearingsOnlyTarget", "WeavingObserver", "STRONG_SCHEDULE", "WEAK_SCHEDULE"]


def _scaled(scale: float, shift: float = 40.0) -> tuple[Maneuver, ...]:
    return (
        Maneuver(21 + shift, 30 + shift, axis="y", accel=4.0 * scale),
        Maneuver(41 + shift, 50 + shift, axis="y", accel=-4.0 * scale),
        Maneuver(67 + shift, 76 + shift, axis="y", accel=-3.0 * scale),
        Maneuver(31 + shift, 45 + shift, axis="x", accel=1.0 * scale),
        Maneuver(56 + shift, 70 + shift, axis="x", accel=-1.0 * scale),
        Maneuver(51 + shift, 70 + shift, axis="z", accel=-0.5 * scale),
    )


STRONG_SCHEDULE: tuple[Maneuver, ...] = _scaled(5.0)
"""[DEFAULT] hard maneuvers: y +20 (61-70 s), −20 (81-90), −15 (107-116) m/s²; x +5 (71-85), −5 (96-110); z −2.5 (91-110)."""
WEAK_SCHEDULE: tuple[Maneuver, ...] = _scaled(0.5)
"""[DEFAULT] weak maneuvers: the same segments at a tenth of the accelerations (y +2, −2, −1.5; x ±0.5; z −0.25 m/s²)."""
_SCHEDULES = {"strong": STRONG_SCHEDULE, "weak": WEAK_SCHEDULE}


@dataclass(frozen=True)
class WeavingObserver:
    """Observer position at filter step k: ``p0 + v t + A sin(2π t / P) e_x`` with ``t = (k + 2) dt``.

    A closed form, so a scenario of any horizon stores no track (filter step k is epoch k + 2).
    """

    position: np.ndarray
    velocity: np.ndarray
    amplitude: float
    period: float
    dt: float

    def __call__(self, k: int) -> np.ndarray:
        t = (int(k) + 2) * self.dt
        p = self.position + t * self.velocity
        p[0] += self.amplitude * np.sin(2.0 * np.pi * t / self.period)
        return p


@dataclass(frozen=True, eq=False)
class BearingsOnlyTarget:
    """Angles of a maneuvering target from a weaving observer; state ``[x, vx, ax, y, vy, ay(, z, vz, az)]``.

    Parameters
    ----------
    dims
        2 (azimuth) or 3 (azimuth and elevation).
    strength
        ``"strong"`` or ``"weak"``: the default schedule (ignored when
        ``maneuvers`` is given).
    maneuvers
        A schedule of :class:`pursuit.scenarios.maneuver.Maneuver` segments
        or tables; default by ``strength``.
    horizon, dt
        Epochs including the two before filtering starts; sampling period (s).
    sigma
        Angle noise standard deviation (rad); 1 mrad.
    position, velocity
        Target position and velocity at t = 0 (first ``dims`` entries used).
    observer_position, observer_velocity
        Observer position and constant base velocity at t = 0.
    weave_amplitude, weave_period
        The observer's x weave ``A sin(2π t / P)`` (m, s); amplitude 0 means
        a straight line (range unobservable).
    prior_std
        Standard deviations of the prior on (position, velocity,
        acceleration) per axis (m, m/s, m/s²).
    name
        Scenario label.
    """

    dims: int = 2
    strength: str = "strong"
    maneuvers: Any = None
    horizon: int = 140
    dt: float = 1.0
    sigma: float = 1e-3
    position: Any = (10000.0, 10000.0, 4000.0)
    velocity: Any = (0.0, 300.0, 0.0)
    observer_position: Any = (0.0, 0.0, 3000.0)
    observer_velocity: Any = (0.0, 300.0, 0.0)
    weave_amplitude: float = 2000.0
    weave_period: float = 50.0
    prior_std: Any = (500.0, 30.0, 5.0)
    name: str = "bearings"
    motion: ConstantAcceleration = field(init=False, repr=False)
    measurement: ObserverBearings = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.dims not in (2, 3) or isinstance(self.dims, bool):
            raise ValueError(f"dims: must be 2 (azimuth) or 3 (azimuth and elevation), got {self.dims!r}")
        d = int(self.dims)
        if self.strength not in _SCHEDULES:
            raise ValueError(f"strength: must be 'strong' or 'weak', got {self.strength!r}")
        schedule = _SCHEDULES[self.strength] if self.maneuvers is None else parse_schedule(self.maneuvers)
        if d == 2:  # a 2-D target ignores the z segments of the default schedules
            schedule = tuple(m for m in schedule if "z" not in m.axes) if self.maneuvers is None else schedule
        object.__setattr__(self, "maneuvers", schedule)
        for key in ("position", "velocity", "observer_position", "observer_velocity"):
            v = as_vector(key, getattr(self, key))
            if v.size < d:
                raise ValueError(f"{key}: expected at least {d} values, got {v.size}")
            object.__setattr__(self, key, v[:d])
        object.__setattr__(self, "sigma", positive("sigma", self.sigma))
        object.__setattr__(self, "dt", positive("dt", self.dt))
        object.__setattr__(self, "weave_period", positive("weave_period", self.weave_period))
        amp = float(self.weave_amplitude)
        if not np.isfinite(amp) or amp < 0:
            raise ValueError(f"weave_amplitude: must be a finite number >= 0, got {self.weave_amplitude!r}")
        object.__setattr__(self, "weave_amplitude", amp)
        std = as_vector("prior_std", self.prior_std, 3)
        for s in std:
            positive("prior_std", s)
        object.__setattr__(self, "prior_std", std)
        horizon = positive_int("horizon", self.horizon)
        # The target's kinematics and schedule checks (overlaps, axes) come from the maneuver scenario.
        target = ManeuveringTarget(horizon=horizon, dt=self.dt, position=self.position, velocity=self.velocity, maneuvers=schedule)
        object.__setattr__(self, "_target", target)
        object.__setattr__(self, "motion", ConstantAcceleration(ndim=d, dt=self.dt, q=1.0, layout="axis"))
        observer = WeavingObserver(self.observer_position, self.observer_velocity, amp, self.weave_period, self.dt)
        object.__setattr__(self, "measurement", ObserverBearings(observer, self.sigma))

    # -- layout (as the maneuver scenario) ------------------------------------------
    @property
    def axes(self) -> str:
        """Axis names, ``"xy"`` or ``"xyz"``."""
        return self._target.axes

    @property
    def steps(self) -> int:
        """Filter steps K = horizon − 2."""
        return self._target.steps

    @property
    def times(self) -> np.ndarray:
        """Times of the filter steps, t_3 … t_horizon (s)."""
        return self._target.times

    @property
    def state_labels(self) -> tuple[str, ...]:
        return self._target.state_labels

    @property
    def state_units(self) -> tuple[str, ...]:
        return self._target.state_units

    @property
    def position_indices(self) -> tuple[int, ...]:
        return self._target.position_indices

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        return self._target.velocity_indices

    @property
    def acceleration_indices(self) -> tuple[int, ...]:
        return self._target.acceleration_indices

    def maneuvering(self) -> np.ndarray:
        """``(K, A)`` bool: axis under a nonzero acceleration at each filter step."""
        return self._target.maneuvering()

    def true_states(self) -> np.ndarray:
        """True states at t_1 … t_horizon, ``(horizon, 3A)``."""
        return self._target.true_states()

    def observer_track(self) -> np.ndarray:
        """Observer positions at the filter steps' times, ``(K, dims)`` (what the measurement model uses)."""
        t = self.times
        track = self.observer_position + t[:, None] * self.observer_velocity
        track[:, 0] += self.weave_amplitude * np.sin(2.0 * np.pi * t / self.weave_period)
        return track

    def ranges(self) -> np.ndarray:
        """True target ranges at the filter steps (m), ``(K,)``."""
        truth = self.true_states()[2:]
        return np.linalg.norm(truth[:, list(self.position_indices)] - self.observer_track(), axis=-1)

    def prior_covariance(self) -> np.ndarray:
        """Diagonal prior covariance ``(3A, 3A)``."""
        return np.diag(np.tile(self.prior_std**2, len(self.axes)))

    # -- simulation ---------------------------------------------------------------
    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Run i draws its angle noise ``(K, m)`` then its prior offset ``(n,)`` from stream i."""
        rng = as_rng(rng)
        if runs is None:
            if not isinstance(rng, RunStreams):
                raise ValueError("runs: required when rng is a single Generator")
            runs = len(rng)
        runs = positive_int("runs", runs)
        K, m = self.steps, self.measurement.dim
        truth_all = self.true_states()
        n = truth_all.shape[1]
        noise = rng.standard_normal((runs, K, m))
        offset = rng.standard_normal((runs, n))
        truth = np.broadcast_to(truth_all[2:, None, :], (K, runs, n)).copy()
        clean = np.stack([self.measurement.h(truth_all[2 + k], k + 1) for k in range(K)])  # (K, m): K angles, not runs
        zs = clean[:, None, :] + self.sigma * np.swapaxes(noise, 0, 1)
        zs[..., 0] = wrap_angle(zs[..., 0])
        P0 = self.prior_covariance()
        mean = truth_all[1] + offset * np.sqrt(np.diag(P0))
        return Simulation(
            truth=truth,
            measurements=zs,
            prior=Gaussian(mean, P0),
            times=self.times,
            extra={"maneuvering": self.maneuvering(), "observer": self.observer_track()},
        )
