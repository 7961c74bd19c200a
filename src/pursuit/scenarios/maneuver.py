"""A maneuvering target in up to three axes with a maneuver schedule (paper P4's experiment).

The truth is deterministic and the same in every run: piecewise constant
acceleration per axis and constant-rate turns in a plane, integrated exactly
over each sampling period, with no process noise.  Each run adds its own
position measurement noise.  Paper P4's Table 1 (the schedule) is missing;
:data:`DEFAULT_SCHEDULE` is the spec's invented one (docs/spec/04-adaptive-cs-model.md §3).

Timing: step k (time t_k = kT) covers the period (t_{k−1}, t_k].  A segment
``start``–``stop`` (seconds, inclusive) acts on the steps whose t_k lies in
[start, stop]; the true acceleration at t_k is the one that acted over that
period.  Filtering starts at k = 3: the measurements at k = 1, 2 give each
run's two-point initial estimate (the prior at t_2).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .._validation import as_vector, positive, positive_int
from ..gaussian import Gaussian
from ..models.measurement import LinearGaussian
from ..models.motion import ConstantAcceleration
from ..rng import RNGLike, RunStreams, as_rng
from .base import Simulation

__all__ = ["Maneuver", "ManeuveringTarget", "DEFAULT_SCHEDULE", "parse_schedule"]

AXES = "xyz"
_PLANES = ("xy", "xz", "yz")


@dataclass(frozen=True)
class Maneuver:
    """One segment of the schedule.

    Attributes
    ----------
    start, stop
        First and last second (inclusive) of the segment.
    axis
        ``"x"``, ``"y"`` or ``"z"`` for a constant-acceleration segment.
    accel
        Acceleration on that axis (m/s²).
    plane
        ``"xy"``, ``"xz"`` or ``"yz"`` for a constant-rate turn (then
        ``axis`` is None).
    rate
        Turn rate in degrees per second (positive: counter-clockwise from
        the first axis of the plane towards the second).
    """

    start: float
    stop: float
    axis: str | None = None
    accel: float = 0.0
    plane: str | None = None
    rate: float = 0.0

    def __post_init__(self) -> None:
        if (self.axis is None) == (self.plane is None):
            raise ValueError("a maneuver needs exactly one of axis (acceleration) or plane (turn)")
        if self.axis is not None and self.axis not in AXES:
            raise ValueError(f"axis: must be 'x', 'y' or 'z', got {self.axis!r}")
        if self.plane is not None and self.plane not in _PLANES:
            raise ValueError(f"plane: must be one of {', '.join(_PLANES)}, got {self.plane!r}")
        for name in ("start", "stop", "accel", "rate"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise ValueError(f"{name}: expected a finite number, got {v!r}")
        if self.start < 0:  # the truth starts at t = 0: a segment before it is a typo or a shifted schedule
            raise ValueError(f"start: must be at least 0 s (the truth starts at t = 0), got {self.start}")
        if self.stop < self.start:
            raise ValueError(f"stop: must not be before start ({self.start}), got {self.stop}")

    @property
    def axes(self) -> tuple[str, ...]:
        """The axes the segment acts on."""
        return (self.axis,) if self.axis is not None else tuple(self.plane)

    @property
    def kind(self) -> str:
        """``"accel"`` or ``"turn"``."""
        return "accel" if self.axis is not None else "turn"

    def label(self) -> str:
        """Short description, e.g. ``y +40 m/s² 21-35 s`` or ``xy turn 3°/s``."""
        span = f"{self.start:g}-{self.stop:g} s"
        if self.kind == "accel":
            return f"{self.axis} {self.accel:+g} m/s² {span}"
        return f"{self.plane} turn {self.rate:+g}°/s {span}"


DEFAULT_SCHEDULE: tuple[Maneuver, ...] = (
    Maneuver(21, 35, axis="y", accel=40.0),
    Maneuver(51, 66, axis="y", accel=-30.0),
    Maneuver(67, 80, axis="y", accel=60.0),
    Maneuver(31, 45, axis="x", accel=15.0),
    Maneuver(51, 70, axis="z", accel=-5.0),
)
"""The [DEFAULT] schedule of docs/spec/04-adaptive-cs-model.md §3 (P4's Table 1 is missing): y 0, +40 (21-35 s), 0, −30 (51-66),
+60 (67-80), 0; x +15 (31-45); z −5 (51-70); zero elsewhere."""

_SEGMENT_KEYS = {"start", "stop", "axis", "accel", "plane", "rate"}


def parse_schedule(entries: Any, field_name: str = "maneuvers") -> tuple[Maneuver, ...]:
    """Segments from a list of tables (TOML ``[[scenario.maneuvers]]``); errors name the entry and key."""
    if isinstance(entries, Maneuver):
        entries = [entries]
    if not isinstance(entries, (list, tuple)):
        raise ValueError(f"{field_name}: expected a list of maneuver tables")
    out = []
    for i, e in enumerate(entries):
        where = f"{field_name}[{i}]"
        if isinstance(e, Maneuver):
            out.append(e)
            continue
        if not isinstance(e, dict):
            raise ValueError(f"{where}: expected a table with start, stop and axis/accel or plane/rate")
        unknown = set(e) - _SEGMENT_KEYS
        if unknown:
            raise ValueError(f"{where}.{sorted(unknown)[0]}: unknown key (known: {', '.join(sorted(_SEGMENT_KEYS))})")
        for key in ("start", "stop"):
            if key not in e:
                raise ValueError(f"{where}.{key}: required")
        try:
            out.append(Maneuver(**e))
        except ValueError as err:
            msg = str(err)
            key = msg.split(":", 1)[0] if ":" in msg and msg.split(":", 1)[0] in _SEGMENT_KEYS else None
            raise ValueError(f"{where}.{key}: {msg.split(':', 1)[1].strip()}" if key else f"{where}: {msg}") from None
        except TypeError as err:
            raise ValueError(f"{where}: {err}") from None
    return tuple(out)


def _check_overlaps(schedule: Sequence[Maneuver], axes: str) -> None:
    for i, a in enumerate(schedule):
        for ax in a.axes:
            if ax not in axes:
                raise ValueError(f"maneuvers[{i}]: axis {ax!r} does not exist in a {len(axes)}-axis scenario")
        for j in range(i):
            b = schedule[j]
            if set(a.axes) & set(b.axes) and a.start <= b.stop and b.start <= a.stop:
                raise ValueError(f"maneuvers[{i}]: overlaps maneuvers[{j}] on axis {sorted(set(a.axes) & set(b.axes))[0]}")


def _turn(p: np.ndarray, v: np.ndarray, omega: float, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact constant-rate turn of (p, v) in a plane; returns p, v and the acceleration at the end."""
    u = omega * T
    S = np.sinc(u / np.pi)  # sin(u)/u
    C = T * (u / 2.0) * np.sinc(u / (2.0 * np.pi)) ** 2  # (1 − cos u)/ω, stable at ω = 0
    c, s = np.cos(u), np.sin(u)
    p_new = p + np.array([T * S * v[0] - C * v[1], C * v[0] + T * S * v[1]])
    v_new = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
    a_new = omega * np.array([-v_new[1], v_new[0]])
    return p_new, v_new, a_new


@dataclass(frozen=True, eq=False)
class ManeuveringTarget:
    """A target maneuvering on a schedule, measured in position on every axis (paper P4).

    State ``[x, vx, ax, y, vy, ay, z, vz, az]`` (fewer axes when
    ``position`` is shorter).  Filtering starts at the third measurement:
    a run has ``steps = horizon − 2`` filter steps.

    Parameters
    ----------
    horizon
        Number of measurement epochs t_1 … t_horizon, including the two
        used for initialisation (paper: N = 100 steps, read as 100 epochs,
        so 98 filter steps).
    dt
        Sampling period T (s).
    position, velocity
        Initial true position and velocity per axis at t = 0 (paper: 200 km
        on each axis; 0, 400 and 10 m/s).  The acceleration is zero outside
        the schedule's segments.
    R
        Measurement noise variance per axis (m²); paper: 20.
    maneuvers
        The schedule: :class:`Maneuver` objects or tables (see
        :func:`parse_schedule`); default :data:`DEFAULT_SCHEDULE`.
    init
        ``"two-point"``: x̂ = z₂, v̂ = (z₂ − z₁)/T, â = 0 (spec default);
        ``"sampled"``: the prior mean is drawn from N(x(t₂), P0).
    init_accel_std
        Prior standard deviation of the acceleration (m/s²); spec: a_max/3
        with a_max = 100.
    name
        Scenario label.

    Notes
    -----
    The prior covariance per axis is the two-point one,
    ``[[R, R/T, 0], [R/T, 2R/T², 0], [0, 0, init_accel_std²]]``.
    ``motion`` is a nominal constant-acceleration model (jerk-increment
    variance 1 (m/s²)²) for filters that take the scenario's model; no
    model matches the schedule.
    """

    horizon: int = 100
    dt: float = 1.0
    position: Any = (200e3, 200e3, 200e3)
    velocity: Any = (0.0, 400.0, 10.0)
    R: float = 20.0
    maneuvers: Any = DEFAULT_SCHEDULE
    init: str = "two-point"
    init_accel_std: float = 100.0 / 3.0
    name: str = "maneuver-3d"
    motion: ConstantAcceleration = field(init=False, repr=False)
    measurement: LinearGaussian = field(init=False, repr=False)

    def __post_init__(self) -> None:
        horizon = positive_int("horizon", self.horizon)
        if horizon < 3:
            raise ValueError(f"horizon: needs at least 3 (two for initialisation), got {horizon}")
        object.__setattr__(self, "dt", positive("dt", self.dt))
        pos = as_vector("position", self.position)
        if not 1 <= pos.size <= 3:
            raise ValueError(f"position: expected 1 to 3 axes, got {pos.size}")
        A = pos.size
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "velocity", as_vector("velocity", self.velocity, A))
        object.__setattr__(self, "R", positive("R", self.R))
        schedule = parse_schedule(self.maneuvers)
        _check_overlaps(schedule, AXES[:A])
        object.__setattr__(self, "maneuvers", schedule)
        if self.init not in ("two-point", "sampled"):
            raise ValueError(f"init: must be 'two-point' or 'sampled', got {self.init!r}")
        object.__setattr__(self, "init_accel_std", positive("init_accel_std", self.init_accel_std))
        motion = ConstantAcceleration(ndim=A, dt=self.dt, q=1.0, layout="axis")
        object.__setattr__(self, "motion", motion)
        object.__setattr__(
            self, "measurement", LinearGaussian.position(3 * A, motion.position_indices, np.sqrt(self.R))
        )

    # -- layout ------------------------------------------------------------------
    @property
    def axes(self) -> str:
        """Axis names, e.g. ``"xyz"``."""
        return AXES[: self.position.size]

    @property
    def steps(self) -> int:
        """Number of filter steps K = horizon − 2."""
        return self.horizon - 2

    @property
    def state_labels(self) -> tuple[str, ...]:
        """``("x", "vx", "ax", "y", ...)``."""
        return tuple(lbl for a in self.axes for lbl in (a, f"v{a}", f"a{a}"))

    @property
    def state_units(self) -> tuple[str, ...]:
        """``("m", "m/s", "m/s²", ...)`` per axis."""
        return ("m", "m/s", "m/s²") * len(self.axes)

    @property
    def position_indices(self) -> tuple[int, ...]:
        """Positions in the state."""
        return tuple(3 * i for i in range(len(self.axes)))

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """Velocities in the state."""
        return tuple(3 * i + 1 for i in range(len(self.axes)))

    @property
    def acceleration_indices(self) -> tuple[int, ...]:
        """Accelerations in the state."""
        return tuple(3 * i + 2 for i in range(len(self.axes)))

    @property
    def times(self) -> np.ndarray:
        """Times of the filter steps, t_3 … t_horizon (s)."""
        return self.dt * np.arange(3, self.horizon + 1)

    # -- truth -------------------------------------------------------------------
    def _integrate(self) -> np.ndarray:
        """True states at t_1 … t_horizon, ``(horizon, 3A)``."""
        A, T = len(self.axes), self.dt
        p, v = self.position.copy(), self.velocity.copy()
        a_now = np.zeros(A)
        out = np.empty((self.horizon, 3 * A))
        for i in range(self.horizon):
            t = (i + 1) * T
            acc = np.zeros(A)  # no segment: no acceleration (constant velocity)
            turning: list[int] = []
            omega = 0.0
            for m in self.maneuvers:
                if m.start <= t <= m.stop:
                    if m.kind == "accel":
                        acc[self.axes.index(m.axis)] = m.accel
                    else:
                        turning = [self.axes.index(ax) for ax in m.plane]
                        omega = np.deg2rad(m.rate)
            for j in range(A):
                if j not in turning:
                    p[j] += v[j] * T + acc[j] * T * T / 2.0
                    v[j] += acc[j] * T
                    a_now[j] = acc[j]
            if turning:
                p[turning], v[turning], a_now[turning] = _turn(p[turning], v[turning], omega, T)
            out[i, 0::3], out[i, 1::3], out[i, 2::3] = p, v, a_now
        out.setflags(write=False)
        return out

    @property
    def _truth(self) -> np.ndarray:
        # integrated on first use, not when built: a horizon of 10**7 took minutes in this loop at load
        # time, before the engine could refuse it for its memory
        truth = self.__dict__.get("_truth_cache")
        if truth is None:
            truth = self._integrate()
            object.__setattr__(self, "_truth_cache", truth)
        return truth

    def true_states(self) -> np.ndarray:
        """True states at t_1 … t_horizon, ``(horizon, 3A)`` (read-only)."""
        return self._truth

    def maneuvering(self) -> np.ndarray:
        """``(K, A)`` bool: axis under a nonzero acceleration or a turn at each filter step."""
        t = self.times
        out = np.zeros((t.size, len(self.axes)), dtype=bool)
        for m in self.maneuvers:
            if m.kind == "accel" and m.accel == 0.0:
                continue
            if m.kind == "turn" and m.rate == 0.0:
                continue
            on = (t >= m.start) & (t <= m.stop)
            for ax in m.axes:
                out[:, self.axes.index(ax)] |= on
        return out

    # -- simulation --------------------------------------------------------------
    def prior_covariance(self) -> np.ndarray:
        """Two-point prior covariance ``(3A, 3A)``."""
        R, T = self.R, self.dt
        block = np.array([[R, R / T, 0.0], [R / T, 2.0 * R / T**2, 0.0], [0.0, 0.0, self.init_accel_std**2]])
        return np.kron(np.eye(len(self.axes)), block)

    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Measurements for ``runs`` runs: run i draws its noise (``(horizon, A)`` normals) from stream i."""
        rng = as_rng(rng)
        if runs is None:
            if not isinstance(rng, RunStreams):
                raise ValueError("runs: required when rng is a single Generator")
            runs = len(rng)
        runs = positive_int("runs", runs)
        A, T = len(self.axes), self.dt
        n = 3 * A
        noise = rng.standard_normal((runs, self.horizon, A))
        truth_all = self._truth
        pos = truth_all[:, 0::3]  # (steps, A)
        zs_all = pos[:, None, :] + np.sqrt(self.R) * np.swapaxes(noise, 0, 1)  # (horizon, M, A)
        P0 = self.prior_covariance()
        if self.init == "two-point":
            z1, z2 = zs_all[0], zs_all[1]
            mean = np.zeros((runs, n))
            mean[:, 0::3] = z2
            mean[:, 1::3] = (z2 - z1) / T
        else:
            offset = rng.standard_normal((runs, n))
            mean = truth_all[1] + np.einsum("ij,mj->mi", np.linalg.cholesky(P0), offset)
        truth = np.broadcast_to(truth_all[2:, None, :], (self.steps, runs, n)).copy()
        return Simulation(
            truth=truth,
            measurements=zs_all[2:].copy(),
            prior=Gaussian(mean, P0),
            times=self.times,
            extra={"maneuvering": self.maneuvering()},
        )
