"""A linear-Gaussian motion model given by its matrices: x_k = F x_{k−1} + w, w ~ N(0, Q)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import psd_factor
from .._validation import as_covariance, as_matrix
from ..rng import RNGLike, as_rng

__all__ = ["LinearMotion"]


@dataclass(frozen=True, eq=False)
class LinearMotion:
    """Time-invariant linear motion with additive Gaussian noise.

    Use it when a paper states F and Q directly (paper P2 uses a
    constant-velocity F with ``Q = 0.01² I``, which is not a kinematic
    white-noise Q).

    Parameters
    ----------
    F
        ``(n, n)`` transition matrix.
    Q
        Process-noise covariance: ``(n, n)``, a vector of variances or a
        scalar variance; positive semidefinite.

    Notes
    -----
    ``dt`` is accepted for a uniform interface and ignored: F and Q are for
    the model's fixed sampling interval.
    """

    F: np.ndarray
    Q: np.ndarray

    def __post_init__(self) -> None:
        F = as_matrix("F", self.F)
        if F.shape[0] != F.shape[1]:
            raise ValueError(f"F: expected a square matrix, got shape {F.shape}")
        Q = as_covariance("Q", self.Q, F.shape[0], allow_singular=True)
        for name, arr in (("F", F), ("Q", Q), ("_G", psd_factor(Q))):
            arr = np.array(arr, dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __setstate__(self, state: dict) -> None:
        # pickle gives writable arrays back: freeze them again, as __post_init__ did (filters cache F and Q on that)
        for name, value in state.items():
            if isinstance(value, np.ndarray):
                value = value.copy()
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def dim(self) -> int:
        """State dimension n."""
        return self.F.shape[0]

    def transition_matrix(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """F, ``(n, n)``."""
        return self.F

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """``F x`` for a batch of states."""
        return np.einsum("ij,...j->...i", self.F, x)

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """The shared matrix F."""
        return self.F

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Q, ``(n, n)``."""
        return self.Q

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """Draw x_k ~ N(F x, Q) for a batch of states (``rng`` may be RunStreams)."""
        xi = as_rng(rng).standard_normal((*x.shape[:-1], self._G.shape[1]))
        return self.f(x) + np.einsum("ij,...j->...i", self._G, xi)
