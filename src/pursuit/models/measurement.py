"""Measurement (sensor) models.

A measurement model is any object with

* ``dim``: measurement dimension m;
* ``h(x, k)``: noise-free measurement, ``(*b, n) -> (*b, m)``;
* ``jacobian(x, k)``: ``(*b, m, n)`` or a shared ``(m, n)`` (optional:
  filters fall back to a numerical Jacobian);
* ``cov(k)``: measurement-noise covariance R, ``(m, m)``;
* ``loglik(z, x, k)``: log p(z | x), with z broadcasting against ``h(x)``;
* ``sample(x, k, rng)``: a noisy measurement of a batch of states;
* optionally ``residual(a, b)``: ``a - b`` with any angle wrapped, used for
  innovations and sigma-point spreads.

Linear models also give ``matrix(k)`` (H), which the plain Kalman filter
requires.  A NaN entry of z means that component was not measured.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .._linalg import apply_matrix
from .._validation import as_covariance, as_matrix, as_vector, positive, positive_int
from ..rng import RNGLike, as_rng

__all__ = [
    "LinearGaussian",
    "RangeSensors",
    "RangeBearing",
    "TimeOfArrival",
    "gaussian_loglik",
    "wrap_angle",
]

_LOG_2PI = float(np.log(2.0 * np.pi))


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles to [-pi, pi)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def measured_somewhere(valid: np.ndarray) -> np.ndarray | None:
    """The components some run measured, or None when that is all of them or none.

    ``valid`` is ``(*batch, m)``: which components each run measured.  A
    component no run measured adds exactly nothing to any particle's
    log-likelihood (:func:`gaussian_loglik` adds a row with a missing
    component in order, the missing one as +0.0), so the particle filters
    leave it out before their per-particle arithmetic (and sum the rest
    ``in_order``): a WSN of 16 nodes of which 3-5 range the target then works
    on a handful of components, with the bits of all 16, whatever the other
    runs of the chunk measured.  None asks for the full width: nothing to
    leave out, or nothing left.
    """
    m = valid.shape[-1]
    if m == 0:
        return None
    somewhere = valid.reshape(-1, m).any(axis=0)
    count = int(np.count_nonzero(somewhere))
    if count == m or count == 0:
        return None
    return np.flatnonzero(somewhere)


def gaussian_loglik(residual: np.ndarray, R: np.ndarray, *, in_order: bool = False) -> np.ndarray:
    """log N(residual; 0, R) over the last axis, NaN components left out.

    Missing (NaN) components are marginalised out exactly when R is
    diagonal.  With a full R, a residual containing NaN raises ``ValueError``.

    A row with a missing component adds its components' terms in order, the
    missing ones as +0.0, so it has the bits of leaving those components
    out; ``in_order=True`` sums every row so (what a row gets that is
    computed without its missing components: the particle filters leave out
    the components no run measured).  A complete row otherwise gets NumPy's
    sum, whose association depends on the number of components.
    """
    residual = np.asarray(residual)
    if residual.dtype.kind not in "fc":  # integers, booleans, objects; float32 is squared as float32, as it always was
        residual = residual.astype(float)
    diag = np.diag(R)
    if np.count_nonzero(R - np.diag(diag)) == 0:
        norm = np.log(diag) + _LOG_2PI
        # r²/σ² + log(2π σ²) per component, in place where the layout allows (particle filters call
        # this on (runs, N, m) arrays every step); then, only where a row's sum is NaN, each
        # missing (NaN) component's term is replaced by the one a zero residual gives, 0/σ² + 0, so
        # the result is that of masking the missing components first, bit for bit
        terms = np.multiply(residual, residual)
        if terms.dtype == np.float64 and terms.shape[-1:] == diag.shape:
            terms /= diag
        else:  # float32 or complex squares, or a residual broadcast against R
            terms = terms / diag
        terms += norm
        total = terms.sum(axis=-1)  # the complete rows' sum, and a cheap test for a missing component
        incomplete = None
        if np.isnan(total).any():
            missing = np.broadcast_to(np.isnan(residual), terms.shape)
            if missing.any():
                zero_terms = 0.0 / diag + 0.0
                if not zero_terms.any():  # every σ² positive: a missing component adds exactly +0.0
                    np.putmask(terms, missing, 0.0)  # a boolean-indexed store costs 5x more here
                else:
                    np.copyto(terms, np.broadcast_to(zero_terms, terms.shape), where=missing)
                incomplete = missing.any(axis=-1)
        if in_order:  # one in-order sum, after the missing terms are zeroed
            total = _sum_in_order(terms)
        elif incomplete is not None:
            total = np.where(incomplete, _sum_in_order(terms), total)
        return -0.5 * total
    if np.isnan(residual).any():
        raise ValueError("missing measurement components need a diagonal measurement covariance")
    L = np.linalg.cholesky(R)
    y = np.linalg.solve(L, np.moveaxis(residual, -1, 0).reshape(R.shape[0], -1))
    maha = np.sum(y * y, axis=0).reshape(residual.shape[:-1])
    logdet = 2.0 * np.sum(np.log(np.diag(L)))
    return -0.5 * (maha + logdet + R.shape[0] * _LOG_2PI)


def _sum_in_order(terms: np.ndarray) -> np.ndarray:
    """Σ_j terms[..., j] added left to right, ((t₀ + t₁) + t₂) + ...

    In this order a term of exactly +0.0 changes no bit of the sum, so a
    missing component (its term zeroed) gives the bits of leaving it out:
    what :func:`measured_somewhere` relies on.  NumPy's ``sum`` associates by
    the length of the axis (pairwise, eight accumulators).  The compiled
    kernels add in this order too.
    """
    if terms.shape[-1] == 0:
        return np.zeros(terms.shape[:-1], dtype=terms.dtype)
    total = 0.0 + terms[..., 0]  # a copy; 0.0 + t is t, as the compiled kernels' accumulator starts
    for j in range(1, terms.shape[-1]):  # over the measurement's components, a handful
        total += terms[..., j]
    return total


class _GaussianNoise:
    """Shared ``cov``, ``loglik`` and ``sample`` for additive Gaussian noise."""

    R: np.ndarray

    def cov(self, k: int | None = None) -> np.ndarray:
        """Measurement-noise covariance R, ``(m, m)``."""
        return self.R

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Difference of two measurements, ``a - b``."""
        return a - b

    def loglik(self, z: np.ndarray, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """log p(z | x); z broadcasts against ``h(x)``, NaN entries are skipped."""
        return gaussian_loglik(self.residual(z, self.h(x, k)), self.R)

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike) -> np.ndarray:
        """Noisy measurement of a batch of states (``rng`` may be RunStreams)."""
        zp = self.h(x, k)
        xi = as_rng(rng).standard_normal(zp.shape)
        return zp + apply_matrix(self._chol_R, xi)

    def _set_noise(self, R: np.ndarray) -> None:
        _freeze(self, "R", R)
        _freeze(self, "_chol_R", np.linalg.cholesky(R))

    def __setstate__(self, state: dict) -> None:
        # pickle gives writable arrays back: freeze them again, as construction did (filters cache R on that)
        for name, value in state.items():
            if isinstance(value, np.ndarray):
                value = value.copy()  # its own dtype: index arrays stay integers
                value.setflags(write=False)
            object.__setattr__(self, name, value)


def _freeze(obj, name: str, arr: np.ndarray) -> None:
    arr = np.array(arr, dtype=float)
    arr.setflags(write=False)
    object.__setattr__(obj, name, arr)


@dataclass(frozen=True, eq=False)
class LinearGaussian(_GaussianNoise):
    """Linear measurement z = H x + v, v ~ N(0, R).

    Parameters
    ----------
    H
        ``(m, n)`` measurement matrix.
    R
        Measurement-noise covariance: ``(m, m)``, a vector of variances, or a
        scalar variance.
    """

    H: np.ndarray
    R: np.ndarray

    def __post_init__(self) -> None:
        H = as_matrix("H", self.H)
        _freeze(self, "H", H)
        self._set_noise(as_covariance("R", self.R, H.shape[0]))

    @classmethod
    def position(cls, state_dim: int, position_indices: Sequence[int], sigma: float | Sequence[float]) -> "LinearGaussian":
        """Measure the given position components with standard deviation ``sigma`` (one value or one per component).

        Raises
        ------
        ValueError
            If ``sigma`` is not positive and finite or has the wrong length, or an index lies outside the state.
        """
        idx = list(position_indices)
        n = positive_int("state_dim", state_dim)
        for i in idx:
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < n:
                raise ValueError(f"position_indices: expected indices in [0, {n}), got {i!r}")
        sig = as_vector("sigma", sigma)
        if sig.shape[0] not in (1, len(idx)):
            raise ValueError(f"sigma: expected 1 or {len(idx)} values, got {sig.shape[0]}")
        for s in sig:
            positive("sigma", s)
        H = np.zeros((len(idx), n))
        H[np.arange(len(idx)), idx] = 1.0
        sig = np.broadcast_to(sig, (len(idx),))
        return cls(H, np.diag(sig**2))

    @property
    def dim(self) -> int:
        """Measurement dimension m."""
        return self.H.shape[0]

    def matrix(self, k: int | None = None) -> np.ndarray:
        """Measurement matrix H, ``(m, n)``."""
        return self.H

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``H x`` for a batch of states."""
        return apply_matrix(self.H, x)

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None) -> np.ndarray:
        """The shared matrix H."""
        return self.H


def _positions(x: np.ndarray, idx: tuple[int, ...]) -> np.ndarray:
    return x[..., list(idx)]


@dataclass(frozen=True, eq=False)
class RangeSensors(_GaussianNoise):
    """Ranges from a target to fixed anchors: z_i = ||p - a_i|| + v_i.

    Parameters
    ----------
    anchors
        ``(s, d)`` anchor positions (d = 1, 2 or 3 spatial axes).
    sigma
        Range noise standard deviation in metres, one value or one per anchor.
    position_indices
        Indices of the d position components in the state; default
        ``(0, 2)`` for the 2-D constant-velocity layout ``[x, vx, y, vy]``.
    """

    anchors: np.ndarray
    sigma: float | np.ndarray
    position_indices: tuple[int, ...] = (0, 2)
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        anchors = np.array(self.anchors, dtype=float)
        if anchors.ndim == 1:
            anchors = anchors[None, :]
        anchors = as_matrix("anchors", anchors)
        idx = tuple(int(i) for i in self.position_indices)
        if anchors.shape[1] != len(idx):
            raise ValueError(
                f"anchors: have {anchors.shape[1]} coordinates but position_indices names {len(idx)} components"
            )
        sig = as_vector("sigma", self.sigma)
        if sig.shape[0] not in (1, anchors.shape[0]):
            raise ValueError(f"sigma: expected 1 or {anchors.shape[0]} values, got {sig.shape[0]}")
        for s in sig:
            positive("sigma", s)
        _freeze(self, "anchors", anchors)
        object.__setattr__(self, "position_indices", idx)
        self._set_noise(np.diag(np.broadcast_to(sig, (anchors.shape[0],)) ** 2))

    @property
    def dim(self) -> int:
        """Number of anchors."""
        return self.anchors.shape[0]

    def _deltas(self, x: np.ndarray, cols: np.ndarray | slice = slice(None)) -> np.ndarray:
        return _positions(x, self.position_indices)[..., None, :] - self.anchors[cols]  # (*b, s, d)

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Ranges to every anchor, ``(*b, s)``."""
        return self._ranges(x, slice(None))

    def h_components(self, x: np.ndarray, k: int | None, cols: np.ndarray | slice) -> np.ndarray:
        """Ranges to the anchors ``cols`` only: ``h(x, k)[..., cols]``, the same bits.

        The particle filters' cuckoo searches measure every moved particle
        against the nodes some run heard; a 16-node grid hears 3-5.
        """
        return self._ranges(x, cols)

    def _ranges(self, x: np.ndarray, cols: np.ndarray | slice) -> np.ndarray:
        d = self._deltas(x, cols)
        return np.sqrt(np.einsum("...i,...i->...", d, d))

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, s, n)``: unit vectors from each anchor, zero at an anchor."""
        d = self._deltas(x)
        r = np.sqrt(np.einsum("...i,...i->...", d, d))[..., None]
        u = np.divide(d, r, out=np.zeros_like(d), where=r > 0)
        J = np.zeros((*x.shape[:-1], self.dim, x.shape[-1]))
        J[..., list(self.position_indices)] = u
        return J


@dataclass(frozen=True, eq=False)
class TimeOfArrival(RangeSensors):
    """One-way acoustic travel times to fixed anchors: z_i = ||p - a_i|| / c + v_i.

    Parameters
    ----------
    anchors
        ``(s, d)`` hydrophone positions.
    sigma
        Travel-time noise standard deviation in seconds (``sigma_t``).
    c
        Signal speed in m/s (1500 for sound in water).
    position_indices
        As in :class:`RangeSensors`.
    """

    c: float = 1500.0

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "c", positive("c", self.c))

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Travel times to every anchor, ``(*b, s)``."""
        return super().h(x, k) / self.c

    def h_components(self, x: np.ndarray, k: int | None, cols: np.ndarray | slice) -> np.ndarray:
        """Travel times to the anchors ``cols`` only: ``h(x, k)[..., cols]``, the same bits."""
        return self._ranges(x, cols) / self.c

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, s, n)``: range Jacobian divided by c."""
        return super().jacobian(x, k) / self.c


@dataclass(frozen=True, eq=False)
class RangeBearing(_GaussianNoise):
    """Range and bearing from one 2-D sensor: z = [||p - s||, atan2(dy, dx)].

    Bearings are in radians, measured from the x axis; innovations are
    wrapped to [-pi, pi).

    Parameters
    ----------
    sensor
        ``(2,)`` sensor position.
    sigma_range, sigma_bearing
        Noise standard deviations (m, rad).
    position_indices
        Indices of (x, y) in the state; default ``(0, 2)``.
    """

    sensor: np.ndarray
    sigma_range: float
    sigma_bearing: float
    position_indices: tuple[int, ...] = (0, 2)
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        _freeze(self, "sensor", as_vector("sensor", self.sensor, 2))
        sr = positive("sigma_range", self.sigma_range)
        sb = positive("sigma_bearing", self.sigma_bearing)
        idx = tuple(int(i) for i in self.position_indices)
        if len(idx) != 2:
            raise ValueError("position_indices: range-bearing needs exactly two position components")
        object.__setattr__(self, "position_indices", idx)
        self._set_noise(np.diag([sr**2, sb**2]))

    @property
    def dim(self) -> int:
        """Measurement dimension (2)."""
        return 2

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, 2)``: range and bearing."""
        d = _positions(x, self.position_indices) - self.sensor
        return np.stack([np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 1], d[..., 0])], axis=-1)

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a - b`` with the bearing difference wrapped to [-pi, pi)."""
        r = a - b
        return np.concatenate([r[..., :1], wrap_angle(r[..., 1:])], axis=-1)

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, 2, n)`` analytic Jacobian."""
        d = _positions(x, self.position_indices) - self.sensor
        r2 = d[..., 0] ** 2 + d[..., 1] ** 2
        r = np.sqrt(r2)
        J = np.zeros((*x.shape[:-1], 2, x.shape[-1]))
        ix, iy = self.position_indices
        with np.errstate(divide="ignore", invalid="ignore"):
            J[..., 0, ix] = np.where(r > 0, d[..., 0] / r, 0.0)
            J[..., 0, iy] = np.where(r > 0, d[..., 1] / r, 0.0)
            J[..., 1, ix] = np.where(r2 > 0, -d[..., 1] / r2, 0.0)
            J[..., 1, iy] = np.where(r2 > 0, d[..., 0] / r2, 0.0)
        return J
