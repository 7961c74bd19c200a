"""The partial-UKF unscented particle filter of patent CN101631395B (paper P3; open choices U1-U8: docs/spec/02-upf-partial.md §7).

Only a fraction l of the N particles, the "important" ones, get an
unscented-Kalman proposal; the others are drawn from the transition prior
(van der Merwe, Doucet, de Freitas & Wan 2000 is the full UPF, l = 1).
One step, for every run at once:

1. choose n_u = round(l·N) important particles (``select``): by default the
   n_u largest previous weights, ties broken uniformly at random (after
   resampling all weights tie, so the subset is a random one);
2. run a UKF step from each important particle's mean x_{k−1}^i and
   covariance P_{k−1}^i with the measurement z_k, and draw
   x_k^i ~ q_i = N(x̄^i, P̂^i); keep P_k^i = P̂^i;
3. draw every other particle from p(x_k | x_{k−1}^i) and give it a
   covariance by ``cov_mode`` (default: the weighted covariance of the
   whole cloud, plus 1e−9·I);
4. weigh: w_k^i ∝ w_{k−1}^i p(z_k | x_k^i) p(x_k^i | x_{k−1}^i) / q_i(x_k^i)
   for the UKF group and w_{k−1}^i p(z_k | x_k^i) for the prior group, all
   in the log domain, normalised together;
5. estimate the weighted mean and covariance, then resample (systematic by
   default, copying each particle's covariance with it) when
   ESS < ``ess_threshold``·N (the patent's N/2).

l = 0 is the bootstrap PF with ESS-triggered resampling (the same draws in
the same order); l = 1 is the full unscented PF.  Each particle's weight is
a valid sequential importance weight for its own proposal, and the
important set is chosen from time-(k−1) quantities, so the estimator is not
biased by the choice.

The transition density needs a full-rank process noise.  A motion model
with singular Q (discrete white-noise acceleration, Q = q Γ Γᵀ) is replaced
inside this filter, by ``singular_noise``: ``"cwna"`` (default) switches a
kinematic model to continuous white-noise acceleration with the same q,
``"jitter"`` adds ``jitter``·I to Q.  Either way the filter's own model is
used for every particle, so the weights stay exact for that model.

Step info: the standard keys (see :mod:`pursuit.filters.particle`; the
predictive weights include p/q for the UKF group), ``ess``, ``resampled``,
``weights_reset``, ``n_ukf`` (important particles per run) and
``repaired`` (a proposal covariance had to be repaired).

Draws per run and step: the selection's tie-break uniforms (N, only when
0 < n_u < N and ``select`` is ``"weight"`` or ``"random"``), the UKF group's
proposal normals (n_u × n), the prior group's process noise, then the
resampler's uniforms if the run resamples.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._linalg import cholesky_psd, mv
from .._validation import in_range, nonnegative, time_step
from ..compute import compiled_specs
from ..rng import RNGLike
from .gaussian import GaussianState, UnscentedKalmanFilter
from .jacobians import motion_jacobian
from .particle import ParticleFilterBase, ParticleState, _prepare_measurement, propagate_particles, weighted_moments
from .resample import gather

__all__ = ["PartialUPF", "JitteredMotion", "full_rank_motion"]

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class JitteredMotion:
    """A motion model with ``jitter``·I added to its process noise.

    Delegates ``f`` and ``jacobian`` to ``base``; ``cov`` is Q + εI and
    ``sample`` draws from N(f(x), Q + εI).
    """

    base: Any
    jitter: float = 1e-6

    def __post_init__(self) -> None:
        object.__setattr__(self, "jitter", in_range("jitter", self.jitter, 0.0, np.inf, low_open=True))

    @property
    def dim(self) -> int:
        """State dimension."""
        return self.base.dim

    def f(self, x, k=None, dt=None):
        """The base model's transition."""
        return self.base.f(x, k) if dt is None else self.base.f(x, k, dt=dt)

    def jacobian(self, x, k=None, dt=None):
        """The base model's Jacobian (numerical if it has none)."""
        return motion_jacobian(self.base, x, k, dt)

    def cov(self, k=None, dt=None):
        """Q + εI."""
        Q = np.asarray(self.base.cov(k) if dt is None else self.base.cov(k, dt=dt), dtype=float)
        return Q + self.jitter * np.eye(Q.shape[-1])

    def sample(self, x, k, rng, dt=None):
        """x_k ~ N(f(x), Q + εI)."""
        L = np.linalg.cholesky(self.cov(k, dt))
        xi = rng.standard_normal(np.shape(x))
        return np.asarray(self.f(x, k, dt), dtype=float) + np.einsum("ij,...j->...i", L, xi)


def full_rank_motion(motion: Any, singular_noise: str = "cwna", jitter: float = 1e-6, k: int = 1) -> Any:
    """The motion model itself if its Q is full rank, else a full-rank replacement.

    ``"cwna"``: a kinematic model (one with a ``noise`` field) gets
    ``noise="continuous"``; other models fall back to ``"jitter"``
    (``jitter``·I added to Q).
    """
    Q = np.asarray(motion.cov(k), dtype=float)
    w = np.linalg.eigvalsh(0.5 * (Q + Q.T))
    if w.min() > 1e-12 * max(w.max(), 1e-300):
        return motion
    if singular_noise == "cwna" and getattr(motion, "noise", None) == "discrete":
        return replace(motion, noise="continuous")
    return JitteredMotion(motion, jitter)


@dataclass(frozen=True)
class PartialUPF(ParticleFilterBase):
    """Unscented particle filter with a UKF proposal for a fraction l of the particles.

    Parameters
    ----------
    motion, measurement, particles, resampler, name
        See :class:`pursuit.filters.particle.ParticleFilterBase`.
    fraction
        l ∈ [0, 1]: share of particles with a UKF proposal.
    ess_threshold
        Resample when ESS < ``ess_threshold``·N (default 0.5, the patent's
        N/2; None: every step).
    select
        Important particles (U1): ``"weight"`` (largest previous weights,
        random tie-break), ``"random"`` (uniform random subset) or
        ``"block"`` (the first n_u, as the claim numbers them).
    rounding
        n_u from l·N (U2): ``"nearest"`` (half up), ``"floor"`` or ``"ceil"``.
    cov_mode
        Covariance of prior-group particles (U3): ``"population"``
        (weighted cloud covariance + 1e−9·I), ``"propagate"``
        (F P Fᵀ + Q, grows if never updated) or ``"reset"`` (the prior's).
        ``"zero"`` (not in the spec) sets *every* particle's covariance to
        1e−9·I after each step, so the UKF proposal approximates the locally
        optimal proposal p(x_k | x_{k−1}^i, z_k) (exact on linear-Gaussian
        models) instead of spreading each particle over the whole posterior.
    alpha, beta, kappa
        Unscented-transform parameters (U4; default 1, 2, 0).
    singular_noise, jitter
        What replaces a singular process noise (U6), see the module
        docstring.
    """

    fraction: float = 0.5
    ess_threshold: float | None = 0.5
    select: str = "weight"
    rounding: str = "nearest"
    cov_mode: str = "population"
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0
    singular_noise: str = "cwna"
    jitter: float = 1e-6
    _model: Any = field(init=False, repr=False, compare=False, default=None)
    _ukf: Any = field(init=False, repr=False, compare=False, default=None)

    compiled_path = "upf:UPF"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "fraction", in_range("fraction", self.fraction, 0.0, 1.0))
        for name, choices in (
            ("select", ("weight", "random", "block")),
            ("rounding", ("nearest", "floor", "ceil")),
            ("cov_mode", ("population", "propagate", "reset", "zero")),
            ("singular_noise", ("cwna", "jitter")),
        ):
            if getattr(self, name) not in choices:
                raise ValueError(f"{name}: must be one of {', '.join(map(repr, choices))}, got {getattr(self, name)!r}")
        in_range("jitter", self.jitter, 0.0, np.inf, low_open=True)
        model = full_rank_motion(self.motion, self.singular_noise, self.jitter)
        object.__setattr__(self, "_model", model)
        object.__setattr__(
            self, "_ukf", UnscentedKalmanFilter(model, self.measurement, alpha=self.alpha, beta=self.beta, kappa=self.kappa)
        )
        nonnegative("beta", self.beta)

    def _default_name(self) -> str:
        return f"UPF(l={self.fraction:g})"

    def _compiled_unsupported(self) -> str | None:
        """The compiled step runs the full-rank model the filter uses; ``"propagate"`` needs it linear."""
        model = full_rank_motion(self.motion, self.singular_noise, self.jitter)
        specs = compiled_specs(model, self.measurement, need_diagonal=self.need_diagonal_noise)
        if isinstance(specs, str):
            if model is not self.motion:
                return f"{specs}: the singular process noise of {type(self.motion).__name__} is replaced by that model (singular_noise={self.singular_noise!r})"
            return specs
        if self.cov_mode == "propagate" and isinstance(
            compiled_specs(model, self.measurement, need_diagonal=self.need_diagonal_noise, linear_motion=True), str
        ):
            return f"cov_mode='propagate' with the nonlinear motion model {type(model).__name__} (the compiled step propagates covariances with a constant F)"
        return None

    @property
    def model(self) -> Any:
        """The motion model the filter actually uses (full-rank process noise)."""
        return self._model

    @property
    def ukf(self) -> UnscentedKalmanFilter:
        """The unscented Kalman filter that makes the proposals (its ``sigma_weights``; the model is :attr:`model`)."""
        return self._ukf

    @property
    def n_ukf(self) -> int:
        """n_u: how many particles get the UKF proposal."""
        x = self.fraction * self.particles
        n = {"nearest": np.floor(x + 0.5), "floor": np.floor(x + 1e-9), "ceil": np.ceil(x - 1e-9)}[self.rounding]
        return int(min(max(n, 0), self.particles))

    def init(self, prior: Any, batch: tuple[int, ...] = (), rng: RNGLike = None) -> ParticleState:
        """Draw the particles from the prior; every particle starts with the prior covariance
        (with ``cov_mode="zero"``: 1e−9·I)."""
        state = super().init(prior, batch, rng)
        P0 = state.cov
        n = P0.shape[-1]
        start = 1e-9 * np.eye(n) if self.cov_mode == "zero" else P0[..., None, :, :]
        Pi = np.broadcast_to(start, (*state.batch, self.particles, n, n))
        return replace(state, particle_cov=Pi, memory=P0)

    # -- one step ----------------------------------------------------------------
    def step(
        self, state: ParticleState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[ParticleState, dict[str, np.ndarray]]:
        """Select, propose (UKF or prior), weigh, estimate and maybe resample."""
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        z = _prepare_measurement(z, state.batch, k, self.measurement)
        if self._compiled_batch(state):
            return self._compiled_step(state, z, k, dt)
        return self.numpy_step(state, z, k, dt)

    def numpy_step(
        self, state: ParticleState, z: np.ndarray, k: int, dt: float | None
    ) -> tuple[ParticleState, dict[str, np.ndarray]]:
        """The NumPy step, whatever the backend (``z`` already checked and broadcast to ``(*batch, m)``).

        :meth:`step` calls it unless the step runs compiled; the compiled
        step calls it where the runs do not draw from streams of their own.
        """
        batch = state.batch
        rng = state.rng
        work = state.work
        N = self.particles
        n_u = self.n_ukf
        X_prev, P_prev = state.particles, state.particle_cov
        logw_prev = None if state.uniform else state.logw
        repaired = np.zeros(batch, dtype=bool)

        if n_u == 0:
            X = propagate_particles(self._model, X_prev, k, dt, rng)
            log_corr = None
            P_u = None
            log_prior = logw_prev
        else:
            if n_u == N:
                order = None
            elif self.select == "block":
                order = np.broadcast_to(np.arange(N), (*batch, N))
            else:
                u = rng.random((*batch, N))
                if self.select == "weight" and logw_prev is not None:
                    order = np.lexsort((u, -logw_prev), axis=-1)  # largest weights first, random ties
                else:
                    order = np.argsort(u, axis=-1)
            Xu, Pu, Xr = _split(X_prev, P_prev, order, n_u)
            x_u, P_u, log_corr_u, rep = self._ukf_proposal(Xu, Pu, z, k, dt, rng)
            repaired |= rep
            if Xr is None:
                X, log_corr = x_u, log_corr_u
            else:
                x_r = propagate_particles(self._model, Xr, k, dt, rng)
                X = np.concatenate([x_u, x_r], axis=-2)
                log_corr = np.concatenate([log_corr_u, np.zeros(x_r.shape[:-1])], axis=-1)
            if logw_prev is None or order is None:
                log_prior = logw_prev
            else:
                log_prior = np.take_along_axis(logw_prev, order, axis=-1)
            # keep the UKF-group covariances for the covariance update
        weighed = self.weigh(X, z, k, log_prior, log_correction=log_corr, work=work)
        mean, cov = weighted_moments(X, weighed.e, weighed.s, work)
        P = self._particle_covariances(P_u, P_prev, X_prev, state, cov, n_u, k, dt, order if n_u else None)
        ess = weighed.ess
        need = self._needs_resampling(weighed, ess)
        (X, P), logw, uniform = self.resample([X, P], weighed, need, rng, work)
        info = weighed.info
        info["ess"] = ess
        info["resampled"] = need
        info["n_ukf"] = np.full(batch, n_u)
        info["repaired"] = repaired
        return ParticleState(X, logw, mean, cov, rng, k, uniform, P, state.memory, work), info

    def _ukf_proposal(self, Xu, Pu, z, k, dt, rng):
        """UKF step per important particle, a draw from it, and log p(x|x_prev) − log q(x)."""
        batch_u = Xu.shape[:-1]  # (*b, n_u)
        zu = np.broadcast_to(z[..., None, :], (*batch_u, z.shape[-1]))
        gs = GaussianState(mean=Xu, cov=Pu, k=k - 1, memory=self._ukf.fading.init(batch_u))
        # the posterior alone (z is already checked): the UKF's info would be thrown away
        moments = self._ukf.posterior(gs, zu, k, dt)
        if moments is None:
            post, _ = self._ukf.step(gs, zu, k=k, dt=dt)
            post_mean, post_cov = post.mean, post.cov
        else:
            post_mean, post_cov, _ = moments
        L, rep = cholesky_psd(post_cov)
        xi = rng.standard_normal(Xu.shape)
        x = post_mean + mv(L, xi)
        n = Xu.shape[-1]
        diagL = np.diagonal(L, axis1=-2, axis2=-1)
        log_q = -0.5 * np.einsum("...i,...i->...", xi, xi) - np.sum(np.log(diagL), axis=-1) - 0.5 * n * _LOG_2PI
        log_trans = self._transition_logpdf(x, Xu, k, dt)
        return x, post_cov, log_trans - log_q, rep.reshape(batch_u).any(axis=-1)

    def _transition_logpdf(self, x, x_prev, k, dt):
        """log N(x; f(x_prev), Q) of the filter's full-rank model."""
        model = self._model
        fx = np.asarray(model.f(x_prev, k) if dt is None else model.f(x_prev, k, dt=dt), dtype=float)
        Q = np.asarray(model.cov(k) if dt is None else model.cov(k, dt=dt), dtype=float)
        L = np.linalg.cholesky(Q)
        y = mv(np.linalg.inv(L), x - fx)  # einsum: the same arithmetic for every particle and run
        maha = np.einsum("...i,...i->...", y, y)
        return -0.5 * maha - np.sum(np.log(np.diag(L))) - 0.5 * Q.shape[0] * _LOG_2PI

    def _particle_covariances(self, P_u, P_prev, X_prev, state, cov, n_u, k, dt, order):
        """Per-particle covariances after the step, in the new particle order (U3)."""
        batch = state.batch
        N = self.particles
        n = cov.shape[-1]
        n_r = N - n_u
        if self.cov_mode == "zero":
            return np.broadcast_to(1e-9 * np.eye(n), (*batch, N, n, n))
        if n_r == 0:
            return P_u
        if self.cov_mode == "population":
            Pr = np.broadcast_to((cov + 1e-9 * np.eye(n))[..., None, :, :], (*batch, n_r, n, n))
        elif self.cov_mode == "reset":
            Pr = np.broadcast_to(np.asarray(state.memory)[..., None, :, :], (*batch, n_r, n, n))
        else:
            if order is None:
                Xr, Pr_prev = X_prev, P_prev
            else:
                Xr = gather(X_prev, order[..., n_u:])
                Pr_prev = gather(P_prev, order[..., n_u:])
            F = motion_jacobian(self._model, Xr, k, dt)
            Q = np.asarray(self._model.cov(k) if dt is None else self._model.cov(k, dt=dt), dtype=float)
            Pr = F @ Pr_prev @ np.swapaxes(F, -1, -2) + Q
        if P_u is None:
            return np.array(Pr)
        return np.concatenate([P_u, np.broadcast_to(Pr, (*batch, n_r, n, n))], axis=-3)


def _split(X, P, order, n_u):
    """Important particles (means, covariances) and the rest, in ``order``."""
    if order is None:
        return X, np.asarray(P), None
    Xo = gather(X, order)
    Pu = gather(P, order[..., :n_u])  # whole rows: np.take_along_axis indexes each of the n² entries, ~40x slower here
    return Xo[..., :n_u, :], Pu, Xo[..., n_u:, :]
