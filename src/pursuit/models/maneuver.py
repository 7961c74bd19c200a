"""Maneuvering-target motion models: Singer, current statistical (CS), Jerk, constant turn.

Singer, CS and Jerk share one structure.  Per axis the state is a chain of
integrators ending in an exponentially correlated (first-order Markov)
component: the acceleration for Singer and CS (state ``[p, v, a]``), the
jerk for the Jerk model (state ``[p, v, a, j]``).  In continuous time the
last component obeys ``ċ = −α c + α c̄ + w`` with white noise ``w`` of
intensity ``2ασ²`` (so ``c`` has stationary variance σ²); Singer and Jerk
have ``c̄ = 0``, the CS model a "current" mean ``c̄ = ā``.  Sampled with
period T the model is ``x_k = F x_{k−1} + U c̄ + v``, ``v ~ N(0, 2ασ² q)``.

**Numerics.**  The closed forms of F, U and q in the literature cancel
catastrophically when x = αT is small (at α = 1e−3, T = 1 the textbook q11
is 13 % wrong; at 1e−4 it is negative).  Here everything is written through
the functions

    φ_p(z) = Σ_{m≥0} z^m / (m + p)!      (φ_0 = e^z, φ_{p+1}(z) = (φ_p(z) − 1/p!)/z)

at z = −x, which are positive for every x ≥ 0:

* F's last column is ``T^{p_i} φ_{p_i}(−x)`` with ``p_i = n − 1 − i``, the
  other columns the integrator chain ``T^{j−i}/(j−i)!``;
* the CS input is ``U_i = T^{p_i} x φ_{p_i+1}(−x)`` (so that F x + U a is
  exactly the constant-acceleration extrapolation);
* ``q_ij = ∫_0^T s^{p_i+p_j} φ_{p_i}(−αs) φ_{p_j}(−αs) ds`` is evaluated by
  its power series in x for x ≤ 1 (alternating with fast-decreasing terms,
  so accurate to a few ulps) and, for x > 1, from the series at T/2^s
  followed by s doublings ``q(2t) = q(t) + Φ(t) q(t) Φ(t)ᵀ``, ``Φ(2t) =
  Φ(t)²``.  Every entry of Φ and q is positive, so the doublings add
  positive terms only and keep full relative accuracy.

The tests check F, U and Q against numerical integration of the continuous
model and against the closed forms evaluated in high-precision decimal
arithmetic (60 digits for Singer and CS, 80 for the Jerk model), to 1e−10
relative for α from 1e−6 to 10 (and against the published Singer reference
values).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from math import factorial

import numpy as np

from .._linalg import psd_factor
from .._validation import nonnegative, positive, positive_int
from ..rng import RNGLike, as_rng

__all__ = [
    "exp_correlated_transition",
    "exp_correlated_noise",
    "exp_correlated_input",
    "singer_sigma2",
    "cs_variance",
    "Singer",
    "CurrentStatistical",
    "Jerk",
    "ConstantTurn",
    "CoordinatedTurn",
    "CS_VARIANCE_FACTOR",
]

CS_VARIANCE_FACTOR = (4.0 - np.pi) / np.pi
"""(4 − π)/π: variance of the modified Rayleigh density per squared distance to the limit."""

_PHI_SERIES_MAX = 2.0  # φ_p(−x) by its series up to here, by upward recurrence above
_PHI_TERMS = 40  # 2^40/40! ≈ 1e−36: the series is exact in double precision for x ≤ 2
_Q_SERIES_MAX = 1.0  # q by its series up to here, by doubling above
_Q_TERMS = 30  # for x ≤ 1 the terms fall below 2^30/30! ≈ 4e−24 of the first


# --------------------------------------------------------------------------
# the φ functions and the discretised exponentially correlated chain
# --------------------------------------------------------------------------
def _phi(p_max: int, x: np.ndarray) -> np.ndarray:
    """φ_p(−x) for p = 0..p_max: ``(*x.shape, p_max + 1)``; x ≥ 0."""
    x = np.asarray(x, dtype=float)
    out = np.empty((*x.shape, p_max + 1))
    small = x <= _PHI_SERIES_MAX
    xs = np.where(small, x, 0.0)
    for p in range(p_max + 1):
        acc = np.zeros_like(xs)
        for m in range(_PHI_TERMS - 1, -1, -1):  # Horner on Σ (−x)^m/(m+p)!
            acc = acc * (-xs) + 1.0 / factorial(m + p)
        out[..., p] = acc
    if not small.all():
        xl = np.where(small, 1.0, x)
        rec = np.exp(-xl)
        big = np.empty_like(out)
        big[..., 0] = rec
        for p in range(p_max):
            # 1/p! > φ_p(−x) > 0: a subtraction of positives that loses at
            # most a factor (p + 1) per step for x > 2.
            rec = (1.0 / factorial(p) - rec) / xl
            big[..., p + 1] = rec
        out = np.where(small[..., None], out, big)
    return out


def _lags(n: int) -> np.ndarray:
    """p_i = n − 1 − i: integrations between component i and the correlated one."""
    return np.arange(n - 1, -1, -1)


def exp_correlated_transition(n: int, alpha, dt: float) -> np.ndarray:
    """Transition matrix F of an n-state integrator chain ending in an exponentially correlated component.

    Parameters
    ----------
    n
        States per axis: 3 for Singer / CS ``[p, v, a]``, 4 for Jerk
        ``[p, v, a, j]``.
    alpha
        Maneuver frequency α ≥ 0 (1/s), a scalar or an array of any shape.
    dt
        Sampling period T > 0.

    Returns
    -------
    ``(*alpha.shape, n, n)``
    """
    alpha = np.asarray(alpha, dtype=float)
    T = float(dt)
    x = alpha * T
    phi = _phi(n - 1, x)
    F = np.zeros((*x.shape, n, n))
    lags = _lags(n)
    for i in range(n):
        for j in range(i, n - 1):
            F[..., i, j] = T ** (j - i) / factorial(j - i)
        F[..., i, n - 1] = T ** lags[i] * phi[..., lags[i]]
    return F


def exp_correlated_input(n: int, alpha, dt: float) -> np.ndarray:
    """Input vector U of the mean c̄ (the CS model's ā): ``(*alpha.shape, n)``.

    ``U_i = T^{p_i} x φ_{p_i+1}(−x)``; F x + U c equals the polynomial
    extrapolation of x with the last component held constant.
    """
    alpha = np.asarray(alpha, dtype=float)
    T = float(dt)
    x = alpha * T
    phi = _phi(n, x)
    lags = _lags(n)
    U = np.empty((*x.shape, n))
    for i in range(n):
        U[..., i] = T ** lags[i] * x * phi[..., lags[i] + 1]
    return U


@lru_cache(maxsize=8)
def _q_series_coefficients(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Power-series coefficients of q_ij / T^{E_ij} in x, highest power first, and exponents E."""
    lags = _lags(n)
    coef = np.zeros((_Q_TERMS, n, n))
    E = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            pi, pj = int(lags[i]), int(lags[j])
            P = pi + pj
            E[i, j] = P + 1
            for N in range(_Q_TERMS):
                c = sum(1.0 / (factorial(m + pi) * factorial(N - m + pj)) for m in range(N + 1))
                coef[_Q_TERMS - 1 - N, i, j] = (-1) ** N * c / (N + P + 1)
    coef.setflags(write=False)
    E.setflags(write=False)
    return coef, E


def _q_series(n: int, x: np.ndarray, T: np.ndarray) -> np.ndarray:
    coef, E = _q_series_coefficients(n)
    acc = np.zeros((*x.shape, n, n))
    xe = x[..., None, None]
    for c in coef:
        acc = acc * xe + c
    return acc * np.power(T[..., None, None], E)


def exp_correlated_noise(n: int, alpha, dt: float) -> np.ndarray:
    """Unit process-noise matrix q: the covariance is Q = 2ασ² q.

    ``q = ∫_0^T g(s) g(s)ᵀ ds`` with g the last column of Φ(s), computed
    without cancellation for every αT ≥ 0 (see the module docstring).

    Parameters
    ----------
    n, alpha, dt
        As :func:`exp_correlated_transition`.

    Returns
    -------
    ``(*alpha.shape, n, n)``, symmetric positive definite.
    """
    alpha = np.asarray(alpha, dtype=float)
    T = float(dt)
    x = alpha * T
    # Halve the interval s times until x/2^s ≤ 1 (per element; powers of two are exact).
    s = np.maximum(np.ceil(np.log2(np.maximum(x, 1e-300) / _Q_SERIES_MAX)), 0.0).astype(int)
    scale = np.ldexp(1.0, -s)
    t = T * scale
    q = _q_series(n, x * scale, t)
    s_max = int(s.max()) if s.size else 0
    if s_max:
        Phi = np.zeros_like(q)
        lags = _lags(n)
        phi = _phi(n - 1, x * scale)
        for i in range(n):
            for j in range(i, n - 1):
                Phi[..., i, j] = t ** (j - i) / factorial(j - i)
            Phi[..., i, n - 1] = t ** lags[i] * phi[..., lags[i]]
        for d in range(s_max):
            todo = (d < s)[..., None, None]
            q = np.where(todo, q + Phi @ q @ np.swapaxes(Phi, -1, -2), q)
            Phi = np.where(todo, Phi @ Phi, Phi)
    return 0.5 * (q + np.swapaxes(q, -1, -2))


def singer_sigma2(a_max: float, p_max: float = 0.0, p_zero: float = 0.0) -> float:
    """Singer's maneuver variance σ_m² = (A_max²/3)(1 + 4 P_max − P_0).

    Parameters
    ----------
    a_max
        Largest acceleration magnitude A_max (m/s²).
    p_max
        Probability of acceleration ±A_max.
    p_zero
        Probability of no acceleration.
    """
    a_max = positive("a_max", a_max)
    for name, v in (("p_max", p_max), ("p_zero", p_zero)):
        if not 0.0 <= v <= 1.0:
            raise ValueError(f"{name}: must lie in [0, 1], got {v!r}")
    if 2.0 * p_max + p_zero > 1.0:
        raise ValueError(f"p_max, p_zero: 2·p_max + p_zero must not exceed 1, got {2 * p_max + p_zero:g}")
    return a_max**2 / 3.0 * (1.0 + 4.0 * p_max - p_zero)


def cs_variance(a_mean: np.ndarray, a_max: float, a_neg_max: float | None = None) -> np.ndarray:
    """Acceleration variance of the current statistical model (Zhou Hongren).

    ``σ² = (4 − π)/π (a_max − ā)²`` for ā > 0, ``(4 − π)/π (a_−max + ā)²``
    for ā < 0 and ``(4 − π)/π a_max²`` at ā = 0.  ``a_max`` and
    ``a_neg_max`` are the magnitudes of the positive and negative limits
    (default symmetric).  The formula is applied as written when |ā|
    exceeds its limit (the variance then grows again).
    """
    a = np.asarray(a_mean, dtype=float)
    neg = a_max if a_neg_max is None else a_neg_max
    dist = np.where(a > 0, a_max - a, np.where(a < 0, neg + a, a_max))
    return CS_VARIANCE_FACTOR * dist * dist


# --------------------------------------------------------------------------
# linear per-axis models
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class _ChainAxes:
    """Shared layout and matrices of the per-axis exponentially correlated models."""

    alpha: float = 0.05
    sigma: float = 1.0
    ndim: int = 1
    dt: float = 1.0

    _per_axis = 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "alpha", positive("alpha", self.alpha))
        object.__setattr__(self, "sigma", nonnegative("sigma", self.sigma))
        positive_int("ndim", self.ndim)
        if self.ndim > 3:
            raise ValueError(f"ndim: must be 1, 2 or 3, got {self.ndim}")
        object.__setattr__(self, "dt", positive("dt", self.dt))

    # -- layout ----------------------------------------------------------------
    @property
    def dim(self) -> int:
        """State dimension: states per axis times ``ndim``."""
        return self._per_axis * self.ndim

    def _indices(self, d: int) -> tuple[int, ...]:
        return tuple(axis * self._per_axis + d for axis in range(self.ndim))

    @property
    def position_indices(self) -> tuple[int, ...]:
        """Indices of the positions (state ordered per axis)."""
        return self._indices(0)

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """Indices of the velocities."""
        return self._indices(1)

    @property
    def acceleration_indices(self) -> tuple[int, ...]:
        """Indices of the accelerations."""
        return self._indices(2)

    # -- matrices ----------------------------------------------------------------
    def _dt(self, dt: float | None) -> float:
        return float(self.dt if dt is None else dt)

    def _blocks(self, dt: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _chain_blocks(self._per_axis, self.ndim, self.alpha, self.sigma, self._dt(dt))

    def transition_matrix(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """F, ``(n, n)``, block diagonal over axes."""
        return self._blocks(dt)[0]

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Jacobian of ``f``: F."""
        return self._blocks(dt)[0]

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """``F x`` for a batch of states."""
        return np.einsum("ij,...j->...i", self._blocks(dt)[0], x)

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Process-noise covariance Q = 2ασ² q, ``(n, n)``."""
        return self._blocks(dt)[1]

    def noise_factor(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """G with ``G Gᵀ = Q``."""
        return self._blocks(dt)[2]

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """x_k ~ N(f(x), Q) for a batch of states (``rng`` may be RunStreams)."""
        _, _, G = self._blocks(dt)
        xi = as_rng(rng).standard_normal((*x.shape[:-1], G.shape[1]))
        return self.f(x, k, dt) + np.einsum("ij,...j->...i", G, xi)


@lru_cache(maxsize=256)
def _chain_blocks(per_axis: int, ndim: int, alpha: float, sigma: float, dt: float):
    Fa = exp_correlated_transition(per_axis, alpha, dt)
    Qa = 2.0 * alpha * sigma**2 * exp_correlated_noise(per_axis, alpha, dt)
    F = np.kron(np.eye(ndim), Fa)
    Q = np.kron(np.eye(ndim), Qa)
    G = psd_factor(Q) if sigma > 0 else np.zeros((F.shape[0], 0))
    for A in (F, Q, G):
        A.setflags(write=False)
    return F, Q, G


@dataclass(frozen=True)
class Singer(_ChainAxes):
    """Singer model: zero-mean exponentially correlated acceleration, per axis ``[p, v, a]``.

    Parameters
    ----------
    alpha
        Maneuver frequency α = 1/τ (1/s); τ ≈ 60 s for a lazy turn, 10-20 s
        for an evasive maneuver, 1 s for atmospheric turbulence.
    sigma
        Standard deviation σ_m of the acceleration (m/s²); see
        :func:`singer_sigma2` for Singer's rule.
    ndim
        Number of axes (1, 2 or 3); the state is ``[x, vx, ax, y, vy, ay, ...]``.
    dt
        Sampling period T (s).
    """


@dataclass(frozen=True)
class Jerk(_ChainAxes):
    """Jerk model (Mehrotra & Mahapatra): exponentially correlated jerk, per axis ``[p, v, a, j]``.

    Parameters
    ----------
    alpha
        Jerk correlation frequency α (1/s).
    sigma
        Standard deviation of the jerk (m/s³).
    ndim, dt
        As :class:`Singer`.
    """

    _per_axis = 4

    @property
    def jerk_indices(self) -> tuple[int, ...]:
        """Indices of the jerks."""
        return self._indices(3)


@dataclass(frozen=True)
class CurrentStatistical(_ChainAxes):
    """Current statistical (CS) model of Zhou Hongren, per axis ``[p, v, a]``.

    The acceleration is exponentially correlated about a "current" mean ā,
    taken as the current acceleration itself (the fixed point of "ā equals
    the predicted acceleration").  The noise-free transition is then
    ``F x + U ā``, which is exactly the constant-acceleration extrapolation,
    and the acceleration variance follows the modified Rayleigh density,
    :func:`cs_variance`, so the process noise depends on the state.

    Parameters
    ----------
    alpha
        Maneuver frequency α (1/s).
    a_max, a_neg_max
        Magnitudes of the positive and negative acceleration limits (m/s²);
        ``a_neg_max`` defaults to ``a_max``.
    ndim, dt
        As :class:`Singer`.

    Notes
    -----
    ``cov(k)`` is the nominal Q at ā = 0, for filters that need one fixed
    matrix; :meth:`process_cov` gives Q for given current accelerations, and
    :meth:`sample` draws with the state-dependent Q.  The adaptive filters in
    :mod:`pursuit.filters.cs` compute their own Q.
    """

    # the noise covariance depends on the state: no fixed factor G (the MH cuckoo moves check this)
    additive_gaussian = False

    a_max: float = 100.0
    a_neg_max: float | None = None
    sigma: float = field(init=False, default=0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "a_max", positive("a_max", self.a_max))
        if self.a_neg_max is not None:
            object.__setattr__(self, "a_neg_max", positive("a_neg_max", self.a_neg_max))
        object.__setattr__(self, "sigma", float(np.sqrt(cs_variance(0.0, self.a_max, self.a_neg_max))))
        super().__post_init__()

    def input_vector(self, dt: float | None = None) -> np.ndarray:
        """Per-axis input U of ā, ``(3,)``."""
        return exp_correlated_input(3, self.alpha, self._dt(dt))

    def _ca(self, dt: float | None) -> np.ndarray:
        T = self._dt(dt)
        return np.kron(np.eye(self.ndim), np.array([[1.0, T, T * T / 2], [0.0, 1.0, T], [0.0, 0.0, 1.0]]))

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """``F x + U ā`` with ā the current acceleration: the constant-acceleration extrapolation."""
        return np.einsum("ij,...j->...i", self._ca(dt), x)

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """∂(F x + U a)/∂x = F + U e_aᵀ, the constant-acceleration matrix."""
        return self._ca(dt)

    def transition_matrix(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """The linear map x ↦ F x + U ā (ā = a): the constant-acceleration matrix."""
        return self._ca(dt)

    def singer_transition(self, dt: float | None = None) -> np.ndarray:
        """The Singer part F (without the input term), ``(n, n)``; CS filters propagate P with it."""
        return self._blocks(dt)[0]

    def process_cov(self, accel: np.ndarray, dt: float | None = None) -> np.ndarray:
        """Q for current accelerations ``accel`` ``(*b, ndim)``: ``(*b, n, n)`` block diagonal."""
        accel = np.asarray(accel, dtype=float)
        s2 = cs_variance(accel, self.a_max, self.a_neg_max)  # (*b, ndim)
        q = exp_correlated_noise(3, self.alpha, self._dt(dt))
        blocks = 2.0 * self.alpha * s2[..., None, None] * q
        return _block_diag(blocks)

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Nominal Q at ā = 0 (σ² = (4 − π)/π a_max²)."""
        return self._blocks(dt)[1]

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """x_k ~ N(F x + U ā, Q(ā)) with ā the current acceleration of each state."""
        x = np.asarray(x, dtype=float)
        accel = x[..., list(self.acceleration_indices)]
        s = np.sqrt(2.0 * self.alpha * cs_variance(accel, self.a_max, self.a_neg_max))  # (*b, ndim)
        L = np.linalg.cholesky(exp_correlated_noise(3, self.alpha, self._dt(dt)))
        xi = as_rng(rng).standard_normal((*x.shape[:-1], self.ndim, 3))
        noise = s[..., None] * np.einsum("ij,...j->...i", L, xi)
        return self.f(x, k, dt) + noise.reshape(x.shape)


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    """``(*b, A, d, d)`` blocks to a ``(*b, A·d, A·d)`` block-diagonal matrix."""
    *b, A, d, _ = blocks.shape
    out = np.zeros((*b, A * d, A * d))
    for a in range(A):
        out[..., a * d : (a + 1) * d, a * d : (a + 1) * d] = blocks[..., a, :, :]
    return out


# --------------------------------------------------------------------------
# constant turn
# --------------------------------------------------------------------------
_TRIG_SERIES_MAX = 0.5
_TRIG_TERMS = 9  # 0.5^18/19! ≈ 3e−23


def _turn_functions(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """S = sin u/u, C = (1 − cos u)/u and their derivatives S', C' in u, stable at u = 0."""
    u = np.asarray(u, dtype=float)
    small = np.abs(u) <= _TRIG_SERIES_MAX
    us = np.where(small, u, 0.0)
    u2 = us * us
    S = np.zeros_like(us)
    C = np.zeros_like(us)
    dS = np.zeros_like(us)
    dC = np.zeros_like(us)
    for kk in range(_TRIG_TERMS - 1, -1, -1):
        sgn = -1.0 if kk % 2 else 1.0
        S = S * u2 + sgn / factorial(2 * kk + 1)
        C = C * u2 + sgn / factorial(2 * kk + 2)
        dC = dC * u2 + sgn * (2 * kk + 1) / factorial(2 * kk + 2)
        if kk >= 1:
            dS = dS * u2 + sgn * 2 * kk / factorial(2 * kk + 1)
    C = C * us  # Σ (−1)^k u^{2k+1}/(2k+2)!
    dS = dS * us  # Σ_{k≥1} (−1)^k 2k u^{2k−1}/(2k+1)!
    if small.all():
        return S, C, dS, dC
    ul = np.where(small, 1.0, u)
    sn, cs = np.sin(ul), np.cos(ul)
    S_l = sn / ul
    C_l = (1.0 - cs) / ul
    dS_l = (ul * cs - sn) / (ul * ul)
    dC_l = (ul * sn - (1.0 - cs)) / (ul * ul)
    return (
        np.where(small, S, S_l),
        np.where(small, C, C_l),
        np.where(small, dS, dS_l),
        np.where(small, dC, dC_l),
    )


def _turn_block(omega: np.ndarray, T: float) -> np.ndarray:
    """The ``[x, vx, y, vy]`` transition of a constant turn at rate ω: ``(*ω.shape, 4, 4)``."""
    omega = np.asarray(omega, dtype=float)
    u = omega * T
    S, C, _, _ = _turn_functions(u)
    c, s = np.cos(u), np.sin(u)
    F = np.zeros((*u.shape, 4, 4))
    F[..., 0, 0] = 1.0
    F[..., 0, 1] = T * S
    F[..., 0, 3] = -T * C
    F[..., 1, 1] = c
    F[..., 1, 3] = -s
    F[..., 2, 1] = T * C
    F[..., 2, 2] = 1.0
    F[..., 2, 3] = T * S
    F[..., 3, 1] = s
    F[..., 3, 3] = c
    return F


def _dwna(T: float, q: float) -> np.ndarray:
    """Discrete white-noise acceleration Q for one ``[p, v]`` axis."""
    G = np.array([T * T / 2.0, T])
    return q * np.outer(G, G)


@dataclass(frozen=True)
class ConstantTurn:
    """Constant turn at a known rate ω in the x-y plane, with an optional constant-velocity z axis.

    State ``[x, vx, y, vy]`` (``ndim=2``) or ``[x, vx, y, vy, z, vz]``
    (``ndim=3``).  The velocity rotates by ωT each step; ω > 0 turns
    counter-clockwise.  The process noise is the discrete white-noise
    acceleration of :class:`pursuit.models.ConstantVelocity` on every axis.
    ω = 0 gives exactly the constant-velocity model.

    Parameters
    ----------
    omega
        Turn rate (rad/s).
    q
        Acceleration noise variance ((m/s²)²).
    ndim
        2 or 3.
    dt
        Sampling period (s).
    """

    omega: float = 0.0
    q: float = 1.0
    ndim: int = 2
    dt: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.omega, bool) or not np.isfinite(float(self.omega)):
            raise ValueError(f"omega: must be a finite number, got {self.omega!r}")
        object.__setattr__(self, "omega", float(self.omega))
        object.__setattr__(self, "q", nonnegative("q", self.q))
        if self.ndim not in (2, 3):
            raise ValueError(f"ndim: must be 2 or 3, got {self.ndim!r}")
        object.__setattr__(self, "dt", positive("dt", self.dt))

    @property
    def dim(self) -> int:
        """State dimension (4 or 6)."""
        return 2 * self.ndim

    position_indices = property(lambda self: (0, 2, 4)[: self.ndim], doc="Indices of the positions.")
    velocity_indices = property(lambda self: (1, 3, 5)[: self.ndim], doc="Indices of the velocities.")

    def _mats(self, dt):
        return _turn_matrices(self.omega, self.q, self.ndim, float(self.dt if dt is None else dt))

    def transition_matrix(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """F, ``(n, n)``."""
        return self._mats(dt)[0]

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """F."""
        return self._mats(dt)[0]

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """``F x`` for a batch of states."""
        return np.einsum("ij,...j->...i", self._mats(dt)[0], x)

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Q, ``(n, n)``."""
        return self._mats(dt)[1]

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """x_k ~ N(F x, Q)."""
        F, _, G = self._mats(dt)
        xi = as_rng(rng).standard_normal((*x.shape[:-1], G.shape[1]))
        return np.einsum("ij,...j->...i", F, x) + np.einsum("ij,...j->...i", G, xi)


@lru_cache(maxsize=128)
def _turn_matrices(omega: float, q: float, ndim: int, dt: float):
    n = 2 * ndim
    F = np.eye(n)
    F[:4, :4] = _turn_block(omega, dt)
    Q = np.kron(np.eye(ndim), _dwna(dt, q))
    if ndim == 3:
        F[4, 5] = dt
    G = psd_factor(Q) if q > 0 else np.zeros((n, 0))
    for A in (F, Q, G):
        A.setflags(write=False)
    return F, Q, G


@dataclass(frozen=True)
class CoordinatedTurn:
    """Nearly coordinated turn with the turn rate in the state (for the EKF, UKF, CKF).

    State ``[x, vx, y, vy, ω]``, or ``[x, vx, y, vy, z, vz, ω]`` with
    ``ndim=3`` (z at constant velocity).  The position and velocity follow
    :class:`ConstantTurn` at the current ω; ω is a random walk.  The
    transition and its analytic Jacobian are smooth through ω = 0 (series
    for small ωT).

    Parameters
    ----------
    q
        Acceleration noise variance ((m/s²)²), discrete white noise per axis.
    q_omega
        Turn-rate noise: ω_k = ω_{k−1} + w, var(w) = q_omega·T² ((rad/s²)²).
    ndim
        2 or 3.
    dt
        Sampling period (s).
    """

    q: float = 1.0
    q_omega: float = 1e-4
    ndim: int = 2
    dt: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", nonnegative("q", self.q))
        object.__setattr__(self, "q_omega", nonnegative("q_omega", self.q_omega))
        if self.ndim not in (2, 3):
            raise ValueError(f"ndim: must be 2 or 3, got {self.ndim!r}")
        object.__setattr__(self, "dt", positive("dt", self.dt))

    @property
    def dim(self) -> int:
        """State dimension (5 or 7)."""
        return 2 * self.ndim + 1

    position_indices = property(lambda self: (0, 2, 4)[: self.ndim], doc="Indices of the positions.")
    velocity_indices = property(lambda self: (1, 3, 5)[: self.ndim], doc="Indices of the velocities.")

    @property
    def turn_rate_index(self) -> int:
        """Index of ω."""
        return 2 * self.ndim

    def _T(self, dt):
        return float(self.dt if dt is None else dt)

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Turn each state's velocity by its own ω·T and move it accordingly."""
        x = np.asarray(x, dtype=float)
        T = self._T(dt)
        w = x[..., self.turn_rate_index]
        S, C, _, _ = _turn_functions(w * T)
        c, s = np.cos(w * T), np.sin(w * T)
        vx, vy = x[..., 1], x[..., 3]
        out = x.copy()
        out[..., 0] = x[..., 0] + T * (S * vx - C * vy)
        out[..., 1] = c * vx - s * vy
        out[..., 2] = x[..., 2] + T * (C * vx + S * vy)
        out[..., 3] = s * vx + c * vy
        if self.ndim == 3:
            out[..., 4] = x[..., 4] + T * x[..., 5]
        return out

    def jacobian(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Analytic ∂f/∂x, ``(*b, n, n)``."""
        x = np.asarray(x, dtype=float)
        T = self._T(dt)
        w = x[..., self.turn_rate_index]
        u = w * T
        S, C, dS, dC = _turn_functions(u)
        c, s = np.cos(u), np.sin(u)
        vx, vy = x[..., 1], x[..., 3]
        n, iw = self.dim, self.turn_rate_index
        J = np.zeros((*x.shape[:-1], n, n))
        J[..., :4, :4] = _turn_block(w, T)
        if self.ndim == 3:
            J[..., 4, 4] = 1.0
            J[..., 4, 5] = T
            J[..., 5, 5] = 1.0
        J[..., iw, iw] = 1.0
        # d/dω of T·S(ωT) is T²·S'(u), and likewise for C, cos and sin.
        J[..., 0, iw] = T * T * (dS * vx - dC * vy)
        J[..., 1, iw] = -T * (s * vx + c * vy)
        J[..., 2, iw] = T * T * (dC * vx + dS * vy)
        J[..., 3, iw] = T * (c * vx - s * vy)
        return J

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Q, ``(n, n)``: DWNA per axis and q_omega·T² for ω."""
        return _coordinated_turn_cov(self.q, self.q_omega, self.ndim, self._T(dt))[0]

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """x_k ~ N(f(x), Q)."""
        _, G = _coordinated_turn_cov(self.q, self.q_omega, self.ndim, self._T(dt))
        xi = as_rng(rng).standard_normal((*np.shape(x)[:-1], G.shape[1]))
        return self.f(x, k, dt) + np.einsum("ij,...j->...i", G, xi)


@lru_cache(maxsize=128)
def _coordinated_turn_cov(q: float, q_omega: float, ndim: int, dt: float):
    n = 2 * ndim + 1
    Q = np.zeros((n, n))
    Q[: 2 * ndim, : 2 * ndim] = np.kron(np.eye(ndim), _dwna(dt, q))
    Q[-1, -1] = q_omega * dt * dt
    G = psd_factor(Q) if Q.any() else np.zeros((n, 0))
    for A in (Q, G):
        A.setflags(write=False)
    return Q, G
