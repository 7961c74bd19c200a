"""Underwater acoustic TOA positioning (paper P2): an L-shaped three-hydrophone array.

The target moves inside (and, under model mismatch, out of) an L-shaped
array A(0,0), B(0,d), C(d,0) and sends acoustic pings; the hydrophones
measure one-way travel times.  The filter may be given the three ranges
(r_i = c t_i), the travel times themselves, or the closed-form position fix.

Paper P2 compares the fading filters under three conditions (docs/spec/03-fading-memory-ekf.md §6.2):

========  ==================  ===========================  =====================
condition initial estimate    truth                         measurements
========  ==================  ===========================  =====================
ideal     X0 = S0             x_k = F x_{k−1} + w_k         clean
actual    X0 = 1.06 S0        x_k = F x_{k−1} + B_k + w_k   clean
abnormal  X0 = 1.20 S0        x_k = F x_{k−1} + w_k         +1 m on every range at 15 s
========  ==================  ===========================  =====================

B_k (the "model change matrix" of P2's eq. 7, unknown to the filter) has
position elements drawn each step from U[1, 2] m.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from .._validation import as_covariance, as_vector, in_range, nonnegative, positive, positive_int
from ..gaussian import Gaussian
from ..models.linear_motion import LinearMotion
from ..models.measurement import RangeSensors, TimeOfArrival
from ..models.toa import PositionFix, l_array, trilaterate, trilateration_jacobian
from ..rng import RNGLike, RunStreams, as_rng
from .base import Simulation

__all__ = ["UnderwaterTOA", "CONDITIONS"]

CONDITIONS: dict[str, dict[str, object]] = {
    "ideal": {"initial_error": 0.0, "mismatch": (0.0, 0.0), "outlier_time": None},
    "actual": {"initial_error": 0.06, "mismatch": (1.0, 2.0), "outlier_time": None},
    "abnormal": {"initial_error": 0.20, "mismatch": (0.0, 0.0), "outlier_time": 15.0},
}
MODES = ("ranges", "times", "position")
STATES = ("cv", "position")


@dataclass(frozen=True, eq=False)
class UnderwaterTOA:
    """Paper P2's underwater TOA positioning scenario.

    Parameters
    ----------
    condition
        ``"ideal"``, ``"actual"`` or ``"abnormal"``: sets the defaults of
        ``initial_error``, ``mismatch`` and ``outlier_time`` (table above).
    mode
        What the filter receives: ``"ranges"`` (default; m), ``"times"``
        (travel times, s) or ``"position"`` (closed-form fix from the ranges;
        a linear measurement, so the plain KF applies).
    d
        Array spacing, m (A(0,0), B(0,d), C(d,0)).
    c
        Sound speed, m/s.
    sigma_r
        Range noise standard deviation, m (travel times: ``sigma_r / c``).
    q
        Process-noise variance of every state component: Q = q I.
    state
        ``"cv"``: X = [x, y, vx, vy] with constant-velocity F (default);
        ``"position"``: X = [x, y] with F = I.
    steps, dt
        Number of pings and interval between them, s.
    x0
        True initial state S0 (default [10, 20, 0.5, 0.4], or [10, 20]).
    P0
        Prior covariance (default identity, as the paper recommends).
    initial_error
        Relative initial error: the filters start at (1 + e) S0.
    mismatch
        ``(low, high)`` of the uniform B_k added to the true positions each
        step (``(0, 0)``: none).  The filter does not know it.
    outlier_time
        Time in s of the one outlier (None: no outlier).
    outlier_size
        Added to every range at the outlier, m.
    """

    condition: Literal["ideal", "actual", "abnormal"] = "ideal"
    mode: Literal["ranges", "times", "position"] = "ranges"
    d: float = 50.0
    c: float = 1500.0
    sigma_r: float = 0.002
    q: float = 1.0e-4
    state: Literal["cv", "position"] = "cv"
    steps: int = 60
    dt: float = 1.0
    x0: np.ndarray | None = None
    P0: np.ndarray | None = None
    initial_error: float | None = None
    mismatch: tuple[float, float] | None = None
    outlier_time: float | None = None
    outlier_size: float = 1.0
    name: str = ""

    def __post_init__(self) -> None:
        if self.condition not in CONDITIONS:
            raise ValueError(f"condition: must be one of {', '.join(CONDITIONS)}, got {self.condition!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode: must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.state not in STATES:
            raise ValueError(f"state: must be one of {', '.join(STATES)}, got {self.state!r}")
        defaults = CONDITIONS[self.condition]
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        set_("d", positive("d", self.d))
        set_("c", positive("c", self.c))
        set_("sigma_r", positive("sigma_r", self.sigma_r))
        set_("q", positive("q", self.q))
        set_("steps", positive_int("steps", self.steps))
        set_("dt", positive("dt", self.dt))
        n = 4 if self.state == "cv" else 2
        x0 = np.array([10.0, 20.0, 0.5, 0.4])[:n] if self.x0 is None else self.x0
        set_("x0", as_vector("x0", x0, n))
        set_("P0", as_covariance("P0", np.eye(n) if self.P0 is None else self.P0, n))
        e = defaults["initial_error"] if self.initial_error is None else self.initial_error
        set_("initial_error", nonnegative("initial_error", e))
        mm = defaults["mismatch"] if self.mismatch is None else self.mismatch
        mm = as_vector("mismatch", mm, 2)
        if mm[1] < mm[0]:
            raise ValueError(f"mismatch: high must be at least low, got {tuple(mm)}")
        set_("mismatch", (float(mm[0]), float(mm[1])))
        t_out = defaults["outlier_time"] if self.outlier_time is None else self.outlier_time
        if t_out is not None:
            t_out = positive("outlier_time", t_out)
        set_("outlier_time", t_out)
        set_("outlier_size", in_range("outlier_size", self.outlier_size, -1.0e6, 1.0e6))
        if not self.name:
            set_("name", f"underwater-toa-{self.condition}")

        anchors = l_array(self.d)
        if self.state == "cv":
            F = np.eye(4)
            F[0, 2] = F[1, 3] = self.dt
        else:
            F = np.eye(2)
        set_("_anchors", anchors)
        set_("_motion", LinearMotion(F, self.q * np.eye(n)))
        set_("_measurement", self._build_measurement(anchors, n))

    # -- scenario protocol ----------------------------------------------------
    @property
    def state_labels(self) -> tuple[str, ...]:
        """``("x", "y", "vx", "vy")`` or ``("x", "y")``."""
        return ("x", "y", "vx", "vy") if self.state == "cv" else ("x", "y")

    @property
    def state_units(self) -> tuple[str, ...]:
        """Metres for positions, metres per second for velocities."""
        return ("m", "m", "m/s", "m/s") if self.state == "cv" else ("m", "m")

    position_indices = (0, 1)

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """``(2, 3)`` for the CV state, else empty."""
        return (2, 3) if self.state == "cv" else ()

    @property
    def motion(self) -> LinearMotion:
        """The filters' motion model (without the mismatch B_k)."""
        return self._motion

    @property
    def measurement(self):
        """The filters' measurement model for ``mode``."""
        return self._measurement

    @property
    def anchors(self) -> np.ndarray:
        """Hydrophone positions A, B, C, ``(3, 2)``."""
        return self._anchors

    @property
    def outlier_step(self) -> int | None:
        """Step index k (1-based) of the outlier, or None."""
        if self.outlier_time is None or self.outlier_size == 0.0:
            return None
        k = int(round(self.outlier_time / self.dt))
        return k if 1 <= k <= self.steps else None

    @property
    def events(self) -> tuple[tuple[float, str], ...]:
        """``(time, label)`` of marked events (the outlier), for figures."""
        k = self.outlier_step
        return () if k is None else ((k * self.dt, "outlier"),)

    @property
    def initial_estimate(self) -> np.ndarray:
        """The filters' prior mean (1 + initial_error) S0."""
        return (1.0 + self.initial_error) * self.x0

    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Truth and measurements for ``runs`` runs.

        Per run and step the draws are: process noise (n normals), the
        mismatch B_k (2 uniforms, only when ``mismatch`` is not (0, 0)),
        range noise (3 normals).
        """
        rng = as_rng(rng)
        if runs is None:
            if not isinstance(rng, RunStreams):
                raise ValueError("runs: required when rng is a single Generator")
            runs = len(rng)
        runs = positive_int("runs", runs)
        n = self.x0.shape[0]
        lo, hi = self.mismatch
        x = np.broadcast_to(self.x0, (runs, n))
        truth = np.empty((self.steps, runs, n))
        ranges = np.empty((self.steps, runs, 3))
        for i in range(self.steps):
            k = i + 1
            x = self.motion.sample(x, k, rng)
            if hi > 0.0:
                x = x.copy()
                x[:, :2] += rng.uniform(lo, hi, size=(runs, 2))
            noise = rng.standard_normal((runs, 3))
            r = self._true_ranges(x) + self.sigma_r * noise
            if k == self.outlier_step:
                r = r + self.outlier_size
            truth[i] = x
            ranges[i] = r
        prior = Gaussian(np.broadcast_to(self.initial_estimate, (runs, n)).copy(), self.P0)
        times = self.dt * np.arange(1, self.steps + 1)
        return Simulation(truth=truth, measurements=self._measure(ranges), prior=prior, times=times, extra={"ranges": ranges})

    # -- internals ------------------------------------------------------------
    def _true_ranges(self, x: np.ndarray) -> np.ndarray:
        diff = x[..., None, :2] - self._anchors
        return np.sqrt(np.einsum("...i,...i->...", diff, diff))

    def _measure(self, ranges: np.ndarray) -> np.ndarray:
        if self.mode == "ranges":
            return ranges
        if self.mode == "times":
            return ranges / self.c
        return trilaterate(self._anchors, ranges)

    def _build_measurement(self, anchors: np.ndarray, n: int):
        if self.mode == "ranges":
            return RangeSensors(anchors, self.sigma_r, (0, 1))
        if self.mode == "times":
            return TimeOfArrival(anchors, self.sigma_r / self.c, (0, 1), c=self.c)
        # Position fix: R_k by error propagation J σ_r² Jᵀ along the nominal
        # path F^k S0 (what the filter can know in advance; not the truth).
        F = self._motion.F
        path = np.empty((self.steps, n))
        x = self.x0
        for i in range(self.steps):
            x = F @ x
            path[i] = x
        J = trilateration_jacobian(anchors, self._true_ranges(path))
        R = self.sigma_r**2 * np.einsum("kij,klj->kil", J, J)
        return PositionFix(n, (0, 1), R)
