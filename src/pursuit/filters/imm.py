"""Interacting multiple model (IMM) filter over any set of model-matched filters.

The IMM runs r filters (modes) in parallel and mixes their estimates through
a Markov chain of mode switches with transition matrix Π (``Π[i, j]`` =
P{mode j at k | mode i at k − 1}).  One cycle [LIT] (docs/spec/04-adaptive-cs-model.md §4.3):

* predicted mode probabilities ``c̄_j = Σ_i Π_ij μ_i`` and mixing weights
  ``μ_{i|j} = Π_ij μ_i / c̄_j``;
* mixed initial condition per mode, ``x̂_0j = Σ_i μ_{i|j} x̂_i``,
  ``P_0j = Σ_i μ_{i|j} [P_i + (x̂_i − x̂_0j)(·)ᵀ]``;
* each mode's own ``step`` from its mixed state, giving its innovation
  log-likelihood ``log Λ_j``;
* ``μ_j ∝ c̄_j Λ_j`` and the output ``x̂ = Σ_j μ_j x̂_j``,
  ``P = Σ_j μ_j [P_j + (x̂_j − x̂)(·)ᵀ]``.

Modes may have different state vectors: a :class:`StateMap` places each
mode's state inside the IMM's common state (usually the largest), and the
components a mode lacks are filled with a fixed mean and variance (zero
acceleration for a constant-velocity mode inside a constant-acceleration
state, the textbook augmentation).

Info keys: the standard ones describe the mixture's predicted measurement,
moment-matched: with ν_j the mode innovations and c̄_j the predicted mode
probabilities, ``innovation = Σ c̄_j ν_j`` (= z − Σ c̄_j ẑ_j) and
``S = Σ c̄_j [S_j + (ν_j − ν)(ν_j − ν)ᵀ]``; ``nis`` and ``loglik`` are
νᵀS⁻¹ν and log N(ν; 0, S) of that Gaussian, as in every filter.  Extra:
``mode_probs`` (*b, r) (μ after the update), ``mode_loglik`` (*b, r),
``mode_nis`` (*b, r) (each mode's NIS from its mixed prior),
``loglik_mixture`` = log Σ_j c̄_j Λ_j, the exact IMM likelihood of the step,
``gated`` (*b,) and ``repaired`` (*b,) (a mode repaired a covariance).

**Gating** (``gate=p``).  The validation region is the union of the modes'
χ² gates [LIT, Bar-Shalom & Li]: a measurement is rejected only where
*every* mode's NIS exceeds the χ²(dof) quantile ``p``.  So a correct
measurement is rejected with probability at most 1 − p whichever mode is
true, and a maneuver onset that only an unlikely maneuvering mode explains
is kept, where a gate on the moment-matched mixture (whose S is far too
small for that mode) would reject it and keep the IMM from switching.  A
rejected step is exactly a step without the measurement: every mode only
predicts from its mixed prior and μ = c̄, while ``innovation``, ``S``,
``nis``, ``dof``, ``loglik``, ``mode_loglik``, ``mode_nis`` and
``loglik_mixture`` describe the rejected measurement.  (A step where some
run is rejected runs the modes a second time, with the rejected runs'
measurements set missing.)  Mode filters may carry gates of their own.

One run without a batch axis (batch ``()``) takes
:meth:`InteractingMultipleModel._one_run_step`: the same cycle on the modes
stacked as ``(r, n)`` and ``(r, n, n)`` arrays, without einsum, each mode
taking its own one-run step; equal to the general step to round-off.  A
batch ``(1,)`` takes the general step (a run's bits do not depend on its batch).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from .._linalg import inv_spd, logdet_spd, quad, small_inv_logdet, symmetrize
from .._validation import in_range, time_step
from ..gaussian import Gaussian
from ..rng import RNGLike
from .base import FilterBase, as_gaussian, prior_batch
from .cs import AxisState
from .gating import gate_exceeded
from .gaussian import GaussianState

__all__ = ["StateMap", "IMMState", "InteractingMultipleModel", "kinematic_map"]

_LOG_2PI = float(np.log(2.0 * np.pi))
_PLAIN_STATES = (GaussianState, AxisState)


@dataclass(frozen=True)
class StateMap:
    """Where a mode's state sits inside the IMM's common state.

    Parameters
    ----------
    indices
        For each component of the mode's state, its index in the common
        state.
    dim
        Dimension of the common state.
    fill_mean, fill_var
        Mean and variance given to the common components the mode does not
        have (scalars or ``(dim − len(indices),)`` vectors, in increasing
        index order), uncorrelated with the rest.
    """

    indices: tuple[int, ...]
    dim: int
    fill_mean: Any = 0.0
    fill_var: Any = 0.0

    def __post_init__(self) -> None:
        idx = tuple(int(i) for i in self.indices)
        if len(set(idx)) != len(idx) or any(i < 0 or i >= self.dim for i in idx):
            raise ValueError(f"indices: must be distinct indices in [0, {self.dim}), got {idx}")
        object.__setattr__(self, "indices", idx)
        missing = np.array([i for i in range(self.dim) if i not in idx], dtype=int)
        fm = np.broadcast_to(np.asarray(self.fill_mean, dtype=float), missing.shape).copy()
        fv = np.broadcast_to(np.asarray(self.fill_var, dtype=float), missing.shape).copy()
        if not (np.all(np.isfinite(fm)) and np.all(np.isfinite(fv))) or np.any(fv < 0):
            raise ValueError("fill_mean, fill_var: must be finite, variances non-negative")
        object.__setattr__(self, "_missing", missing)
        object.__setattr__(self, "_fill_mean", fm)
        object.__setattr__(self, "_fill_var", fv)

    def to_mode(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Common-state Gaussian to the mode's components (a marginal)."""
        i = np.array(self.indices)
        return np.ascontiguousarray(mean[..., i]), np.ascontiguousarray(cov[..., i[:, None], i[None, :]])

    def to_common(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mode's Gaussian in the common state, missing components filled."""
        i = np.array(self.indices)
        batch = mean.shape[:-1]
        out_m = np.empty((*batch, self.dim))
        out_m[..., i] = mean
        out_m[..., self._missing] = self._fill_mean
        out_c = np.zeros((*np.broadcast_shapes(batch, cov.shape[:-2]), self.dim, self.dim))
        out_c[..., i[:, None], i[None, :]] = cov
        out_c[..., self._missing, self._missing] = self._fill_var
        return out_m, out_c


def kinematic_map(mode_motion: Any, common_motion: Any, fill_var: float = 0.0) -> StateMap:
    """A :class:`StateMap` matching position, velocity, acceleration and jerk indices of two models.

    Both models must expose ``position_indices`` and ``velocity_indices``
    (and ``acceleration_indices`` / ``jerk_indices`` where they have them),
    e.g. a constant-velocity mode inside a CA or Singer common state.
    """
    pairs = []
    for attr in ("position_indices", "velocity_indices", "acceleration_indices", "jerk_indices"):
        a = getattr(mode_motion, attr, None)
        b = getattr(common_motion, attr, None)
        if a is None:
            continue
        if b is None or len(a) != len(b):
            raise ValueError(f"kinematic_map: the common model has no matching {attr}")
        pairs.extend(zip(a, b))
    n_mode = int(getattr(mode_motion, "dim"))
    if sorted(p for p, _ in pairs) != list(range(n_mode)):
        raise ValueError("kinematic_map: the mode's state is not covered by position/velocity/acceleration indices")
    order = [c for _, c in sorted(pairs)]
    return StateMap(tuple(order), int(getattr(common_motion, "dim")), 0.0, fill_var)


@dataclass(frozen=True)
class IMMState:
    """State of the IMM filter.

    Attributes
    ----------
    mean, cov
        Combined estimate in the common state, ``(*b, n)`` and ``(*b, n, n)``.
    k
        Last step processed.
    modes
        Each mode filter's own state.
    probs
        Mode probabilities μ, ``(*b, r)``.
    """

    mean: np.ndarray
    cov: np.ndarray
    k: int
    modes: tuple[Any, ...]
    probs: np.ndarray

    @property
    def batch(self) -> tuple[int, ...]:
        """Batch shape."""
        return self.mean.shape[:-1]


def _check_transition(P: np.ndarray, r: int) -> np.ndarray:
    P = np.array(P, dtype=float)
    if P.shape != (r, r):
        raise ValueError(f"transition: expected a {r}x{r} matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)) or np.any(P < 0):
        raise ValueError("transition: entries must be finite and non-negative")
    if not np.allclose(P.sum(axis=1), 1.0, rtol=0, atol=1e-9):
        raise ValueError(f"transition: rows must sum to 1, got {P.sum(axis=1)}")
    P = P / P.sum(axis=1, keepdims=True)
    P.setflags(write=False)
    return P


@dataclass(frozen=True)
class InteractingMultipleModel(FilterBase):
    """IMM filter.

    Parameters
    ----------
    filters
        The model-matched filters (any pursuit filters whose states have
        ``mean`` and ``cov`` and whose info has ``loglik``: KF, EKF, UKF,
        CKF, the CS-family filters, ...).
    transition
        ``(r, r)`` Markov transition matrix, rows summing to 1; or a number
        p: ``Π_ii = p``, off-diagonal entries equal.
    initial_probs
        ``(r,)`` initial mode probabilities (default uniform).
    maps
        One :class:`StateMap` (or None for the identity) per filter; default
        all identity (every mode has the common state).
    name
        Label in results (keyword only; default ``"IMM"``).
    gate
        χ² gate probability in (0, 1), keyword only: a measurement outside
        every mode's gate is not used (see the module notes) and the step
        is flagged in ``gated``.  Default: no gate.
    backend
        Keyword only; the IMM itself computes with NumPy (``"numba"`` warns),
        its mode filters each with their own backend.
    """

    filters: Sequence[Any]
    transition: Any = 0.95
    initial_probs: Any = None
    maps: Sequence[StateMap | None] | None = None
    gate: float | None = field(default=None, kw_only=True)

    warn_on_default_backend = False  # no compiled path at all: a process-wide numba default is not a request

    def __post_init__(self) -> None:
        filters = tuple(self.filters)
        r = len(filters)
        if r < 1:
            raise ValueError("filters: the IMM needs at least one model-matched filter")
        for f in filters:
            if not (callable(getattr(f, "init", None)) and callable(getattr(f, "step", None))):
                raise TypeError(f"filters: {type(f).__name__} is not a filter (needs init and step)")
        object.__setattr__(self, "filters", filters)
        if np.ndim(self.transition) == 0:
            p = float(self.transition)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"transition: a staying probability must lie in [0, 1], got {p}")
            T = np.full((r, r), (1.0 - p) / (r - 1) if r > 1 else 0.0)
            np.fill_diagonal(T, p if r > 1 else 1.0)
        else:
            T = self.transition
        object.__setattr__(self, "transition", _check_transition(T, r))
        mu0 = np.full(r, 1.0 / r) if self.initial_probs is None else np.array(self.initial_probs, dtype=float)
        if mu0.shape != (r,) or not np.all(np.isfinite(mu0)) or np.any(mu0 < 0) or not np.isclose(mu0.sum(), 1.0):
            raise ValueError(f"initial_probs: expected {r} non-negative probabilities summing to 1, got {self.initial_probs!r}")
        object.__setattr__(self, "initial_probs", mu0 / mu0.sum())
        maps = (None,) * r if self.maps is None else tuple(self.maps)
        if len(maps) != r:
            raise ValueError(f"maps: expected {r} entries (one per filter), got {len(maps)}")
        dims = {m.dim for m in maps if m is not None}
        if len(dims) > 1:
            raise ValueError(f"maps: all maps must target the same common dimension, got {sorted(dims)}")
        object.__setattr__(self, "maps", maps)
        if self.gate is not None:
            object.__setattr__(self, "gate", in_range("gate", self.gate, 0.0, 1.0, low_open=True, high_open=True))
        super().__post_init__()

    def _default_name(self) -> str:
        return "IMM"

    @property
    def modes(self) -> int:
        """Number of modes r."""
        return len(self.filters)

    # -- helpers --------------------------------------------------------------
    def _to_common(self, j: int, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.maps[j]
        return (mean, cov) if m is None else m.to_common(mean, cov)

    def _to_mode(self, j: int, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.maps[j]
        return (mean, cov) if m is None else m.to_mode(mean, cov)

    def _common(self, states) -> tuple[np.ndarray, np.ndarray]:
        """Mode estimates in the common state, stacked: ``(*b, r, n)``, ``(*b, r, n, n)``."""
        means, covs = [], []
        for j, s in enumerate(states):
            m, c = self._to_common(j, s.mean, s.cov)
            means.append(m)
            covs.append(np.broadcast_to(c, (*m.shape, m.shape[-1])))
        return np.stack(means, axis=-2), np.stack(covs, axis=-3)

    # -- protocol ---------------------------------------------------------------
    def init(self, prior: Gaussian, batch: tuple[int, ...] = (), rng: RNGLike = None) -> IMMState:
        """Every mode starts from the prior (its marginal for smaller modes); μ = initial_probs."""
        prior = as_gaussian(prior)
        batch = prior_batch(prior, batch)
        mean, cov = prior.broadcast(batch)
        for j, m in enumerate(self.maps):
            if m is not None and m.dim != prior.dim:
                raise ValueError(f"prior: dimension {prior.dim} differs from the common state of maps[{j}] ({m.dim})")
        states = []
        for j, f in enumerate(self.filters):
            mj, cj = self._to_mode(j, mean, cov)
            states.append(f.init(Gaussian(mj, cj), batch=batch, rng=rng))
        probs = np.broadcast_to(self.initial_probs, (*batch, self.modes)).copy()
        return IMMState(mean, np.array(cov), 0, tuple(states), probs)

    def step(
        self, state: IMMState, z: np.ndarray, k: int | None = None, dt: float | None = None
    ) -> tuple[IMMState, dict[str, np.ndarray]]:
        """One IMM cycle: mix, run every mode, update μ, combine."""
        k = state.k + 1 if k is None else int(k)
        dt = time_step(dt, k)
        if not state.batch:
            # One run without a batch axis.  A batch (1,) keeps the general step, whose bits equal those
            # of the same run in a larger batch; the one-run maths agrees with it to round-off only.
            return self._one_run_step(state, z, k, dt)
        return self._general_step(state, z, k, dt)

    def _general_step(
        self, state: IMMState, z: np.ndarray, k: int, dt: float | None
    ) -> tuple[IMMState, dict[str, np.ndarray]]:
        """:meth:`step` for any batch, on ``(*b, r, ...)`` stacks through einsum."""
        batch = state.batch
        Pi = self.transition
        mu = state.probs
        c_bar = np.einsum("...i,ij->...j", mu, Pi)  # (*b, r)
        w = mu[..., :, None] * Pi  # (*b, i, j) = Π_ij μ_i
        safe = np.where(c_bar > 0, c_bar, 1.0)
        w = np.where(c_bar[..., None, :] > 0, w / safe[..., None, :], mu[..., :, None])

        X, P = self._common(state.modes)  # (*b, r, n), (*b, r, n, n)
        x0 = np.einsum("...ij,...in->...jn", w, X)  # (*b, j, n)
        d = X[..., :, None, :] - x0[..., None, :, :]  # (*b, i, j, n)
        P0 = np.einsum("...ij,...inm->...jnm", w, P) + np.einsum("...ij,...ijn,...ijm->...jnm", w, d, d)

        mixed = []
        for j in range(self.modes):
            # Contiguous copies keep einsum's summation order independent of the batch.
            xj = np.ascontiguousarray(x0[..., j, :])
            mj, cj = self._to_mode(j, xj, np.ascontiguousarray(symmetrize(P0[..., j, :, :])))
            mixed.append(replace(state.modes[j], mean=mj, cov=cj))
        new_states, infos = self._step_modes(mixed, z, k, dt)
        mode_ll = np.stack([np.broadcast_to(i["loglik"], batch) for i in infos], axis=-1)  # (*b, r)
        mode_nis = np.stack([np.broadcast_to(i["nis"], batch) for i in infos], axis=-1)  # (*b, r)

        gated = np.zeros(batch, dtype=bool)
        used_ll = mode_ll
        mode_infos = list(infos)
        if self.gate is not None:
            dof = np.broadcast_to(infos[0]["dof"], batch)  # the same measured components in every mode
            m = np.shape(infos[0]["innovation"])[-1]
            gated = np.all(gate_exceeded(self.gate, mode_nis, dof[..., None], m), axis=-1)
            if gated.any():
                zb = np.broadcast_to(np.asarray(z, dtype=float), (*batch, m))
                new_states, kept = self._step_modes(mixed, np.where(gated[..., None], np.nan, zb), k, dt)
                used_ll = np.stack([np.broadcast_to(i["loglik"], batch) for i in kept], axis=-1)
                mode_infos += kept

        with np.errstate(divide="ignore"):
            log_prior = np.log(c_bar)
        probs, loglik_mixture = _normalise(log_prior + used_ll)
        if gated.any():  # the likelihood of the rejected measurement, as in the other keys
            loglik_mixture = np.where(gated, _normalise(log_prior + mode_ll)[1], loglik_mixture)

        X, P = self._common(new_states)
        mean = np.einsum("...j,...jn->...n", probs, X)
        d = X - mean[..., None, :]
        cov = symmetrize(np.einsum("...j,...jnm->...nm", probs, P) + np.einsum("...j,...jn,...jm->...nm", probs, d, d))

        info = _mixture_info(infos, c_bar, batch)
        info["mode_probs"] = probs
        info["mode_loglik"] = mode_ll
        info["mode_nis"] = mode_nis
        info["loglik_mixture"] = loglik_mixture
        info["gated"] = gated
        info["repaired"] = np.zeros(batch, dtype=bool)
        for i in mode_infos:
            if "repaired" in i:
                info["repaired"] = info["repaired"] | np.broadcast_to(i["repaired"], batch)
        return IMMState(mean, cov, k, tuple(new_states), probs), info

    def _one_run_step(
        self, state: IMMState, z: np.ndarray, k: int, dt: float | None
    ) -> tuple[IMMState, dict[str, np.ndarray]]:
        """:meth:`_general_step` for one run without a batch axis, the M modes as one stacked array.

        The mixing and the combination are matrix products of the ``(r, n)``
        means and the ``(r, n·n)`` covariances with the weights (the spread
        terms Σ_i w_ij d_ij d_ijᵀ as one stacked product), the mixture's
        S⁻¹ and log det S in closed form for m ≤ 3: no einsum, no broadcast
        to a batch.  Each mode takes its own step of one run.  Same info
        keys, shapes and dtypes as the general step, same numbers to round-off.
        """
        Pi = self.transition
        mu = state.probs
        r = Pi.shape[0]
        c_bar = mu.dot(Pi)
        w = mu[:, None] * Pi  # w[i, j] = Π_ij μ_i
        if c_bar.all():
            w = w / c_bar
        else:  # a mode no one can reach: its mixing weights are μ (as the general step)
            w = np.where(c_bar > 0, w / np.where(c_bar > 0, c_bar, 1.0), mu[:, None])

        X, P = self._common_one(state.modes)  # (r, n), (r, n, n)
        n = X.shape[1]
        x0 = w.T.dot(X)  # (j, n)
        d = X[:, None, :] - x0[None, :, :]  # (i, j, n)
        spread = np.matmul((d * w[:, :, None]).transpose(1, 2, 0), d.transpose(1, 0, 2))  # (j, n, n)
        P0 = w.T.dot(P.reshape(r, n * n)).reshape(r, n, n) + spread
        P0 = symmetrize(P0)
        mixed = []
        for j, s in enumerate(state.modes):
            mj, cj = self._to_mode(j, x0[j], P0[j])
            if type(s) in _PLAIN_STATES:  # their fields are mean, cov, k, memory: dataclasses.replace costs more
                mixed.append(type(s)(mj, cj, s.k, s.memory))
            else:
                mixed.append(replace(s, mean=mj, cov=cj))
        new_states, infos = self._step_modes(mixed, z, k, dt)
        mode_ll = np.array([float(i["loglik"]) for i in infos])
        mode_nis = np.array([float(i["nis"]) for i in infos])

        gated = np.zeros((), dtype=bool)
        used_ll = mode_ll
        mode_infos = list(infos)
        if self.gate is not None:
            dof = np.asarray(infos[0]["dof"])
            m = np.shape(infos[0]["innovation"])[-1]
            gated = np.all(gate_exceeded(self.gate, mode_nis, dof, m))
            if gated:
                new_states, kept = self._step_modes(mixed, np.full(m, np.nan), k, dt)
                used_ll = np.array([float(i["loglik"]) for i in kept])
                mode_infos += kept

        if c_bar.all():
            log_prior = np.log(c_bar)
        else:
            with np.errstate(divide="ignore"):
                log_prior = np.log(c_bar)
        probs, loglik_mixture = _normalise(log_prior + used_ll)
        if gated:  # the likelihood of the rejected measurement, as in the other keys
            loglik_mixture = _normalise(log_prior + mode_ll)[1]

        X, P = self._common_one(new_states)
        mean = probs.dot(X)
        d = X - mean
        cov = symmetrize(probs.dot(P.reshape(r, n * n)).reshape(n, n) + (d.T * probs).dot(d))

        info = _mixture_info_one(infos, c_bar)
        info["mode_probs"] = probs
        info["mode_loglik"] = mode_ll
        info["mode_nis"] = mode_nis
        info["loglik_mixture"] = loglik_mixture
        info["gated"] = gated
        repaired = False
        for i in mode_infos:
            if "repaired" in i:
                repaired = repaired or bool(i["repaired"])
        info["repaired"] = np.array(repaired)
        return IMMState(mean, cov, k, tuple(new_states), probs), info

    def _common_one(self, states) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_common` of one run: ``(r, n)`` and ``(r, n, n)``."""
        means, covs = [], []
        for j, s in enumerate(states):
            m, c = self._to_common(j, s.mean, s.cov)
            means.append(m)
            covs.append(c)
        return np.array(means), np.array(covs)

    def _step_modes(self, mixed, z, k, dt):
        states, infos = [], []
        for f, s0 in zip(self.filters, mixed):
            s, info = f.step(s0, z, k=k, dt=dt)
            states.append(s)
            infos.append(info)
        return states, infos


def _normalise(log_post: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Posterior probabilities and log Σ exp of unnormalised log-probabilities ``(*b, r)``."""
    top = np.max(log_post, axis=-1, keepdims=True)
    e = np.exp(log_post - top)
    total = e.sum(axis=-1, keepdims=True)
    return e / total, (top + np.log(total))[..., 0]


def _mixture_info_one(infos: list[dict[str, np.ndarray]], c_bar: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`_mixture_info` of one run: ``(r, m)`` innovations as plain arrays, S⁻¹ and log det S in closed form for m ≤ 3."""
    nus = np.array([i["innovation"] for i in infos])  # (r, m)
    r, m = nus.shape
    Ss = np.array([i["S"] for i in infos]).reshape(r, m * m)
    valid = ~np.isnan(nus[0])  # the same measurement for every mode
    nus0 = np.where(valid, nus, 0.0)
    nu = c_bar.dot(nus0)
    d = nus0 - nu
    S = symmetrize(c_bar.dot(Ss).reshape(m, m) + (d.T * c_bar).dot(d))
    small = small_inv_logdet(S)
    if small is None:  # m > 3, or a determinant the closed forms cannot trust
        S_inv, logdet = inv_spd(S), float(logdet_spd(S))
    else:
        S_inv, logdet = small
    dof = valid.sum()
    if dof:
        nis = float(nu.dot(S_inv).dot(nu))
        loglik = -0.5 * (nis + logdet + dof * _LOG_2PI)
    else:
        nis, loglik = np.nan, 0.0
    return {
        "innovation": np.where(valid, nu, np.nan),
        "S": S,
        "nis": np.array(nis),
        "dof": dof,
        "loglik": np.array(loglik),
    }


def _mixture_info(infos: list[dict[str, np.ndarray]], c_bar: np.ndarray, batch: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Moment-matched predicted-measurement Gaussian of the modes, weighted by c̄."""
    nus = np.stack([np.broadcast_to(i["innovation"], (*batch, i["innovation"].shape[-1])) for i in infos], axis=-2)
    m = nus.shape[-1]
    Ss = np.stack([np.broadcast_to(i["S"], (*batch, m, m)) for i in infos], axis=-3)
    valid = ~np.isnan(nus[..., 0, :])  # the same measurement for every mode
    nus0 = np.where(valid[..., None, :], nus, 0.0)
    nu = np.einsum("...j,...jm->...m", c_bar, nus0)
    d = nus0 - nu[..., None, :]
    S = symmetrize(np.einsum("...j,...jab->...ab", c_bar, Ss) + np.einsum("...j,...ja,...jb->...ab", c_bar, d, d))
    S_inv = inv_spd(S)
    dof = valid.sum(axis=-1)
    nis = quad(nu, S_inv)
    loglik = -0.5 * (nis + logdet_spd(S) + dof * _LOG_2PI)
    measured = dof > 0
    return {
        "innovation": np.where(valid, nu, np.nan),
        "S": S,
        "nis": np.where(measured, nis, np.nan),
        "dof": dof,
        "loglik": np.where(measured, loglik, 0.0),
    }
