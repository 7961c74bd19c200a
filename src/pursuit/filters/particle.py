"""Particle filters: the shared particle state and the bootstrap (SIR) filter.

A particle filter's state holds ``(*batch, N, n)`` particles with
``(*batch, N)`` normalised log-weights, for a whole batch of Monte Carlo
runs at once; every operation is vectorised over runs and particles.  The
state's ``mean`` and ``cov`` are the weighted mean and covariance of the
particles of the step *before* resampling (what paper P1 and the patent P3
report as the estimate); ``particles`` and ``logw`` are the set after it.

Step info
---------
Every particle filter returns the standard info keys with the same meaning as
the Gaussian filters (:mod:`pursuit.filters.gaussian`), defined from the
particles as follows.  Let ω_i be the normalised *predictive* weights under
which the propagated particles x_{k,i} represent p(x_k | z_{1:k−1}): for the
bootstrap filter ω_i = w_{k−1,i}; for a filter with proposal q (the partial
UPF) ω_i ∝ w_{k−1,i} p(x_{k,i} | x_{k−1,i}) / q(x_{k,i}).

``innovation`` (*b, m)
    ν = z − ẑ with ẑ = Σ ω_i h(x_{k,i}), the predictive mean of the
    measurement (averaged on the circle for angle components); NaN where a
    component is missing.
``S`` (*b, m, m)
    Σ ω_i (h_i − ẑ)(h_i − ẑ)ᵀ + R: the particle spread of h(x) plus the
    measurement noise, the predictive covariance of z.  Missing components
    are decoupled with unit variance, as in the Gaussian filters.
``nis``, ``dof``
    νᵀS⁻¹ν over the measured components (NaN when nothing is measured, and
    when S is not finite or singular, as in a diverged filter) and the
    number of measured components.
``loglik`` (*b,)
    log Σ_i w_{k−1,i} α_i, with α_i the incremental importance weight (for
    the bootstrap filter α_i = p(z_k | x_{k,i}) with the measurement model's
    full normalising constant): the particle estimate of the marginal
    likelihood increment log p(z_k | z_{1:k−1}).  Its exponential is an
    unbiased estimate.  It is *not* log N(ν; 0, S); the two agree on
    linear-Gaussian models as N grows.  0 when nothing is measured, −inf
    when every particle has zero likelihood (see below).
``ess`` (*b,)
    Effective sample size 1 / Σ w_i² of the weights before resampling.
``resampled`` (*b,)
    Whether the run resampled in this step.
``weights_reset`` (*b,)
    True where every particle's likelihood was zero or NaN (all log-weights
    −inf): the recovery rule then keeps the predictive weights (as if the
    measurement had been missing), so the estimate is the predictive mean,
    never NaN.  A NaN likelihood of a single particle counts as zero.

A measurement that is NaN in every component means predict only: particles
are propagated and the weights are left unchanged (and not resampled).

Randomness
----------
Every draw goes through the ``rng`` given to ``init`` (kept in the state):
a Generator, or :class:`pursuit.RunStreams` with one stream per run.  Each
run draws the same numbers in the same order whatever batch it is computed
in: where only some runs need a draw (ESS-triggered resampling), only their
streams are used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from .._linalg import inv_spd, quad, symmetrize
from .._validation import in_range, measurement_for_step, model_dim, positive_int, prior_of_size, time_step
from ..gaussian import Gaussian
from ..models.measurement import _GaussianNoise, gaussian_loglik, measured_somewhere
from ..rng import RNGLike, RunStreams, as_rng
from .base import FilterBase, prior_batch
from .resample import get_resampler, repeat_particles
from .workspace import Workspace, scratch

__all__ = [
    "ParticleState",
    "ParticleFilterBase",
    "Weighed",
    "BootstrapParticleFilter",
    "SIR",
    "weighted_moments",
    "rows_rng",
    "propagate_particles",
]

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class ParticleState:
    """State of a particle filter for a batch of runs.

    Attributes
    ----------
    particles
        ``(*batch, N, n)`` particles after the step (after resampling).
    logw
        ``(*batch, N)`` normalised log-weights of ``particles``.
    mean, cov
        ``(*batch, n)`` and ``(*batch, n, n)`` weighted mean and covariance
        of the step's particles before resampling: the filter's estimate.
    rng
        The random streams every draw comes from.
    k
        Index of the last step processed (0 for the prior).
    uniform
        True when every weight is exactly 1/N (all runs resampled, or the
        prior); lets the next step skip the weight arithmetic.
    particle_cov
        ``(*batch, N, n, n)`` per-particle covariances (unscented PF only).
    memory
        Filter-specific memory.
    work
        Scratch buffers reused by the next step (see
        :mod:`pursuit.filters.workspace`).
    """

    particles: np.ndarray
    logw: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    rng: Any = field(repr=False, default=None)
    k: int = 0
    uniform: bool = False
    particle_cov: np.ndarray | None = None
    memory: Any = None
    work: Workspace = field(default_factory=Workspace, repr=False, compare=False)

    @property
    def batch(self) -> tuple[int, ...]:
        """Batch shape."""
        return self.mean.shape[:-1]

    @property
    def n_particles(self) -> int:
        """Number of particles N per run."""
        return self.particles.shape[-2]

    @property
    def weights(self) -> np.ndarray:
        """``(*batch, N)`` normalised weights."""
        return np.exp(self.logw)


# --------------------------------------------------------------------------
# helpers shared by all particle filters
# --------------------------------------------------------------------------
def rows_rng(rng: np.random.Generator | RunStreams, rows: np.ndarray) -> np.random.Generator | RunStreams:
    """The streams of the given leading-axis rows (a Generator is returned as is)."""
    if isinstance(rng, RunStreams):
        return RunStreams([rng.generators[i] for i in rows])
    return rng


def weighted_moments(
    X: np.ndarray, e: np.ndarray, s: np.ndarray | None = None, work: Workspace | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(*b, n)`` and covariance ``(*b, n, n)`` of particles ``(*b, N, n)``.

    ``e`` are non-negative weights ``(*b, N)`` with row sums ``s`` (computed
    when not given).  Particles with zero weight never contribute, even if
    they are not finite.  ``work`` holds the scratch arrays.
    """
    if s is None:
        s = e.sum(axis=-1)
    inv = 1.0 / s
    mean = np.einsum("...p,...pi->...i", e, X) * inv[..., None]
    if not np.all(np.isfinite(mean)):  # a NaN or infinite particle of zero weight
        X = np.where(e[..., None] > 0, X, 0.0)
        mean = np.einsum("...p,...pi->...i", e, X) * inv[..., None]
    d = np.subtract(X, mean[..., None, :], out=scratch(work, "moments.d", X.shape))
    if X.shape[-1] == 1:
        d0 = d[..., 0]
        np.square(d0, out=d0)
        cov = (np.einsum("...p,...p->...", e, d0) * inv)[..., None, None]
    else:
        de = np.multiply(d, e[..., None], out=scratch(work, "moments.de", X.shape))
        # one GEMM per run (batch-invariant); the einsum "...pi,...pj->...ij" cost ~20x more on (100, 200, 4)
        cov = symmetrize((np.swapaxes(de, -1, -2) @ d) * inv[..., None, None])
    return mean, cov


def _safe_inverse(S: np.ndarray) -> np.ndarray:
    """Inverse of a stack of innovation covariances; NaN where one is not finite or singular.

    A diverged filter (particles at astronomically large values) can produce
    an infinite or singular S; its NIS is then NaN rather than an exception.
    """
    ok = np.all(np.isfinite(S), axis=(-2, -1))
    if ok.all():
        try:
            return inv_spd(S)
        except np.linalg.LinAlgError:
            pass
    m = S.shape[-1]
    Sf = np.where(ok[..., None, None], S, np.eye(m))
    with np.errstate(all="ignore"):
        inv = np.linalg.pinv(Sf)
        det = np.linalg.det(Sf)
    bad = ~ok | ~(np.abs(det) > 0) | ~np.all(np.isfinite(inv), axis=(-2, -1))
    return np.where(bad[..., None, None], np.nan, inv)


def _prepare_measurement(z: np.ndarray, batch: tuple[int, ...], k: int, measurement: Any = None) -> np.ndarray:
    """``z`` as ``(*batch, m)``, checked against the measurement model's ``dim`` where it declares one."""
    return measurement_for_step(z, batch, model_dim(measurement), k)


def _sample_prior(prior: Any, batch: tuple[int, ...], N: int, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Particles ``(*batch, N, n)`` from the prior, and the prior's mean and covariance."""
    if hasattr(prior, "sample_particles") and not isinstance(prior, Gaussian):
        X = np.asarray(prior.sample_particles(batch, N, rng), dtype=float)
        if X.shape[:-1] != (*batch, N):
            raise ValueError(f"prior.sample_particles: expected shape {(*batch, N)} + (n,), got {X.shape}")
        mean, cov = weighted_moments(X, np.ones(X.shape[:-1]))
        return X, mean, cov
    if not isinstance(prior, Gaussian):
        prior = Gaussian(*prior)
    mean, cov = prior.broadcast(batch)
    n = prior.dim
    L = np.linalg.cholesky(prior.cov)
    xi = rng.standard_normal((*batch, N, n))
    if L.ndim == 2:
        X = mean[..., None, :] + np.einsum("ij,...pj->...pi", L, xi)
    else:
        X = mean[..., None, :] + np.einsum("...ij,...pj->...pi", L, xi)
    return X, mean, cov


@dataclass
class Weighed:
    """The measurement step of a particle filter (see the module docstring).

    Attributes
    ----------
    shifted
        ``(*b, N)`` new log-weights minus their row maximum ``mx`` (NaN
        replaced by −inf; rows that were reset hold the predictive weights).
    mx
        ``(*b,)`` row maxima of the unnormalised new log-weights.
    e, s
        ``exp(shifted)`` and its row sums.
    ll, ll_const
        Per-particle log-likelihoods are ``ll + ll_const``: ``ll`` ``(*b, N)``
        (for Gaussian noise −½ νᵀR⁻¹ν, the fitness of paper P1) and a
        constant, one float or ``(*b,)`` per run (0 in rows with nothing
        measured, and in rows whose ``ll`` holds it: those with a missing
        component).
    measured
        ``(*b,)`` rows with at least one measured component.
    info
        The standard info keys plus ``weights_reset``.
    """

    shifted: np.ndarray
    mx: np.ndarray
    e: np.ndarray
    s: np.ndarray
    ll: np.ndarray
    ll_const: float | np.ndarray
    measured: np.ndarray
    info: dict[str, np.ndarray]

    @property
    def logw(self) -> np.ndarray:
        """Normalised log-weights."""
        return self.shifted - np.log(self.s)[..., None]

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights."""
        return self.e / self.s[..., None]

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size of the new weights."""
        return self.s**2 / np.einsum("...i,...i->...", self.e, self.e)


def _normalising_constant(diag: np.ndarray) -> float:
    """−½ (Σ log σ² + m log 2π) of a diagonal R."""
    return -0.5 * (float(np.sum(np.log(diag))) + diag.size * _LOG_2PI)


def _complete_loglik(r2: np.ndarray, diag: np.ndarray) -> np.ndarray:
    """−½ Σ_j r_j²/σ_j² from the squared residuals ``(*b, N, m)`` (overwritten when m = 1)."""
    if diag.size == 1:
        r2 *= -0.5 / diag[0]
        return r2[..., 0]
    return np.einsum("...i,i->...", r2, -0.5 / diag)


def _has_h_components(measurement: Any) -> bool:
    """Whether ``measurement.h_components`` is defined where its ``h`` is (a subclass overriding ``h`` alone must not use it)."""
    return _class_has_h_components(type(measurement))


@lru_cache(maxsize=None)
def _class_has_h_components(cls: type) -> bool:
    """:func:`_has_h_components` per class, walked once (the cuckoo fitness asks every move)."""
    owner = {name: next((c for c in cls.__mro__ if name in c.__dict__), None) for name in ("h", "h_components")}
    return owner["h_components"] is not None and owner["h_components"] is owner["h"]


def _exp_shifted(
    a: np.ndarray, fallback: np.ndarray | None, work: Workspace | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(a − mx, mx, exp(a − mx), reset)`` per row, with the zero-likelihood recovery rule applied."""
    mx = a.max(axis=-1)
    reset = np.zeros(mx.shape, dtype=bool)
    if not np.all(np.isfinite(mx)):
        a = np.where(np.isnan(a), -np.inf, a)  # a NaN likelihood counts as zero
        pos = np.isposinf(a)
        if pos.any():  # infinite densities: those particles share the weight
            a = np.where(pos.any(axis=-1, keepdims=True), np.where(pos, 0.0, -np.inf), a)
        mx = a.max(axis=-1)
        reset = ~np.isfinite(mx)
        if reset.any():
            fb = 0.0 if fallback is None else fallback
            a = np.where(reset[..., None], fb, a)
            mx = a.max(axis=-1)
    shifted = np.subtract(a, mx[..., None], out=scratch(work, "weigh.shifted", a.shape))
    e = np.exp(shifted, out=scratch(work, "weigh.e", a.shape))
    return shifted, mx, e, reset


# --------------------------------------------------------------------------
# the shared particle-filter machinery
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class ParticleFilterBase(FilterBase):
    """What every particle filter shares: prior sampling, weighing, moments, resampling.

    Parameters
    ----------
    motion
        Motion model with ``sample(x, k, rng, dt=None)`` (and ``f``, ``cov``).
    measurement
        Measurement model with ``h``, ``cov`` and ``loglik``.
    particles
        Number of particles N per run.
    resampler
        ``"systematic"`` (default), ``"stratified"``, ``"multinomial"`` or
        ``"residual"``.
    ess_threshold
        ``None``: resample at every step (classic SIR, paper P1's PF); a
        number r in [0, 1]: resample when ESS < r·N (0 = never).
    name
        Label used in results (keyword only).
    backend
        Compute backend, keyword only: ``"numpy"``, ``"numba"`` (compiled,
        for the built-in models; see :mod:`pursuit.compute`) or ``None`` for
        the process default.  Not the Monte Carlo engine's execution backend.
    """

    motion: Any
    measurement: Any
    particles: int = 1000
    resampler: str = "systematic"
    ess_threshold: float | None = None
    _stock: bool = field(init=False, repr=False, compare=False, default=False)
    _plain_residual: bool = field(init=False, repr=False, compare=False, default=True)

    motion_needs = ("sample", "f", "cov")
    measurement_needs = ("h", "cov", "loglik")
    need_diagonal_noise = True  # the compiled likelihood sums per component

    def __post_init__(self) -> None:
        object.__setattr__(self, "particles", positive_int("particles", self.particles))
        get_resampler(self.resampler)
        if self.ess_threshold is not None:
            object.__setattr__(self, "ess_threshold", in_range("ess_threshold", self.ess_threshold, 0.0, 1.0))
        cls = type(self.measurement)
        res = getattr(cls, "residual", None)
        object.__setattr__(self, "_plain_residual", res is None or res is _GaussianNoise.residual)
        object.__setattr__(
            self, "_stock", getattr(cls, "loglik", None) is _GaussianNoise.loglik and self._plain_residual
        )
        super().__post_init__()

    # -- compute backend -----------------------------------------------------
    def _sequence_applies(self, state: ParticleState) -> bool:
        return self._compiled_batch(state) and state.k == 0 and state.particles.ndim == 3

    def _compiled_batch(self, state: ParticleState) -> bool:
        """Compiled steps handle one batch axis with RunStreams (any batch shape with one Generator)."""
        return self._specs is not None and (state.particles.ndim <= 3 or not isinstance(state.rng, RunStreams))

    # -- init ----------------------------------------------------------------
    def init(self, prior: Any, batch: tuple[int, ...] = (), rng: RNGLike = None) -> ParticleState:
        """Draw N particles per run from the prior.

        Parameters
        ----------
        prior
            A :class:`pursuit.Gaussian` (its mean may carry the batch axes),
            or any object with ``sample_particles(batch, N, rng)`` returning
            ``(*batch, N, n)``.
        batch
            Batch shape (default: the prior mean's leading axes).
        rng
            Seed, Generator or :class:`pursuit.RunStreams`; kept in the state
            for every later draw.
        """
        rng = as_rng(rng)
        batch = prior_batch(prior, batch)
        X, mean, cov = _sample_prior(prior, batch, self.particles, rng)
        prior_of_size(X.shape[-1], model_dim(self.motion), self.motion)
        logw = np.broadcast_to(-np.log(self.particles), (*batch, self.particles))
        return ParticleState(X, logw, mean, np.broadcast_to(cov, (*batch, *cov.shape[-2:])), rng, 0, True)

    # -- the measurement step ------------------------------------------------
    def _likelihoods(
        self,
        X: np.ndarray,
        z: np.ndarray,
        k: int,
        valid: np.ndarray,
        measured: np.ndarray,
        work: Workspace | None = None,
        predicted: bool = True,
    ):
        """Predicted measurements ``(*b, N, m)``, log-likelihoods ``(*b, N)`` and their constant.

        The log-likelihood of particle i is ``ll[i] + const``; for the stock
        Gaussian models ``ll`` is −½ νᵀR⁻¹ν and ``const`` the normalising
        constant, which saves a pass over the particles.  With ``work``, the
        returned ``ll`` may live in a scratch buffer.  ``predicted=False``
        (the cuckoo searches' fitness) may return None for the predicted
        measurements: a range model then computes only the ranges some run
        measured (:meth:`~pursuit.models.RangeSensors.h_components`), the same
        bits as those columns of ``h``.
        """
        meas = self.measurement
        R = np.asarray(meas.cov(k), dtype=float) if self._stock else None
        diagonal = R is not None and np.count_nonzero(R - np.diag(np.diag(R))) == 0
        # components no run measured add exactly nothing with a diagonal R (gaussian_loglik): left out
        cols = None if not diagonal or valid.all() else measured_somewhere(valid)
        if cols is not None and not predicted and _has_h_components(meas):
            Zp = None
        else:
            Zp = np.asarray(meas.h(X, k), dtype=float)
        everywhere = bool(measured.all())
        const: float | np.ndarray = 0.0
        if self._stock:
            if cols is None:
                r = np.subtract(z[..., None, :], Zp, out=scratch(work, "lik.r", Zp.shape))
            else:
                Zc = np.asarray(meas.h_components(X, k, cols), dtype=float) if Zp is None else Zp[..., cols]
                r = z[..., None, cols] - Zc
                R = R[np.ix_(cols, cols)]
            diag = np.diag(R)
            # A run that measured every component gets −½ Σ ν²/σ² and the constant apart (a pass fewer);
            # one with a missing component gets gaussian_loglik's terms.  Chosen run by run, so that a
            # run's bits do not depend on what the other runs of its chunk measured.
            complete = valid.all(axis=-1) if diagonal else np.zeros(valid.shape[:-1], dtype=bool)
            if complete.all():
                const = _normalising_constant(diag)
                ll = _complete_loglik(np.square(r, out=r), diag)
            else:
                # rows with nothing measured get a dummy residual; their log-likelihood is set to 0 below;
                # in_order with components left out: every row had a missing one at full width
                ll = gaussian_loglik(r if everywhere else np.where(measured[..., None, None], r, 0.0), R, in_order=cols is not None)
                if complete.any():  # (then nothing was left out)
                    ll = np.where(complete[..., None], _complete_loglik(np.square(r), diag), ll)
                    const = np.where(complete, _normalising_constant(diag), 0.0)
        else:
            zc = z if everywhere else np.where(measured[..., None], z, 0.0)
            ll = np.asarray(meas.loglik(zc[..., None, :], X, k), dtype=float)
        if not everywhere:
            ll = np.where(measured[..., None], ll, 0.0)
        return Zp, ll, const

    def _spread(self, Zp: np.ndarray, omega: np.ndarray | None, work: Workspace | None):
        """ẑ and Σ ω (h − ẑ)(h − ẑ)ᵀ; ``omega=None`` means equal weights (cheaper arithmetic)."""
        meas = self.measurement
        N = Zp.shape[-2]
        if omega is None:
            wmean = lambda A: np.einsum("...pi->...i", A) * (1.0 / N)  # noqa: E731
        else:
            wmean = lambda A: np.einsum("...p,...pi->...i", omega, A)  # noqa: E731
        if self._plain_residual:
            zhat = wmean(Zp)
            D = np.subtract(Zp, zhat[..., None, :], out=scratch(work, "pred.D", Zp.shape))
        else:  # average angles about one particle's value, not across the ±π cut
            Z0 = Zp[..., :1, :]
            zhat = Z0[..., 0, :] + wmean(meas.residual(Zp, Z0))
            D = meas.residual(Zp, zhat[..., None, :])
        if Zp.shape[-1] == 1:
            d = D[..., 0]
            if omega is None:
                Pzz = np.einsum("...p,...p->...", d, d) * (1.0 / N)
            else:
                Pzz = np.einsum("...p,...p->...", np.multiply(d, omega, out=scratch(work, "pred.Dw", d.shape)), d)
            return zhat, Pzz[..., None, None]
        # Dᵀ D as one GEMM per run (batch-invariant): the einsum "...pi,...pj->...ij" took a generic loop
        # that cost ~20x more on (100, 200, 16) (p1-wsn's grid)
        if omega is None:
            Pzz = (np.swapaxes(D, -1, -2) @ D) * (1.0 / N)
        else:
            Dw = np.multiply(D, omega[..., None], out=scratch(work, "pred.Dw", D.shape))
            Pzz = np.swapaxes(Dw, -1, -2) @ D
        return zhat, symmetrize(Pzz)

    def _predictive(
        self,
        Zp: np.ndarray,
        omega: np.ndarray | None,
        uniform_rows: np.ndarray | None,
        z: np.ndarray,
        valid: np.ndarray,
        k: int,
        work: Workspace | None = None,
    ):
        """Innovation statistics from predicted measurements and normalised predictive weights.

        ``omega=None``: every run has equal weights.  Otherwise the runs in
        ``uniform_rows`` (equal weights) get the equal-weight arithmetic too,
        so a run's numbers do not depend on its neighbours in the batch.
        """
        meas = self.measurement
        zhat, Pzz = self._spread(Zp, omega, work)
        if omega is not None and uniform_rows is not None and uniform_rows.any():
            zu, Pu = self._spread(Zp, None, work)
            zhat = np.where(uniform_rows[..., None], zu, zhat)
            Pzz = np.where(uniform_rows[..., None, None], Pu, Pzz)
        nu_full = z - zhat if self._plain_residual else meas.residual(z, zhat)
        m = Zp.shape[-1]
        R = np.asarray(meas.cov(k), dtype=float)
        batch = z.shape[:-1]
        if valid.all():
            nu = nu_full
            S = Pzz + R
            dof = np.full(batch, m)
        else:
            vv = valid[..., :, None] & valid[..., None, :]
            nu = np.where(valid, nu_full, 0.0)
            S = np.where(vv, Pzz + R, 0.0) + np.eye(m) * (~valid)[..., None, :]
            dof = valid.sum(axis=-1)
        nis = quad(nu, _safe_inverse(S))
        measured = dof > 0
        return {
            "innovation": np.where(valid, nu_full, np.nan) if not valid.all() else nu_full,
            "S": np.broadcast_to(S, (*batch, m, m)),
            "nis": np.where(measured, nis, np.nan),
            "dof": np.broadcast_to(dof, batch),
        }

    def weigh(
        self,
        X: np.ndarray,
        z: np.ndarray,
        k: int,
        log_prior: np.ndarray | None,
        log_correction: np.ndarray | None = None,
        work: Workspace | None = None,
    ) -> Weighed:
        """Weight propagated particles by the measurement.

        Parameters
        ----------
        X
            ``(*b, N, n)`` propagated particles.
        z
            ``(*b, m)`` measurement (NaN = missing).
        k
            Step index.
        log_prior
            ``(*b, N)`` normalised log-weights of the previous step, or
            ``None`` when they are all 1/N.
        log_correction
            ``(*b, N)`` log p(x_k | x_{k−1}) − log q(x_k) for particles drawn
            from a proposal q other than the transition prior (None: 0).
        work
            Scratch buffers (the returned arrays may live in them, valid until
            the next call with the same workspace).

        Returns
        -------
        Weighed
        """
        N = X.shape[-2]
        log_n = float(np.log(N))
        valid = ~np.isnan(z)
        measured = valid.any(axis=-1)
        Zp, ll, const = self._likelihoods(X, z, k, valid, measured, work)
        # Previous weights enter as offset = log w_{k-1} + log N, which is exactly 0 for a
        # run that resampled (its log-weights are exactly −log N).  The all-uniform fast
        # path skips only those exact no-ops, so a run gets the same bits whether or
        # not the other runs in its batch resampled.
        offset = None if log_prior is None else log_prior + log_n
        uniform_rows = None
        if log_correction is not None:  # predictive weights ∝ w_{k-1} p/q (module docstring)
            lp = log_correction if offset is None else log_correction + offset
            lp = np.where(np.isnan(lp), -np.inf, lp)
            top = np.max(lp, axis=-1, keepdims=True)
            ew = np.exp(lp - np.where(np.isfinite(top), top, 0.0))
            omega = ew / ew.sum(axis=-1, keepdims=True)
            offset = lp
        elif offset is None:
            omega = None
        else:
            omega = np.exp(offset) * (1.0 / N)
            uniform_rows = ~np.any(offset, axis=-1)
        info = self._predictive(Zp, omega, uniform_rows, z, valid, k, work)
        a = ll if offset is None else ll + offset
        shifted, mx, e, reset = _exp_shifted(a, offset, work)
        s = e.sum(axis=-1)
        loglik = mx + np.log(s) + (np.where(measured, const, 0.0) - log_n)
        loglik = np.where(reset, -np.inf, loglik)
        loglik = np.where(measured, loglik, 0.0)
        info["loglik"] = loglik
        info["weights_reset"] = reset
        return Weighed(shifted, mx, e, s, ll, const, measured, info)

    # -- resampling ----------------------------------------------------------
    def resample(
        self,
        arrays: list[np.ndarray],
        weighed: Weighed,
        need: np.ndarray,
        rng: np.random.Generator | RunStreams,
        work: Workspace | None = None,
    ) -> tuple[list[np.ndarray], np.ndarray, bool]:
        """Resample the rows in ``need``: ``(arrays, logw, uniform)``.

        ``arrays`` are per-particle arrays ``(*b, N, ...)`` copied together
        (particles, and per-particle covariances for the unscented PF).
        Only the streams of rows that resample are drawn from.
        """
        counts_of = get_resampler(self.resampler, counts=True)
        N = weighed.e.shape[-1]
        uniform_logw = -np.log(N)
        if not need.any():
            return arrays, weighed.logw, False
        if need.all():
            counts = counts_of(weighed.e, rng, work)
            out = [repeat_particles(a, counts) for a in arrays]
            return out, np.broadcast_to(uniform_logw, weighed.e.shape), True
        batch = need.shape
        lead = np.flatnonzero(need.reshape(batch[0], -1).any(axis=1))
        counts = counts_of(weighed.e[lead], rows_rng(rng, lead), work)
        sub_need = need[lead]
        out = []
        for a in arrays:
            sub = repeat_particles(a[lead], counts)
            if len(batch) > 1:
                mask = sub_need.reshape(sub_need.shape + (1,) * (a.ndim - len(batch)))
                sub = np.where(mask, sub, a[lead])
            new = np.array(a, copy=True)
            new[lead] = sub
            out.append(new)
        logw = np.where(need[..., None], uniform_logw, weighed.logw)
        return out, logw, False

    def _needs_resampling(self, weighed: Weighed, ess: np.ndarray) -> np.ndarray:
        if self.ess_threshold is None:
            return weighed.measured.copy()
        return weighed.measured & (ess < self.ess_threshold * weighed.e.shape[-1])


@dataclass(frozen=True)
class BootstrapParticleFilter(ParticleFilterBase):
    """Bootstrap / SIR particle filter (Gordon, Salmond & Smith 1993).

    Propagates every particle through the motion model (the transition prior
    is the proposal), weights it by the measurement likelihood, reports the
    weighted mean and covariance, and resamples every step
    (``ess_threshold=None``, the default, as paper P1's PF) or when
    ESS < ``ess_threshold``·N (paper P3's rule with 0.5).

    Parameters
    ----------
    motion, measurement, particles, resampler, ess_threshold, name, backend
        See :class:`ParticleFilterBase`.

    Notes
    -----
    Draws per run and step: the motion model's process noise, then (if the
    run resamples) the resampler's uniforms.  See the module docstring for
    the step info.
    """

    compiled_path = "particle:BOOTSTRAP"

    def _default_name(self) -> str:
        return "PF"

    def step(
        self, state: ParticleState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[ParticleState, dict[str, np.ndarray]]:
        """Propagate, weigh, estimate and (maybe) resample.

        Parameters
        ----------
        state
            State after step ``k − 1``.
        z
            ``(*batch, m)`` measurement; NaN entries are missing.
        k
            Step index (default ``state.k + 1``).
        dt
            Time since the previous step (default: the motion model's).
        """
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        z = _prepare_measurement(z, state.batch, k, self.measurement)
        if self._compiled_batch(state):
            return self._compiled_step(state, z, k, dt)
        rng = state.rng
        X = propagate_particles(self.motion, state.particles, k, dt, rng)
        work = state.work
        weighed = self.weigh(X, z, k, None if state.uniform else state.logw, work=work)
        mean, cov = weighted_moments(X, weighed.e, weighed.s, work)
        ess = weighed.ess
        need = self._needs_resampling(weighed, ess)
        (X,), logw, uniform = self.resample([X], weighed, need, rng, work)
        info = weighed.info
        info["ess"] = ess
        info["resampled"] = need
        return ParticleState(X, logw, mean, cov, rng, k, uniform, work=work), info


SIR = BootstrapParticleFilter
"""Alias: the sampling-importance-resampling filter is the bootstrap filter."""


def propagate_particles(motion: Any, X: np.ndarray, k: int, dt: float | None, rng) -> np.ndarray:
    """Draw x_k ~ p(x_k | x_{k−1}) for every particle ``X (*b, N, n)`` with the motion model's ``sample``.

    The draw every particle filter (NumPy or compiled step) makes first, from ``rng``.
    """
    if dt is None:
        return np.asarray(motion.sample(X, k, rng), dtype=float)
    return np.asarray(motion.sample(X, k, rng, dt=dt), dtype=float)
