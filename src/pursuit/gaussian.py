"""The Gaussian prior / posterior container."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validation import as_covariance, as_float_array
from .rng import RNGLike, RunStreams, as_rng

__all__ = ["Gaussian"]


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian density N(mean, cov), possibly with a batch of means.

    Parameters
    ----------
    mean
        ``(n,)`` or ``(*batch, n)``.  A batch of means lets every Monte Carlo
        run start from its own initial estimate.
    cov
        ``(n, n)`` covariance shared by the batch, or ``(*batch, n, n)``.
        A shared ``(n, n)`` matrix is checked for symmetry and positive
        definiteness; a batched one is checked with a batched Cholesky.

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite entries or a covariance that is not
        symmetric positive definite.
    """

    mean: np.ndarray
    cov: np.ndarray

    def __post_init__(self) -> None:
        mean = as_float_array("mean", self.mean)
        if mean.ndim == 0:
            mean = mean.reshape(1)
        n = mean.shape[-1]
        cov_in = np.asarray(self.cov, dtype=float)
        if cov_in.ndim <= 2:
            cov = as_covariance("cov", cov_in, n)
        else:
            cov = as_float_array("cov", cov_in)
            if cov.shape[-2:] != (n, n):
                raise ValueError(f"cov: expected trailing shape ({n}, {n}), got {cov.shape}")
            if not np.allclose(cov, np.swapaxes(cov, -1, -2), rtol=1e-9, atol=1e-12):
                raise ValueError("cov: covariance is not symmetric")
            try:
                np.linalg.cholesky(cov)
            except np.linalg.LinAlgError:
                raise ValueError("cov: covariance is not positive definite") from None
        try:
            np.broadcast_shapes(mean.shape[:-1], cov.shape[:-2])
        except ValueError:
            raise ValueError(f"mean batch {mean.shape[:-1]} and cov batch {cov.shape[:-2]} do not broadcast") from None
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", cov)

    @property
    def dim(self) -> int:
        """State dimension n."""
        return self.mean.shape[-1]

    def broadcast(self, batch: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``(*batch, n)`` and covariance ``(*batch, n, n)`` for a batch.

        The covariance stays a zero-stride broadcast view when it is shared,
        which lets the Kalman filter keep one Riccati recursion for all runs.
        """
        n = self.dim
        mean = np.broadcast_to(self.mean, (*batch, n)).copy()
        cov = np.broadcast_to(self.cov, (*batch, n, n))
        return mean, cov

    def sample(self, rng: RNGLike, size: tuple[int, ...] = ()) -> np.ndarray:
        """Draw ``(*size, *batch, n)`` samples; with RunStreams, ``size[0]`` is the run axis."""
        rng = as_rng(rng)
        L = np.linalg.cholesky(self.cov)
        batch = np.broadcast_shapes(self.mean.shape[:-1], self.cov.shape[:-2])
        shape = (*size, *batch, self.dim)
        if isinstance(rng, RunStreams) and len(shape) < 2:
            raise ValueError("sampling with RunStreams needs a leading run axis")
        xi = rng.standard_normal(shape)
        return self.mean + np.einsum("...ij,...j->...i", L, xi)
