"""Closed-form TOA positioning and the position-fix measurement model it feeds.

Three (or more) hydrophones at known positions a_i measure one-way travel
times t_i, hence ranges r_i = c t_i.  Subtracting the first circle equation
‖p − a_1‖² = r_1² from the others removes ‖p‖² and leaves a linear system

    2 (a_i − a_1)ᵀ p = r_1² − r_i² + ‖a_i‖² − ‖a_1‖²,   i = 2..s,

solved exactly for three anchors and by least squares for more.  For paper
P2's L-shaped array A(0,0), B(0,d), C(d,0) this is its equation (4):

    x = (d² + r_1² − r_3²)/(2d),   y = (d² + r_1² − r_2²)/(2d).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .._validation import as_matrix, positive
from ..rng import RNGLike, as_rng
from .measurement import gaussian_loglik

__all__ = ["l_array", "toa_position", "trilaterate", "trilateration_jacobian", "PositionFix"]


def l_array(d: float = 50.0) -> np.ndarray:
    """Paper P2's L-shaped array: A(0, 0), B(0, d), C(d, 0), as ``(3, 2)``."""
    d = positive("d", d)
    return np.array([[0.0, 0.0], [0.0, d], [d, 0.0]])


def toa_position(ranges: np.ndarray, d: float = 50.0) -> np.ndarray:
    """Paper P2's eq. (4): position ``(*b, 2)`` from ranges ``(*b, 3)`` to A(0,0), B(0,d), C(d,0)."""
    r = np.asarray(ranges, dtype=float)
    r1, r2, r3 = r[..., 0], r[..., 1], r[..., 2]
    x = (d * d + r1 * r1 - r3 * r3) / (2.0 * d)
    y = (d * d + r1 * r1 - r2 * r2) / (2.0 * d)
    return np.stack([x, y], axis=-1)


def _design(anchors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverse of the linear system's matrix and the anchors' constant terms."""
    a = as_matrix("anchors", anchors)
    if a.shape[0] < a.shape[1] + 1:
        raise ValueError(f"anchors: {a.shape[1]}-D positioning needs at least {a.shape[1] + 1} anchors, got {a.shape[0]}")
    A = 2.0 * (a[1:] - a[0])
    if np.linalg.matrix_rank(A) < a.shape[1]:
        raise ValueError("anchors: are collinear (coplanar in 3-D); the position is not determined")
    const = np.sum(a[1:] ** 2, axis=1) - np.sum(a[0] ** 2)
    return np.linalg.pinv(A), const


def trilaterate(anchors: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Position ``(*b, d)`` from ranges ``(*b, s)`` to ``s`` anchors ``(s, d)``.

    Exact for ``s = d + 1`` non-degenerate anchors; linear least squares
    (on the differenced circle equations) for more.
    """
    pinv, const = _design(anchors)
    r2 = np.asarray(ranges, dtype=float) ** 2
    b = r2[..., :1] - r2[..., 1:] + const
    return np.einsum("ij,...j->...i", pinv, b)


def trilateration_jacobian(anchors: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """∂p/∂r of :func:`trilaterate`, ``(*b, d, s)``: for propagating range noise into the fix."""
    pinv, _ = _design(anchors)
    r = np.asarray(ranges, dtype=float)
    s = r.shape[-1]
    db = np.zeros((*r.shape[:-1], s - 1, s))
    db[..., :, 0] = 2.0 * r[..., :1]
    idx = np.arange(s - 1)
    db[..., idx, idx + 1] = -2.0 * r[..., 1:]
    return np.einsum("ij,...jk->...ik", pinv, db)


@dataclass(frozen=True, eq=False)
class PositionFix:
    """A position fix z = p + v with v ~ N(0, R_k): linear in the state, R may change with the step.

    Parameters
    ----------
    state_dim
        Size of the state.
    position_indices
        Indices of the fixed position components in the state.
    R
        ``(d, d)`` noise covariance, or ``(K, d, d)``: one per step k = 1..K
        (steps beyond K use the last, k < 1 the first).
    """

    state_dim: int
    position_indices: Sequence[int]
    R: np.ndarray

    def __post_init__(self) -> None:
        idx = tuple(int(i) for i in self.position_indices)
        if not idx or any(not 0 <= i < self.state_dim for i in idx):
            raise ValueError(f"position_indices: must lie in [0, {self.state_dim - 1}], got {idx}")
        R = np.array(self.R, dtype=float)
        if R.ndim == 2:
            R = R[None]
        d = len(idx)
        if R.ndim != 3 or R.shape[1:] != (d, d):
            raise ValueError(f"R: expected ({d}, {d}) or (K, {d}, {d}), got shape {np.shape(self.R)}")
        if not np.all(np.isfinite(R)) or np.any(np.linalg.eigvalsh(0.5 * (R + np.swapaxes(R, 1, 2))) <= 0):
            raise ValueError("R: every covariance must be finite and positive definite")
        H = np.zeros((d, self.state_dim))
        H[np.arange(d), idx] = 1.0
        chol = np.linalg.cholesky(R)
        for name, arr in (("R", R), ("H", H), ("_chol", chol)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "position_indices", idx)

    @property
    def dim(self) -> int:
        """Measurement dimension."""
        return self.H.shape[0]

    def _step(self, k: int | None) -> int:
        if k is None:
            return 0
        return int(min(max(int(k), 1), self.R.shape[0])) - 1

    def matrix(self, k: int | None = None) -> np.ndarray:
        """H: selects the position components."""
        return self.H

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """The position components of a batch of states."""
        return x[..., list(self.position_indices)]

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None) -> np.ndarray:
        """The shared matrix H."""
        return self.H

    def cov(self, k: int | None = None) -> np.ndarray:
        """R_k, ``(d, d)``."""
        return self.R[self._step(k)]

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b``."""
        return a - b

    def loglik(self, z: np.ndarray, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """log N(z; h(x), R_k), NaN components skipped."""
        return gaussian_loglik(z - self.h(x, k), self.cov(k))

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike) -> np.ndarray:
        """A Gaussian fix of a batch of states (the TOA scenario instead fixes from noisy ranges)."""
        zp = self.h(x, k)
        xi = as_rng(rng).standard_normal(zp.shape)
        return zp + np.einsum("ij,...j->...i", self._chol[self._step(k)], xi)
