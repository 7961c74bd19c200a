"""Priors from the first measurements (track initiation), instead of a guessed ``[prior]``.

A filter needs a Gaussian prior on the whole state.  When nothing is known
before the first measurements, the prior can be built from them, as
MATLAB's ``initcvekf`` does and as Bar-Shalom, Li & Kirubarajan describe
(*Estimation with Applications to Tracking and Navigation*, §5.5.3):

* a **position** with its covariance comes from one scan of measurements:
  a position fix directly, a range and a bearing from one site by
  :func:`polar_to_cartesian`, ranges to ``d + 1`` or more anchors by
  :func:`multilaterate`;
* :func:`one_point` puts one such position into a state: position known,
  velocity zero with a large documented variance (the target's speed is
  unknown), acceleration zero;
* :func:`two_point` is the two-point differencing initiation: the position
  of the later scan, the velocity from the difference of the two positions,
  and the covariance that follows from the two positions' covariances and dt.

States are laid out by the motion model's ``position_indices``,
``velocity_indices`` and (where it has them) ``acceleration_indices``, so the
same helpers serve CV, CA, constant-turn and Singer states.

Example
-------
>>> import numpy as np
>>> from pursuit.models import ConstantVelocity
>>> from pursuit.initiation import two_point
>>> R = np.eye(2) * 4.0
>>> prior = two_point([0.0, 0.0], R, [1.0, 2.0], R, dt=1.0, motion=ConstantVelocity(ndim=2))
>>> prior.mean
array([1., 1., 2., 2.])
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .gaussian import Gaussian
from .models.toa import trilaterate

__all__ = ["polar_to_cartesian", "multilaterate", "one_point", "two_point", "VELOCITY_SIGMA", "ACCELERATION_SIGMA"]

VELOCITY_SIGMA = 10.0
"""Default standard deviation (m/s) of a velocity nothing has measured yet (MATLAB's ``initcvekf`` uses variance 100)."""

ACCELERATION_SIGMA = 10.0
"""Default standard deviation (m/s²) of an acceleration nothing has measured yet."""


def polar_to_cartesian(
    r: Any, bearing: Any, sigma_r: float, sigma_bearing: float, origin: Any = (0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray]:
    """A 2-D position from a range and a bearing measured at one site: the standard conversion.

    ``p = origin + r [cos θ, sin θ]`` with the linearised (first-order)
    covariance ``C = J diag(σ_r², σ_θ²) Jᵀ``, ``J = ∂p/∂(r, θ)``.  This is
    the *standard* converted measurement, not the debiased one: it is
    consistent while the cross-range error ``r σ_θ`` is small against the
    range (``r σ_θ² / σ_r`` well below 1, e.g. σ_θ of a few degrees); beyond
    that the conversion bias (a factor ``e^(−σ_θ²/2)`` on the mean) is no
    longer negligible.

    Parameters
    ----------
    r, bearing
        Range (m) and bearing (rad from the x axis), scalars or arrays of
        one shape ``b``.
    sigma_r, sigma_bearing
        Their noise standard deviations (m, rad).
    origin
        The site's position ``(2,)``.

    Returns
    -------
    p, C
        ``(*b, 2)`` positions and ``(*b, 2, 2)`` covariances.
    """
    r = np.asarray(r, dtype=float)
    th = np.asarray(bearing, dtype=float)
    c, s = np.cos(th), np.sin(th)
    p = np.asarray(origin, dtype=float) + np.stack([r * c, r * s], axis=-1)
    J = np.stack([np.stack([c, -r * s], axis=-1), np.stack([s, r * c], axis=-1)], axis=-2)  # (*b, 2, 2)
    D = np.diag([float(sigma_r) ** 2, float(sigma_bearing) ** 2])
    C = np.einsum("...ij,jk,...lk->...il", J, D, J)
    return p, C


def multilaterate(anchors: Any, ranges: Any, sigma: Any, iterations: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A position from ranges to ``s ≥ d + 1`` anchors in ``d`` dimensions: least squares.

    The start is the linear least-squares solution of the circle equations
    differenced against the first anchor (:func:`pursuit.models.trilaterate`);
    a few Gauss-Newton steps then minimise Σ (r_i − ‖p − a_i‖)² / σ_i², and
    the covariance is the inverse Fisher information ``(Jᵀ R⁻¹ J)⁻¹`` at the
    solution (J the unit vectors from the anchors).  Consistent when the
    range noise is small against the anchors' spread.

    Parameters
    ----------
    anchors
        ``(s, d)`` anchor positions.
    ranges
        ``(*b, s)`` measured ranges (m).
    sigma
        Range noise standard deviation: one number or ``(s,)``.
    iterations
        Gauss-Newton steps after the linear start.

    Returns
    -------
    p, C
        ``(*b, d)`` positions and ``(*b, d, d)`` covariances.

    Raises
    ------
    ValueError
        With fewer than ``d + 1`` anchors, or anchors on one line (2-D) or
        plane (3-D), where ranges do not fix a position.
    """
    A = np.asarray(anchors, dtype=float)
    if A.ndim != 2:
        raise ValueError(f"anchors: expected (s, d), got shape {A.shape}")
    s, d = A.shape
    if s < d + 1:
        raise ValueError(f"ranges: a position in {d}-D needs ranges to at least {d + 1} anchors, got {s}")
    if np.linalg.matrix_rank(A[1:] - A[0]) < d:
        raise ValueError(f"anchors: the {s} anchors lie on a {'line' if d == 2 else 'plane'}; ranges do not fix a position")
    r = np.asarray(ranges, dtype=float)
    w = 1.0 / np.broadcast_to(np.asarray(sigma, dtype=float), (s,)) ** 2
    p = trilaterate(A, r)
    for _ in range(iterations):
        diff = p[..., None, :] - A  # (*b, s, d)
        dist = np.maximum(np.linalg.norm(diff, axis=-1), 1e-12)
        J = diff / dist[..., None]
        JW = J * w[:, None]
        info = np.einsum("...si,...sj->...ij", JW, J)
        p = p + np.linalg.solve(info, np.einsum("...si,...s->...i", JW, r - dist)[..., None])[..., 0]
    diff = p[..., None, :] - A
    J = diff / np.maximum(np.linalg.norm(diff, axis=-1), 1e-12)[..., None]
    C = np.linalg.inv(np.einsum("...si,...sj->...ij", J * w[:, None], J))
    return p, 0.5 * (C + np.swapaxes(C, -1, -2))


def _layout(motion: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    pos = np.asarray(motion.position_indices, dtype=int)
    vel = np.asarray(motion.velocity_indices, dtype=int)
    acc = np.asarray(getattr(motion, "acceleration_indices", ()), dtype=int)
    n = int(motion.dim)
    covered = sorted([*pos.tolist(), *vel.tolist(), *acc.tolist()])
    if covered != list(range(n)):
        raise ValueError(
            f"motion: its state has components that are neither position, velocity nor acceleration "
            f"({type(motion).__name__}, {n} components); give a [prior] instead"
        )
    return pos, vel, acc, n


def _state(motion, p, Cp, v, Cv, Cpv, acceleration_sigma) -> Gaussian:
    pos, vel, acc, n = _layout(motion)
    d = pos.size
    p = np.asarray(p, dtype=float)
    if p.shape[-1] != d:
        raise ValueError(f"position: expected {d} coordinates for a {d}-axis motion model, got {p.shape[-1]}")
    batch = p.shape[:-1]
    mean = np.zeros((*batch, n))
    cov = np.zeros((*batch, n, n))
    mean[..., pos] = p
    mean[..., vel] = v
    cov[..., pos[:, None], pos[None, :]] = Cp
    cov[..., vel[:, None], vel[None, :]] = Cv
    cov[..., pos[:, None], vel[None, :]] = Cpv
    cov[..., vel[:, None], pos[None, :]] = np.swapaxes(np.broadcast_to(Cpv, (*batch, d, d)), -1, -2)
    cov[..., acc, acc] = float(acceleration_sigma) ** 2
    return Gaussian(mean, cov)


def one_point(
    p: Any, C: Any, motion: Any, velocity_sigma: float = VELOCITY_SIGMA, acceleration_sigma: float = ACCELERATION_SIGMA
) -> Gaussian:
    """A prior from one position: the position as measured, velocity and acceleration unknown.

    Velocity and acceleration get mean zero and the variances
    ``velocity_sigma²`` and ``acceleration_sigma²`` per axis: choose them
    to cover the fastest target you expect (the default 10 m/s, as MATLAB's
    ``initcvekf``, suits walking and slow vehicles, not aircraft).

    Parameters
    ----------
    p, C
        ``(*b, d)`` position and ``(*b, d, d)`` its covariance.
    motion
        The motion model whose state the prior is for.
    velocity_sigma, acceleration_sigma
        Standard deviations of the unknown velocity (m/s) and acceleration (m/s²).
    """
    p = np.asarray(p, dtype=float)
    d = p.shape[-1]
    eye = np.eye(d)
    return _state(motion, p, C, 0.0, float(velocity_sigma) ** 2 * eye, np.zeros((d, d)), acceleration_sigma)


def two_point(
    p1: Any, C1: Any, p2: Any, C2: Any, dt: float, motion: Any, acceleration_sigma: float = ACCELERATION_SIGMA
) -> Gaussian:
    """Two-point differencing: the prior at the time of the second position.

    ``x̂ = [p₂, (p₂ − p₁)/dt]`` per axis with ``P_pp = C₂``,
    ``P_pv = C₂/dt`` and ``P_vv = (C₁ + C₂)/dt²`` (the two positions'
    errors independent); an acceleration in the state gets mean zero and
    variance ``acceleration_sigma²``.  Like the textbook version it ignores
    the process noise between the two positions: for a target that
    accelerates by about ``a`` meanwhile, the velocity error gains about
    ``a dt / 2`` not covered by P.

    Parameters
    ----------
    p1, C1, p2, C2
        The two positions ``(*b, d)`` and their covariances ``(*b, d, d)``.
    dt
        Time from the first to the second position, s (> 0).
    motion
        The motion model whose state the prior is for.
    acceleration_sigma
        Standard deviation of the unknown acceleration (m/s²).
    """
    if not (isinstance(dt, (int, float, np.floating)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: the two positions must be at increasing times, got dt = {dt!r}")
    p1 = np.asarray(p1, dtype=float)
    p2 = np.asarray(p2, dtype=float)
    C1 = np.asarray(C1, dtype=float)
    C2 = np.asarray(C2, dtype=float)
    return _state(motion, p2, C2, (p2 - p1) / dt, (C1 + C2) / dt**2, C2 / dt, acceleration_sigma)
