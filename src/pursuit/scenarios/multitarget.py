"""Multi-target scenarios: targets that are born and die, missed detections, Poisson clutter.

The measurement model of docs/spec/05-multi-target-pmht.md §1: each target
moves by its own motion model between its birth and death scans; at every
scan a present target is detected with probability P_D and then gives one
measurement ``h(x) + v`` of the scenario's sensor; a Poisson number of false
alarms (mean ``clutter_rate`` per scan) lies uniformly in ``clutter_region``,
a box **in measurement space** (x, y for a position sensor; range and
bearing for a radar, so a radar's clutter is uniform in range and bearing,
as a radar's false alarms are over its resolution cells).  The detections of
a scan are shuffled per run and packed first, padding last
(:class:`pursuit.multitarget.Scans`).

Scans are numbered k = 1..K at times ``k·dt``.  A target exists at scans
``birth <= k < death``.

Random numbers (common random numbers): with :class:`pursuit.RunStreams`,
run i draws only from stream i, every call drawing the same number of values
for run i whatever the other runs are, so run i's truth and detections are
the same alone or in any batch.  Draw order per run: for each target in
order, its spread around ``x0``, its process noise forwards from the anchor
scan, then backwards; then per scan: one uniform per target slot (detected
or not), the measurement noise of every slot, one uniform shuffle key per
slot, the clutter count (Poisson) and, for each false alarm, its m
components and its shuffle key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .._validation import as_covariance, as_vector, in_range, nonnegative, positive, positive_int
from ..models.maneuver import ConstantTurn
from ..models.measurement import LinearGaussian, RangeBearing
from ..models.motion import ConstantVelocity
from ..multitarget.detections import CLUTTER, PADDING, MultiTargetTruth, Scans
from ..rng import RNGLike, RunStreams
from .base import resolve_runs

__all__ = ["Leg", "Target", "MultiTargetScenario", "crossing", "williams15", "maneuvering_radar", "WILLIAMS15_GOSPA"]


def _step(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected a scan number (an integer), got {value!r}")
    return int(value)


@dataclass(frozen=True, eq=False)
class Leg:
    """A change of a target's motion from scan ``start`` on.

    Attributes
    ----------
    start
        The first scan reached with this leg's motion (the transition from
        scan ``start − 1`` to ``start`` uses it).
    motion
        The motion model from then on (None: the target's own).
    accel
        A known acceleration input per position axis (m/s²), added each
        step as ``G a`` with ``G = [dt²/2, dt]`` on each axis's position and
        velocity (the maneuver input of docs/spec/05-multi-target-pmht.md §3);
        None: no input.  Needs a motion model with ``position_indices``,
        ``velocity_indices`` and ``dt``.
    """

    start: int
    motion: Any = None
    accel: Sequence[float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _step("start", self.start))
        if self.accel is not None:
            object.__setattr__(self, "accel", as_vector("accel", self.accel))


@dataclass(frozen=True, eq=False)
class Target:
    """One target of a :class:`MultiTargetScenario`.

    Attributes
    ----------
    x0
        ``(n,)`` state at scan ``anchor`` (default: at birth).
    birth
        First scan at which the target exists (1-based).
    death
        First scan at which it no longer exists; None: it lives to the end.
    motion
        Its motion model (None: the scenario's).
    legs
        Later changes of motion or acceleration input, by increasing
        ``start`` after the anchor.
    spread
        Covariance of the state at the anchor: each run draws it from
        N(x0, spread); None: exactly x0 in every run.
    anchor
        The scan at which the state is ``x0`` (default: ``birth``; at most
        ``death``, where the target is no longer shown); scans before it are
        simulated backwards, ``x_{k−1} = F⁻¹(x_k + w)``, which needs a
        linear motion (``transition_matrix``); legs start after it.
    """

    x0: Sequence[float]
    birth: int = 1
    death: int | None = None
    motion: Any = None
    legs: tuple[Leg, ...] = ()
    spread: Any = None
    anchor: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "x0", as_vector("x0", self.x0))
        birth = _step("birth", self.birth)
        if birth < 1:
            raise ValueError(f"birth: scans are numbered from 1, got {birth}")
        object.__setattr__(self, "birth", birth)
        if self.death is not None:
            death = _step("death", self.death)
            if death <= birth:
                raise ValueError(f"death: must come after birth ({birth}), got {death}")
            object.__setattr__(self, "death", death)
        anchor = birth if self.anchor is None else _step("anchor", self.anchor)
        if anchor < birth or (self.death is not None and anchor > self.death):
            last = "the end" if self.death is None else f"its death scan {self.death}"
            raise ValueError(f"anchor: must lie between birth ({birth}) and {last}, got {anchor}")
        object.__setattr__(self, "anchor", anchor)
        if self.spread is not None:
            object.__setattr__(self, "spread", as_covariance("spread", self.spread, self.x0.shape[0], allow_singular=True))
        legs = tuple(self.legs)
        for i, leg in enumerate(legs):
            if not isinstance(leg, Leg):
                raise ValueError(f"legs[{i}]: expected a Leg, got {type(leg).__name__}")
            if leg.start <= anchor:
                raise ValueError(f"legs[{i}].start: must come after the anchor scan {anchor}, got {leg.start}")
            if i and leg.start <= legs[i - 1].start:
                raise ValueError(f"legs[{i}].start: legs must start at increasing scans, got {leg.start} after {legs[i - 1].start}")
        object.__setattr__(self, "legs", legs)

    def lives(self, steps: int) -> tuple[int, int]:
        """``(first, end)``: the scans ``first <= k < end`` it exists at, within 1..steps."""
        end = steps + 1 if self.death is None else min(self.death, steps + 1)
        return self.birth, end


@dataclass(frozen=True, eq=False)
class MultiTargetScenario:
    """Targets with birth and death, each with its own motion, seen by one sensor with P_D and clutter.

    Parameters
    ----------
    targets
        The :class:`Target` s; slot j of the truth is ``targets[j]``, with
        label j.
    motion
        The default motion model (of targets without their own), and the
        one a matched tracker should use.
    measurement
        Any measurement model with ``dim``, ``h`` and ``sample`` (a
        :class:`pursuit.models.LinearGaussian` position sensor, a
        :class:`pursuit.models.RangeBearing` radar, ...).
    clutter_region
        ``(m, 2)`` low and high bound of each measurement component: the box
        in measurement space in which false alarms are uniform.
    clutter_rate
        Mean number of false alarms per scan λ (Poisson), ≥ 0.
    p_detect
        Detection probability P_D of a present target, in [0, 1].
    steps
        Number of scans K.
    dt
        Scan interval, s (scan k is at time k·dt).
    name
        The scenario's name.
    max_speed
        The largest target speed a tracker should expect (position units per
        second), for two-point track initiation; None: not stated.
    """

    targets: Sequence[Target]
    motion: Any
    measurement: Any
    clutter_region: Any
    clutter_rate: float = 0.0
    p_detect: float = 1.0
    steps: int = 20
    dt: float = 1.0
    name: str = "multi-target"
    max_speed: float | None = None

    def __post_init__(self) -> None:
        if self.max_speed is not None:
            object.__setattr__(self, "max_speed", positive("max_speed", self.max_speed))
        object.__setattr__(self, "steps", positive_int("steps", self.steps))
        object.__setattr__(self, "dt", positive("dt", self.dt))
        object.__setattr__(self, "p_detect", in_range("p_detect", self.p_detect, 0.0, 1.0))
        object.__setattr__(self, "clutter_rate", nonnegative("clutter_rate", self.clutter_rate))
        targets = tuple(self.targets)
        if not targets:
            raise ValueError("targets: expected at least one Target")
        m = self.measurement.dim
        box = _region(self.clutter_region, m)
        object.__setattr__(self, "clutter_region", box)
        n = _state_dim(self.motion, "motion")
        for j, t in enumerate(targets):
            if not isinstance(t, Target):
                raise ValueError(f"targets[{j}]: expected a Target, got {type(t).__name__}")
            _check_target(t, j, n, self.motion, self.steps)
        object.__setattr__(self, "targets", targets)

    # ------------------------------------------------------------------ labels
    @property
    def clutter_volume(self) -> float:
        """Volume V of the clutter box (product of its side lengths)."""
        return float(np.prod(self.clutter_region[:, 1] - self.clutter_region[:, 0]))

    @property
    def clutter_density(self) -> float:
        """Clutter intensity λ / V per unit measurement volume."""
        return self.clutter_rate / self.clutter_volume

    @property
    def position_indices(self) -> tuple[int, ...]:
        """Position components of the state (from the motion model)."""
        return tuple(self.motion.position_indices)

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """Velocity components of the state (from the motion model, if it says)."""
        return tuple(getattr(self.motion, "velocity_indices", ()))

    @property
    def state_labels(self) -> tuple[str, ...]:
        """``("x", "vx", "y", "vy", ...)`` for a position–velocity state, else ``("s0", "s1", ...)``."""
        n = _state_dim(self.motion, "motion")
        labels = [f"s{i}" for i in range(n)]
        for axis, (p, v) in zip("xyz", zip(self.position_indices, self.velocity_indices)):
            labels[p], labels[v] = axis, f"v{axis}"
        return tuple(labels)

    @property
    def times(self) -> np.ndarray:
        """``(K,)`` scan times, s."""
        return self.dt * np.arange(1, self.steps + 1)

    @property
    def labels(self) -> np.ndarray:
        """``(N,)`` target labels: the slot numbers."""
        return np.arange(len(self.targets))

    # ---------------------------------------------------------------- simulate
    def simulate(self, rng: RNGLike, runs: int | None = None) -> tuple[MultiTargetTruth, Scans]:
        """Truth and detections of ``runs`` runs (default: one per stream of a RunStreams).

        Returns
        -------
        truth, scans
            :class:`~pursuit.multitarget.MultiTargetTruth` ``(K, M, N, n)``
            and :class:`~pursuit.multitarget.Scans` ``(K, M, D, m)`` with
            each row's origin.
        """
        rng, runs = resolve_runs(rng, runs)
        truth = self.simulate_truth(rng, runs)
        return truth, self.detect(truth, rng)

    def simulate_truth(self, rng: RNGLike, runs: int | None = None) -> MultiTargetTruth:
        """The truth alone (the first draws of :meth:`simulate`)."""
        rng, runs = resolve_runs(rng, runs)
        K = self.steps
        n = _state_dim(self.motion, "motion")
        states = np.full((K, runs, len(self.targets), n), np.nan)
        for j, target in enumerate(self.targets):
            first, end = target.lives(K)
            if first > K:
                continue
            x = np.broadcast_to(target.x0, (runs, n)).copy()
            if target.spread is not None:
                x = x + np.einsum("ij,mj->mi", _factor(target.spread), rng.standard_normal((runs, n)))
            anchored = x
            if first <= target.anchor < end:
                states[target.anchor - 1, :, j] = x
            for k in range(target.anchor + 1, end):  # forwards
                motion, accel = _leg_at(target, self.motion, k)
                x = motion.sample(x, k, rng)
                if accel is not None:
                    x = x + _input(motion, accel)
                states[k - 1, :, j] = x
            x = anchored
            motion = target.motion if target.motion is not None else self.motion
            F = np.asarray(motion.transition_matrix(), dtype=float) if first < target.anchor else None
            for k in range(target.anchor - 1, first - 1, -1):  # backwards: x_k = F⁻¹(x_{k+1} + w)
                w = motion.sample(np.zeros_like(x), k + 1, rng)
                x = np.linalg.solve(F, (x + w).T).T
                if k < end:
                    states[k - 1, :, j] = x
        exists = ~np.isnan(states[..., 0])
        return MultiTargetTruth(states, exists, self.labels)

    def detect(self, truth: MultiTargetTruth, rng: RNGLike) -> Scans:
        """Detections of ``truth`` (its runs must match ``rng``'s streams): P_D, noise, clutter, shuffling."""
        rng, runs = resolve_runs(rng, truth.runs)
        if isinstance(rng, RunStreams) and len(rng) != truth.runs:
            raise ValueError(f"rng: {len(rng)} streams for a truth of {truth.runs} runs; give one stream per run")
        K, M, N, _ = truth.states.shape
        m = self.measurement.dim
        z_scans, o_scans = [], []
        for i in range(K):
            k = i + 1
            exists = truth.exists[i]
            detected = exists & (rng.random((M, N)) < self.p_detect)
            x = np.where(exists[..., None], truth.states[i], 0.0)  # no NaN through the sensor's maths
            z_t = np.asarray(self.measurement.sample(x, k, rng), dtype=float).reshape(M, N, m)
            key_t = rng.random((M, N))
            counts = _poisson(rng, self.clutter_rate, M)
            clutter = _ragged_uniform(rng, counts, m + 1)  # (M, C, m + 1): components, then the key
            lo, hi = self.clutter_region[:, 0], self.clutter_region[:, 1]
            z_c = lo + (hi - lo) * clutter[..., :m]
            valid_c = np.arange(clutter.shape[1]) < counts[:, None]
            z_all = np.concatenate([z_t, z_c], axis=1)
            keys = np.concatenate([np.where(detected, key_t, np.inf), np.where(valid_c, clutter[..., m], np.inf)], axis=1)
            origin_all = np.concatenate(
                [np.broadcast_to(np.arange(N), (M, N)), np.full((M, clutter.shape[1]), CLUTTER)], axis=1
            )
            order = np.argsort(keys, axis=1, kind="stable")  # a random order of the detections, padding last
            width = int((detected.sum(axis=1) + counts).max(initial=0))
            order = order[:, :width]
            kept = np.isfinite(np.take_along_axis(keys, order, axis=1))
            z_scans.append(np.where(kept[..., None], np.take_along_axis(z_all, order[..., None], axis=1), np.nan))
            o_scans.append(np.where(kept, np.take_along_axis(origin_all, order, axis=1), PADDING))
        D = max(z.shape[1] for z in z_scans)
        z = np.full((K, M, D, m), np.nan)
        origin = np.full((K, M, D), PADDING, dtype=np.int64)
        for i, (zi, oi) in enumerate(zip(z_scans, o_scans)):
            z[i, :, : zi.shape[1]] = zi
            origin[i, :, : oi.shape[1]] = oi
        return Scans(z, self.times, origin)


# ---------------------------------------------------------------------- helpers
def _state_dim(motion: Any, name: str) -> int:
    dim = getattr(motion, "dim", None)
    if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
        raise ValueError(f"{name}: expected a motion model with an integer dim, got {type(motion).__name__}")
    return int(dim)


def _region(value: Any, m: int) -> np.ndarray:
    try:
        box = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"clutter_region: expected ({m}, 2) numbers (low, high per measurement component)") from None
    if box.shape != (m, 2):
        raise ValueError(f"clutter_region: expected shape ({m}, 2) (low, high per measurement component), got {box.shape}")
    if not np.all(np.isfinite(box)):
        raise ValueError("clutter_region: contains NaN or infinity")
    if not np.all(box[:, 1] > box[:, 0]):
        c = int(np.argmax(~(box[:, 1] > box[:, 0])))
        raise ValueError(f"clutter_region: empty: component {c} has high {box[c, 1]!r} not above low {box[c, 0]!r}")
    box.setflags(write=False)
    return box


def _check_target(t: Target, j: int, n: int, default: Any, steps: int) -> None:
    where = f"targets[{j}]"
    if t.birth > steps:
        raise ValueError(f"{where}.birth: {t.birth} is after the last scan ({steps})")
    if t.anchor > steps:
        raise ValueError(f"{where}.anchor: {t.anchor} is after the last scan ({steps})")
    motions = [("motion", t.motion if t.motion is not None else default)]
    motions += [(f"legs[{i}].motion", leg.motion) for i, leg in enumerate(t.legs) if leg.motion is not None]
    for name, motion in motions:
        if _state_dim(motion, f"{where}.{name}") != n:
            raise ValueError(
                f"{where}.{name}: state dimension {motion.dim} differs from the scenario's motion ({n}): one state layout for all targets"
            )
    if t.x0.shape[0] != n:
        raise ValueError(f"{where}.x0: expected {n} state components, got {t.x0.shape[0]}")
    if t.anchor > t.birth and not hasattr(motions[0][1], "transition_matrix"):
        raise ValueError(f"{where}.anchor: simulating backwards from the anchor needs a linear motion model (transition_matrix)")
    for i, leg in enumerate(t.legs):
        if leg.accel is None:
            continue
        motion = leg.motion if leg.motion is not None else motions[0][1]
        pos = getattr(motion, "position_indices", None)
        if pos is None or getattr(motion, "velocity_indices", None) is None or getattr(motion, "dt", None) is None:
            raise ValueError(f"{where}.legs[{i}].accel: needs a motion with position_indices, velocity_indices and dt")
        if leg.accel.shape[0] != len(pos):
            raise ValueError(f"{where}.legs[{i}].accel: expected {len(pos)} components (one per position axis), got {leg.accel.shape[0]}")


def _leg_at(target: Target, default: Any, k: int) -> tuple[Any, np.ndarray | None]:
    """The motion and acceleration input of the transition into scan ``k``."""
    motion = target.motion if target.motion is not None else default
    accel = None
    for leg in target.legs:
        if leg.start > k:
            break
        motion = leg.motion if leg.motion is not None else (target.motion if target.motion is not None else default)
        accel = leg.accel
    return motion, accel


def _input(motion: Any, accel: np.ndarray) -> np.ndarray:
    """``G a``: a constant acceleration over one step on each axis's position and velocity."""
    dt = float(motion.dt)
    u = np.zeros(motion.dim)
    u[list(motion.position_indices)] = 0.5 * dt * dt * accel
    u[list(motion.velocity_indices)] = dt * accel
    return u


def _factor(C: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(C)
    return V * np.sqrt(np.clip(w, 0.0, None))


def _poisson(rng: np.random.Generator | RunStreams, lam: float, runs: int) -> np.ndarray:
    """``(runs,)`` Poisson counts, run i's from stream i."""
    if lam == 0.0:
        return np.zeros(runs, dtype=np.int64)
    if isinstance(rng, RunStreams):
        return np.array([g.poisson(lam) for g in rng.generators], dtype=np.int64)
    return rng.poisson(lam, runs).astype(np.int64)


def _ragged_uniform(rng: np.random.Generator | RunStreams, counts: np.ndarray, width: int) -> np.ndarray:
    """``(runs, max count, width)`` uniforms, run i's first ``counts[i]`` rows from stream i (the rest 0).

    Run i draws exactly ``counts[i] * width`` numbers, so its stream does not
    depend on the other runs' counts (one NumPy call per run, as RunStreams
    draws anyway).
    """
    runs = counts.shape[0]
    out = np.zeros((runs, int(counts.max(initial=0)), width))
    if isinstance(rng, RunStreams):
        for g, c, row in zip(rng.generators, counts, out):
            if c:
                g.random(out=row[:c])
        return out
    flat = rng.random((int(counts.sum()), width))
    rows = np.arange(out.shape[1]) < counts[:, None]
    out[rows] = flat
    return out


# -------------------------------------------------------------------- built-ins
def crossing(*, clutter_rate: float = 5.0, p_detect: float = 0.9, steps: int = 20) -> MultiTargetScenario:
    """Two 2-D constant-velocity targets whose paths cross (docs/spec/05-multi-target-pmht.md §6).

    The Stone Soup tutorials' set-up: targets from ``(0, 1, 0, 1)`` and
    ``(0, 1, 20, −1)`` (state ``[x, vx, y, vy]``, at scan 1), both alive
    throughout, continuous white-noise acceleration with q = 0.005 m²/s³
    (Stone Soup's ``ConstantVelocity(0.005)``), position measurements with
    R = 0.75 I, P_D = 0.9, 20 scans 1 s apart; they cross at (10, 10)
    around scan 11.  Clutter [DEFAULT]: Poisson with mean 5 per scan,
    uniform over the box x, y ∈ [−10, 30] m, which holds both paths with a
    10 m margin (Stone Soup draws 0-9 false alarms over a similar box).
    """
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.005, noise="continuous")
    sensor = LinearGaussian.position(4, (0, 2), math.sqrt(0.75))
    targets = (Target([0.0, 1.0, 0.0, 1.0]), Target([0.0, 1.0, 20.0, -1.0]))
    return MultiTargetScenario(
        targets, motion, sensor, [[-10.0, 30.0], [-10.0, 30.0]], clutter_rate, p_detect, steps, 1.0, "mt-crossing",
        max_speed=5.0,
    )


WILLIAMS15_STEPS = 81
"""Scans of the Williams 2015 scenario (``Nsteps`` in ScenarioWilliams15.m; odd, so that it has a midpoint)."""


WILLIAMS15_GOSPA = {"c": 10.0, "p": 2.0, "alpha": 2.0}
"""The GOSPA settings the MATLAB code scores the Williams 2015 scenario with (``c_gospa = 10``, p = 2, α = 2; 100 runs)."""


def williams15(*, clutter_rate: float = 10.0, p_detect: float = 0.9) -> MultiTargetScenario:
    """Four constant-velocity targets that meet mid-scenario (Williams 2015; docs/spec/05-multi-target-pmht.md §6).

    The numbers are those of ``PMBM filter/ScenarioWilliams15.m`` and
    ``TrajectoryWilliams15.m`` (scenario number 1) in the public MATLAB
    repository github.com/Agarciafernandez/MTT (read at commit cc5c6df,
    April 2026):

    * T = 1 s, 81 scans; state ``[x, vx, y, vy]``;
      F = I₂ ⊗ [[1, T], [0, 1]], Q = 0.02 · I₂ ⊗ [[T³/3, T²/2], [T²/2, T]]
      (continuous white-noise acceleration with q = 0.02 m²/s³; the spec's
      summary says 0.01, the code says 0.02 and wins);
    * H picks x and y, R = I (m²); P_D = 0.9;
    * clutter: Poisson with mean 10 per scan, uniform over the 300 m × 300 m
      area [0, 300] × [0, 300];
    * the truth is anchored at the midpoint, scan 41: each target's state
      there is drawn from N((150, 0, 150, 0), 0.1 I), so the four targets
      nearly coincide, almost at rest, then simulated forwards with the
      motion model and backwards with ``x_{k−1} = F⁻¹(x_k + w)``;
    * births and deaths (``t_birth``, ``t_death``): all four exist from
      scan 1; target 1 dies at scan 41 (it exists at scans 1-40), the
      others live to scan 81.

    The MATLAB demo draws one truth with a fixed seed and reuses it in all
    its runs; here every run draws its own truth by that recipe (from its
    own stream), so a Monte Carlo average covers the scenario's randomness.
    """
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.02, noise="continuous")
    sensor = LinearGaussian.position(4, (0, 2), 1.0)
    mid = (WILLIAMS15_STEPS + 1) // 2
    centre = [150.0, 0.0, 150.0, 0.0]
    deaths = (mid, None, None, None)
    targets = tuple(Target(centre, 1, d, spread=0.1 * np.eye(4), anchor=mid) for d in deaths)
    return MultiTargetScenario(
        targets, motion, sensor, [[0.0, 300.0], [0.0, 300.0]], clutter_rate, p_detect, WILLIAMS15_STEPS, 1.0, "mt-williams15",
        max_speed=5.0,
    )


def maneuvering_radar(*, clutter_rate: float = 20.0, p_detect: float = 0.9) -> MultiTargetScenario:
    """Three maneuvering targets seen by a range-bearing radar in clutter [DEFAULT].

    docs/spec/05-multi-target-pmht.md §6 asks for two or three targets at
    radar scale with coordinated turns and acceleration segments; the
    numbers are ours.  A radar at the origin measures range (σ = 20 m) and
    bearing (σ = 2 mrad) once a second for 100 scans; P_D = 0.9; clutter
    Poisson with mean 20 per scan, uniform in range [2, 30] km and bearing
    [0, π/2] (the quadrant the targets fly in).  State ``[x, vx, y, vy]``
    (m, m/s), nearly constant velocity with q = 1 (m/s²)² between maneuvers:

    * target 0, from (14 km, 4 km) at (−180, 60) m/s: a coordinated turn at
      −3°/s (clockwise, a quarter circle) over scans 31-60, then straight on;
    * target 1, from (3 km, 15 km) at (150, −100) m/s: accelerates at
      (0, +20) m/s² (about 2 g, the maneuver level of §3) over scans 41-50;
    * target 2, born at scan 21 from (18 km, 18 km) at (−150, −200) m/s,
      gone after scan 90: a −2°/s turn over scans 51-70 and a
      (−10, +10) m/s² push over scans 71-80.
    """
    dt = 1.0
    q = 1.0
    motion = ConstantVelocity(ndim=2, dt=dt, q=q)
    deg = math.pi / 180.0
    targets = (
        Target([14_000.0, -180.0, 4_000.0, 60.0], legs=(Leg(31, ConstantTurn(-3 * deg, q, 2, dt)), Leg(61))),
        Target([3_000.0, 150.0, 15_000.0, -100.0], legs=(Leg(41, accel=[0.0, 20.0]), Leg(51))),
        Target(
            [18_000.0, -150.0, 18_000.0, -200.0],
            birth=21,
            death=91,
            legs=(Leg(51, ConstantTurn(-2 * deg, q, 2, dt)), Leg(71, accel=[-10.0, 10.0]), Leg(81)),
        ),
    )
    radar = RangeBearing(np.zeros(2), 20.0, 0.002)
    region = [[2_000.0, 30_000.0], [0.0, math.pi / 2]]
    return MultiTargetScenario(
        targets, motion, radar, region, clutter_rate, p_detect, 100, dt, "mt-maneuvering-radar", max_speed=400.0
    )
