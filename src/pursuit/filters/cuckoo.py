"""Cuckoo-search particle filters: CS-PF and the improved ICS-PF (paper P1).

Two algorithms share the cuckoo proposals below, chosen by ``acceptance``:

* ``"mh"`` (the default): a resample-move particle filter whose moves are
  Metropolis–Hastings steps in the space of the process noise, built from
  the Lévy-flight and discovery proposals; they keep the posterior
  (:mod:`pursuit.filters.cuckoo_mh`, docs/spec/01-particle-filters.md §10).
* ``"greedy"``: the paper-literal algorithm described in the rest of this
  docstring.  It forgets the transition density, so its particles do not
  represent the posterior, and it can diverge (one-node WSN).

Paper P1 replaces the resampling step of a particle filter by a cuckoo
search (Yang & Deb 2009): the propagated particles are "nests", the
measurement likelihood is their fitness, and every time step runs
``n_iter`` iterations of two greedy moves before the particles are
weighted:

1. **Lévy flight** (global search, paper eq. 5-6)::

       C_i = X_i + α_i · L_i ⊙ (X_i − X_best) ⊙ ξ_i,   ξ_i ~ N(0, I)

   with Mantegna's Lévy-stable steps L = u / |v|^(1/β), u ~ N(0, σ_u²),
   v ~ N(0, 1) (``step_scaling="relative"``, Yang's reference code; the
   best nest does not move).  ``"absolute"`` uses C_i = X_i + α_i L_i
   (literal eq. 5), ``"std"`` C_i = X_i + α_i L_i ⊙ σ with σ the
   per-dimension spread of the nests.
2. **Discovery** (local search and diversity, paper eq. 7)::

       C_i = X_i + r · (X_{π1(i)} − X_{π2(i)}) ⊙ K_i,   K_ij = [s_ij > Pa]

   with r ~ U(0, 1) one scalar per run and sweep, π1, π2 random
   permutations and s ~ U(0, 1) per entry (``discovery="yang"``: note that
   a fraction 1 − Pa of the entries moves, as in the paper and Yang's code;
   ``"literal_pa"`` moves the entries with s < Pa).

After each move a candidate replaces its nest only if its fitness is
strictly higher (greedy selection), so no particle's fitness ever drops
within a step.  The fitness is log f(x) = −½ νᵀR⁻¹ν for the Gaussian
measurement models (paper eq. 13, maximum 0); for other measurement models
it is their log-likelihood.

**CS-PF** keeps α = 0.01 and Pa = 0.25 fixed.  **ICS-PF** makes them shrink
over the iterations t = 0 … n−1 of a step (paper eq. 8-9)::

    α(t)  = α_max − (α_max − α_min) · t / (n − 1)                 (0.5 → 0.01)
    Pa(t) = P_max − (P_max − P_min) · sin(π t / (2 (n − 1)))      (0.3 → 0.01)

and puts the fitness trend into the step size (eq. 10, reconstructed)::

    Δ_i(t) = (f_i(t) − f_i(t−1)) / (f_i(t−1) + ε),   α_i(t) = clip(α(t) · exp(−κ Δ_i(t)), α_min, α_max)

with f = exp(fitness) at the start of iterations t and t − 1 (Δ = 0 at
t = 0).  Because moves are greedy, Δ ≥ 0: an improving nest takes smaller
steps, a stagnating one keeps α(t).

Weights (``weight_mode``): ``"reset"`` (default, the paper's) treats the
moved particles as a fresh, equally weighted sample and weights them by the
likelihood alone, with no resampling; ``"sequential"`` multiplies by the
previous weights and resamples when ESS < ``ess_threshold``·N.  In reset
mode the predictive statistics of the step info (innovation, S, NIS,
loglik; see :mod:`pursuit.filters.particle`) use the propagated particles
with equal weights, in sequential mode with the previous weights, in both
cases before the moves.

Draws per run and step: process noise; then, in two calls whatever the
search does, the normals of all iterations (Lévy u and v, and the ξ of the
relative step) and the uniforms of all iterations (discovery s, the scalar
r, the keys of the two permutations); then the resampler's uniforms in
sequential mode.  A run that stops early (``f_stop``) leaves the rest of its
draws unused, so no run's stream depends on the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import gamma, pi, sin
from typing import Any, Callable

import numpy as np

from .._validation import in_range, nonnegative, positive, time_step
from ..rng import RunStreams
from .cuckoo_mh import mh_moves, propagate_in_noise_space
from .particle import (
    ParticleFilterBase,
    ParticleState,
    Weighed,
    _exp_shifted,
    _prepare_measurement,
    propagate_particles,
    weighted_moments,
)
from .resample import gather

__all__ = [
    "mantegna_sigma",
    "levy_steps",
    "CuckooSearch",
    "CuckooParticleFilter",
    "CSPF",
    "ICSPF",
]

_EPS = 1e-12


def mantegna_sigma(beta: float) -> float:
    """σ_u of Mantegna's algorithm for stability index β ∈ (0, 2].

    σ_u = [Γ(1+β) sin(πβ/2) / (Γ((1+β)/2) β 2^((β−1)/2))]^(1/β); 0.6965745
    for β = 1.5.
    """
    beta = in_range("beta", beta, 0.0, 2.0, low_open=True)
    num = gamma(1.0 + beta) * sin(pi * beta / 2.0)
    den = gamma((1.0 + beta) / 2.0) * beta * 2.0 ** ((beta - 1.0) / 2.0)
    return (num / den) ** (1.0 / beta)


def levy_steps(rng: np.random.Generator | RunStreams, shape: tuple[int, ...], beta: float = 1.5) -> np.ndarray:
    """Mantegna Lévy-stable steps L = u / |v|^(1/β) of the given shape.

    Draws u ``shape`` then v ``shape`` (standard normals; u is scaled by
    σ_u).  With RunStreams the first axis of ``shape`` is the run axis.
    """
    mantegna_sigma(beta)
    u = rng.standard_normal(shape)
    v = rng.standard_normal(shape)
    return _mantegna(u, v, beta)


@dataclass(frozen=True)
class CuckooSearch:
    """The cuckoo-search move step, batched over runs and particles.

    Parameters
    ----------
    n_iter
        Iterations per time step (paper's value unreadable; default 10).
    alpha_max, alpha_min
        Step-size schedule α(t), linear from max to min over the iterations
        (equal values: constant α).
    pa_max, pa_min
        Discovery-probability schedule Pa(t) endpoints.
    pa_schedule
        ``"sine"`` (default, eq. 8 reconstructed), ``"linear"``, ``"cosine"``
        (P_max − (P_max − P_min)(1 − cos(π t / (2(n − 1))))) or
        ``"constant"`` (P_max throughout).
    trend
        Fitness-trend factor on α: ``"exp"`` (α·exp(−κΔ), default),
        ``"linear"`` (α·(1 + κΔ)) or ``"off"``; clipped to
        [α_min, α_max].
    kappa
        Trend gain κ.
    beta
        Lévy stability index β = λ − 1 ∈ (0, 2] (default 1.5).
    step_scaling
        ``"relative"`` (Yang), ``"absolute"`` (literal eq. 5) or ``"std"``;
        None (default): ``"relative"`` for the greedy search, the only
        choice ``"absolute"`` (in noise space) for ``acceptance="mh"``.
    discovery
        ``"yang"`` (move entries with s > Pa) or ``"literal_pa"`` (s < Pa).
    f_stop
        Stop a run's iterations once its best fitness exp(F_best) >= f_stop
        (None: never; the paper's value is unreadable).
    lower, upper
        Optional per-dimension box bounds applied after each move.
    """

    n_iter: int = 10
    alpha_max: float = 0.5
    alpha_min: float = 0.01
    pa_max: float = 0.3
    pa_min: float = 0.01
    pa_schedule: str = "sine"
    trend: str = "exp"
    kappa: float = 1.0
    beta: float = 1.5
    step_scaling: str | None = None
    discovery: str = "yang"
    f_stop: float | None = None
    lower: Any = None
    upper: Any = None

    def __post_init__(self) -> None:
        if isinstance(self.n_iter, bool) or not isinstance(self.n_iter, (int, np.integer)) or self.n_iter < 0:
            raise ValueError(f"n_iter: must be a non-negative integer, got {self.n_iter!r}")
        object.__setattr__(self, "n_iter", int(self.n_iter))
        amax = positive("alpha_max", self.alpha_max)
        amin = positive("alpha_min", self.alpha_min)
        if amin > amax:
            raise ValueError(f"alpha_min: must not exceed alpha_max ({amin} > {amax})")
        pmax = in_range("pa_max", self.pa_max, 0.0, 1.0)
        pmin = in_range("pa_min", self.pa_min, 0.0, 1.0)
        if pmin > pmax:
            raise ValueError(f"pa_min: must not exceed pa_max ({pmin} > {pmax})")
        _choice("pa_schedule", self.pa_schedule, ("sine", "linear", "cosine", "constant"))
        _choice("trend", self.trend, ("exp", "linear", "off"))
        if self.step_scaling is not None:
            _choice("step_scaling", self.step_scaling, ("relative", "absolute", "std"))
        _choice("discovery", self.discovery, ("yang", "literal_pa"))
        nonnegative("kappa", self.kappa)
        mantegna_sigma(self.beta)
        if self.f_stop is not None:
            in_range("f_stop", self.f_stop, 0.0, 1.0, low_open=True)
        for name in ("lower", "upper"):
            v = getattr(self, name)
            if v is not None:
                arr = np.atleast_1d(np.asarray(v, dtype=float))
                if arr.ndim != 1 or np.isnan(arr).any():
                    raise ValueError(f"{name}: expected a vector of bounds, got {v!r}")
                arr.setflags(write=False)
                object.__setattr__(self, name, arr)
        if self.lower is not None and self.upper is not None and np.any(self.lower > self.upper):
            raise ValueError("lower: every lower bound must not exceed its upper bound")

    @property
    def scaling(self) -> str:
        """The greedy search's Lévy step scaling (``step_scaling``, ``"relative"`` when None)."""
        return "relative" if self.step_scaling is None else self.step_scaling

    # -- schedules -------------------------------------------------------------
    def _frac(self, t: int) -> float:
        return 0.0 if self.n_iter <= 1 else t / (self.n_iter - 1)

    def alpha(self, t: int) -> float:
        """Step size α(t) at iteration t (eq. 9)."""
        return self.alpha_max - (self.alpha_max - self.alpha_min) * self._frac(t)

    def pa(self, t: int) -> float:
        """Discovery probability Pa(t) at iteration t (eq. 8)."""
        x = self._frac(t)
        span = self.pa_max - self.pa_min
        if self.pa_schedule == "sine":
            return self.pa_max - span * float(np.sin(np.pi * x / 2.0))
        if self.pa_schedule == "linear":
            return self.pa_max - span * x
        if self.pa_schedule == "cosine":
            return self.pa_max - span * (1.0 - float(np.cos(np.pi * x / 2.0)))
        return self.pa_max

    # -- the search ------------------------------------------------------------
    def draw(self, rng: np.random.Generator | RunStreams, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """All random numbers of one time step's search for nests of ``shape`` ``(*b, N, n)``.

        Two draws per run and step, whatever happens in the search (so early
        stopping does not change any run's stream): standard normals
        ``(*b, n_iter, k, N, n)`` (k = 3 with the relative step: Lévy u and v
        and ξ; else 2) and uniforms ``(*b, n_iter, N n + 1 + 2N)`` (the
        discovery s, the scalar r and the keys of the two permutations).
        """
        *batch, N, n = shape
        k = 3 if self.scaling == "relative" else 2
        normals = rng.standard_normal((*batch, self.n_iter, k, N, n))
        uniforms = rng.random((*batch, self.n_iter, N * n + 1 + 2 * N))
        return normals, uniforms

    def run(
        self,
        X: np.ndarray,
        fitness: Callable[[np.ndarray], np.ndarray],
        rng: np.random.Generator | RunStreams,
        F: np.ndarray | None = None,
        trace: list[tuple[np.ndarray, np.ndarray]] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Move the nests ``X`` ``(*b, N, n)`` towards higher fitness.

        Parameters
        ----------
        X
            Nests (particles); not modified.
        fitness
            ``fitness(C) -> (*b, N)``, larger is better.
        rng
            Streams to draw from (RunStreams: one per leading batch index);
            see :meth:`draw`.
        F
            Fitness of ``X`` if already known.
        trace
            If a list, ``(before, after)`` fitness pairs of every greedy
            selection are appended (for tests of the greedy property).

        Returns
        -------
        X, F, stats
            Moved nests, their fitness, and per run the ``iterations`` done
            and the ``accepted`` moves.
        """
        X = np.array(X, dtype=float, copy=True)
        batch = X.shape[:-2]
        F = np.array(fitness(X) if F is None else F, dtype=float, copy=True)
        iterations = np.zeros(batch, dtype=int)
        accepted = np.zeros(batch)
        if self.n_iter == 0:
            return X, F, {"iterations": iterations, "accepted": accepted}
        normals, uniforms = self.draw(rng, X.shape)
        log_stop = None if self.f_stop is None else float(np.log(self.f_stop))
        f_prev = None
        active = None
        for t in range(self.n_iter):
            if log_stop is not None:
                active = F.max(axis=-1) < log_stop
                if not active.any():
                    break
            X, F, f_prev, acc = self._iterate(t, X, F, f_prev, fitness, normals[..., t, :, :, :], uniforms[..., t, :], active, trace)
            step = np.ones(batch, dtype=int) if active is None else active.astype(int)
            iterations += step
            accepted += acc
        return X, F, {"iterations": iterations, "accepted": accepted}

    def _iterate(self, t, X, F, f_prev, fit, normals, uniforms, active, trace):
        """One iteration: Lévy flight, greedy, discovery, greedy (runs not ``active`` stay put)."""
        batch = X.shape[:-2]
        N, n = X.shape[-2:]
        a_t = self.alpha(t)
        accepted = np.zeros(batch)
        # step size, with the fitness trend of each nest
        f_start = None
        alpha: float | np.ndarray = a_t
        if self.trend != "off":
            f_start = np.exp(F)
            if f_prev is not None:
                delta = (f_start - f_prev) / (f_prev + _EPS)
                factor = np.exp(-self.kappa * delta) if self.trend == "exp" else 1.0 + self.kappa * delta
                alpha = np.clip(a_t * factor, self.alpha_min, self.alpha_max)[..., None]
        # 1. Lévy flight
        step = _mantegna(normals[..., 0, :, :], normals[..., 1, :, :], self.beta)
        if self.scaling == "relative":
            best = np.argmax(F, axis=-1)
            X_best = np.take_along_axis(X, best[..., None, None], axis=-2)
            step *= X - X_best
            step *= normals[..., 2, :, :]
        elif self.scaling == "std":
            step *= X.std(axis=-2, keepdims=True)
        step *= alpha
        X, F, acc = self._greedy(X, F, X + step, fit, active, trace)
        accepted += acc
        # 2. discovery of alien eggs
        s = uniforms[..., : N * n].reshape(*batch, N, n)
        pa = self.pa(t)
        K = s > pa if self.discovery == "yang" else s < pa
        r = uniforms[..., N * n]
        p1 = np.argsort(uniforms[..., N * n + 1 : N * n + 1 + N], axis=-1)
        p2 = np.argsort(uniforms[..., N * n + 1 + N :], axis=-1)
        diff = gather(X, p1) - gather(X, p2)
        diff *= K
        diff *= r[..., None, None]
        X, F, acc = self._greedy(X, F, X + diff, fit, active, trace)
        accepted += acc
        return X, F, f_start, accepted

    def _greedy(self, X, F, C, fit, active, trace):
        """Keep a candidate only where its fitness is strictly higher."""
        if self.lower is not None or self.upper is not None:
            C = np.clip(C, self.lower, self.upper)
        FC = fit(C)
        better = FC > F  # NaN candidates never win
        if active is not None:
            better &= active[..., None]
        X_new = np.where(better[..., None], C, X)
        F_new = np.where(better, FC, F)
        if trace is not None:
            trace.append((F, F_new))
        return X_new, F_new, better.sum(axis=-1)


def _mantegna(u: np.ndarray, v: np.ndarray, beta: float) -> np.ndarray:
    """L = σ_u u / |v|^(1/β) from standard normals u, v (new array)."""
    L = u * mantegna_sigma(beta)
    a = np.abs(v)
    if beta == 1.5:
        np.square(a, out=a)
        np.cbrt(a, out=a)  # |v|^(2/3) = cbrt(v²), much faster than power
    elif beta == 2.0:
        np.sqrt(a, out=a)
    elif beta != 1.0:
        np.power(a, 1.0 / beta, out=a)
    L /= a
    return L


def _choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name}: must be one of {', '.join(map(repr, choices))}, got {value!r}")


_CS_SEARCH = CuckooSearch(
    alpha_max=0.01, alpha_min=0.01, pa_max=0.25, pa_min=0.25, pa_schedule="constant", trend="off"
)
_ICS_SEARCH = CuckooSearch()


@dataclass(frozen=True)
class CuckooParticleFilter(ParticleFilterBase):
    """A particle filter with cuckoo-search moves (paper P1).

    Parameters
    ----------
    motion, measurement, particles, resampler, name, backend
        See :class:`pursuit.filters.particle.ParticleFilterBase`.
    ess_threshold
        Greedy with ``weight_mode="sequential"`` only: resample when
        ESS < ``ess_threshold``·N (None, the default, means 0.5; 1 resamples
        at almost every step).  Must be None with ``acceptance="mh"``, which
        resamples at every measured step.
    search
        The :class:`CuckooSearch` settings (iterations, schedules, moves).
    acceptance
        ``"mh"`` (default): resample-move with Metropolis–Hastings cuckoo
        moves that keep the posterior (:mod:`pursuit.filters.cuckoo_mh`);
        ``"greedy"``: the paper-literal search, greedy moves on the
        propagated particles weighted by the likelihood alone (module
        docstring; it can diverge).
    weight_mode
        Greedy only.  ``"reset"`` (the greedy default, None): weights are
        the likelihood of the moved particles, no resampling;
        ``"sequential"``: previous weights times the likelihood, resampling
        on low ESS.  Must be None with ``acceptance="mh"``.
    estimate
        ``"mean"`` (default): mean and covariance of the (weighted) moved
        particles; ``"best"`` (greedy only): the best nest, with the weighted
        second moment about it as covariance; ``"weighted"`` (mh only): the
        weighted mean and covariance before resampling and moving.

    Notes
    -----
    Step info adds ``fitness_best`` (the best nest's fitness), ``iterations``
    (cuckoo iterations run) and ``acceptance`` (share of accepted moves).
    With greedy acceptance ``weights_reset`` refers to the final (post-move)
    weights; with MH acceptance ``ess`` and ``weights_reset`` are those of
    the weights before resampling.
    """

    ess_threshold: float | None = None
    search: CuckooSearch = _ICS_SEARCH
    acceptance: str = "mh"
    weight_mode: str | None = None
    estimate: str = "mean"

    compiled_path = "particle:CUCKOO"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.search, CuckooSearch):
            raise TypeError(f"search: expected a CuckooSearch, got {type(self.search).__name__}")
        _choice("acceptance", self.acceptance, ("mh", "greedy"))
        if self.acceptance == "greedy":
            if self.weight_mode is not None:
                _choice("weight_mode", self.weight_mode, ("reset", "sequential"))
            _choice("estimate", self.estimate, ("mean", "best"))
            return
        _choice("estimate", self.estimate, ("mean", "weighted"))
        search = self.search
        bad = [
            ("weight_mode", self.weight_mode is not None, "the weights are uniform after the moves"),
            ("ess_threshold", self.ess_threshold is not None, "resample-move resamples at every measured step"),
            ("step_scaling", search.step_scaling not in (None, "absolute"), "only the absolute Lévy step in noise space is symmetric"),
            ("f_stop", search.f_stop is not None, "a stopping rule on the fitness breaks the move's invariance"),
            ("lower", search.lower is not None, "a box in state space breaks the move's invariance"),
            ("upper", search.upper is not None, "a box in state space breaks the move's invariance"),
        ]
        for field_name, is_set, why in bad:
            if is_set:
                raise ValueError(f'{field_name}: not used with acceptance="mh" ({why}); leave it unset or use acceptance="greedy"')
        motion = self.motion
        if not (callable(getattr(motion, "f", None)) and (hasattr(motion, "noise_factor") or callable(getattr(motion, "cov", None)))):
            raise ValueError(
                f'motion: acceptance="mh" needs an additive Gaussian motion model with f and cov (or noise_factor); '
                f'{type(motion).__name__} has not; use acceptance="greedy"'
            )
        if getattr(motion, "additive_gaussian", True) is False:
            raise ValueError(
                f'motion: acceptance="mh" needs an additive Gaussian motion model x = f(x) + G xi; '
                f'{type(motion).__name__} is not; use acceptance="greedy"'
            )

    @property
    def greedy_ess_threshold(self) -> float:
        """The ESS fraction greedy sequential mode resamples below (``ess_threshold``, 0.5 when None)."""
        return 0.5 if self.ess_threshold is None else float(self.ess_threshold)

    @property
    def mode(self) -> str:
        """The greedy weight mode (``weight_mode``, ``"reset"`` when None)."""
        return "reset" if self.weight_mode is None else self.weight_mode

    def _compiled_unsupported(self) -> str | None:
        if self.acceptance == "greedy" and self.search.step_scaling == "std":
            # the nests' spread is a NumPy pairwise sum; the search amplifies any rounding difference
            return "step_scaling='std'"
        return None

    def _fitness(self, C: np.ndarray, z: np.ndarray, k: int) -> np.ndarray:
        valid = ~np.isnan(z)
        measured = valid.any(axis=-1)
        return self._likelihoods(C, z, k, valid, measured, predicted=False)[1]

    def step(
        self, state: ParticleState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[ParticleState, dict[str, np.ndarray]]:
        """Propagate, weigh, move and estimate (``acceptance`` says in which order)."""
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        z = _prepare_measurement(z, state.batch, k, self.measurement)
        if self._compiled_batch(state):
            return self._compiled_step(state, z, k, dt)
        if self.acceptance == "mh":
            return self._mh_step(state, z, k, dt)
        return self._greedy_step(state, z, k, dt)

    def _mh_step(self, state: ParticleState, z: np.ndarray, k: int, dt: float | None):
        """Resample-move with MH cuckoo moves (:mod:`pursuit.filters.cuckoo_mh`)."""
        rng = state.rng
        work = state.work
        N = self.particles
        X, m, xi, G = propagate_in_noise_space(self.motion, state.particles, k, dt, rng)
        # exactly the bootstrap PF's measurement step, estimate and resampling (ess_threshold=None)
        weighed = self.weigh(X, z, k, None if state.uniform else state.logw, work=work)
        if self.estimate == "weighted":
            mean, cov = weighted_moments(X, weighed.e, weighed.s, work)
        ess = weighed.ess
        need = weighed.measured.copy()
        e_after = np.where(need[..., None], 1.0, weighed.e)
        s_after = np.where(need, float(N), weighed.s)
        info = weighed.info
        # the weighing's log-likelihoods, resampled with the particles, are the fitness of the resampled
        # particles (computed particle by particle, so the same bits): the moves start from them
        ll = np.broadcast_to(weighed.ll, weighed.e.shape)
        (X, m, xi, ll), logw, uniform = self.resample([X, m, xi, ll], weighed, need, rng, work)
        X, xi, F, accepted, proposals = mh_moves(
            self.search, mantegna_sigma(self.search.beta), X, m, xi, G, lambda C: self._fitness(C, z, k), rng, F=ll
        )
        if self.estimate == "mean":
            mean, cov = weighted_moments(X, e_after, s_after, work)
        info["ess"] = ess
        info["resampled"] = need
        info["fitness_best"] = F.max(axis=-1)
        info["iterations"] = np.full(state.batch, self.search.n_iter, dtype=int)
        info["acceptance"] = accepted / max(proposals, 1)
        return ParticleState(X, logw, mean, cov, rng, k, uniform, work=work), info

    def _greedy_step(self, state: ParticleState, z: np.ndarray, k: int, dt: float | None):
        """The paper-literal step: propagate, greedy search, weigh by the likelihood alone."""
        rng = state.rng
        work = state.work
        N = self.particles
        X = propagate_particles(self.motion, state.particles, k, dt, rng)
        sequential = self.mode == "sequential"
        log_prior = state.logw if sequential and not state.uniform else None
        # predictive statistics and likelihood increment from the propagated particles
        weighed = self.weigh(X, z, k, log_prior, work=work)
        info = weighed.info
        X, F, stats = self.search.run(X, lambda C: self._fitness(C, z, k), rng, F=weighed.ll)
        # weights of the moved particles
        a = F if log_prior is None else log_prior + F
        shifted, mx, e, reset = _exp_shifted(a, log_prior, None)
        s = e.sum(axis=-1)
        ess = s**2 / np.einsum("...i,...i->...", e, e)
        if self.estimate == "mean":
            mean, cov = weighted_moments(X, e, s, work)
        else:
            best = np.argmax(F, axis=-1)
            mean = np.take_along_axis(X, best[..., None, None], axis=-2)[..., 0, :]
            d = X - mean[..., None, :]
            cov = np.einsum("...pi,...pj->...ij", d * (e / s[..., None])[..., None], d)
            cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        logw = shifted - np.log(s)[..., None]
        uniform = False
        need = np.zeros(state.batch, dtype=bool)
        if sequential:
            moved = Weighed(shifted, mx, e, s, F, 0.0, weighed.measured, {})
            need = moved.measured & (ess < self.greedy_ess_threshold * N)
            if need.any():
                (X,), logw, uniform = self.resample([X], moved, need, rng, None)
        info["weights_reset"] = reset
        info["ess"] = ess
        info["resampled"] = need
        info["fitness_best"] = F.max(axis=-1)
        info["iterations"] = stats["iterations"]
        info["acceptance"] = stats["accepted"] / (2.0 * N * np.maximum(stats["iterations"], 1))
        return ParticleState(X, logw, mean, cov, rng, k, uniform, work=work), info


@dataclass(frozen=True)
class CSPF(CuckooParticleFilter):
    """CS-PF: cuckoo-search PF with fixed α = 0.01 and Pa = 0.25 (paper P1's baseline).

    Same as :class:`CuckooParticleFilter` with the search
    ``CuckooSearch(alpha 0.01, Pa 0.25, constant schedules, no trend)`` and
    ``n_iter`` = 10 like ICS-PF, so cost comparisons are fair.
    """

    search: CuckooSearch = _CS_SEARCH

    def _default_name(self) -> str:
        return "CS-PF"


@dataclass(frozen=True)
class ICSPF(CuckooParticleFilter):
    """ICS-PF: improved cuckoo-search PF (paper P1).

    Shrinking α (0.5 → 0.01) and Pa (0.3 → 0.01, sine) over the iterations
    and the fitness-trend step factor; see the module docstring.
    """

    search: CuckooSearch = _ICS_SEARCH

    def _default_name(self) -> str:
        return "ICS-PF"
