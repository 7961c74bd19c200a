"""Glue between the partial unscented particle filter and its compiled kernel (imports numba).

:func:`upf_step` is what ``PartialUPF.step`` calls when the filter computes
with numba: it packs the filter's public state (particles, per-particle
covariances, log-weights) and its full-rank motion model
(``PartialUPF.model``), the unscented transform (``PartialUPF.ukf``'s
``sigma_weights``) and the transition density, runs
:mod:`pursuit._compiled.upf_kernels`, and builds the same
``ParticleState`` and info keys as the NumPy step.  The kernel draws from
each run's own PCG64 stream; where the runs cannot draw themselves (one
Generator shared by the batch, or streams that are not PCG64) the step is
the NumPy one (``PartialUPF.numpy_step``), which gives the same numbers.

Reached only through ``PartialUPF.compiled_path`` (:data:`UPF`); uses only
the filter's public API.
"""

from __future__ import annotations

import numpy as np

from ..filters.base import CompiledPath
from ..filters.particle import ParticleState
from . import upf_kernels as UK
from .kernel_args import Draws, Motion, PFOptions, PFOutputs, UPFArgs, UPFOutputs
from .particle import RESAMPLER_CODES, _step_info, flat_batch, measurement_args, run_stream_addresses, use_parallel
from .specs import MeasurementSpec, MotionSpec, motion_spec

__all__ = ["upf_step", "UPF"]

_SELECT = {"weight": UK.SELECT_WEIGHT, "random": UK.SELECT_RANDOM, "block": UK.SELECT_BLOCK}


def _transition(Q: np.ndarray) -> tuple[np.ndarray, float]:
    """``(chol(Q)⁻¹, Σ log diag chol Q)``: the transition density's factor, as the NumPy step forms it."""
    L = np.linalg.cholesky(Q)
    return np.ascontiguousarray(np.linalg.inv(L)), float(np.sum(np.log(np.diag(L))))


def _gram_factor(R: np.ndarray, wc: np.ndarray) -> tuple[np.ndarray, bool]:
    """chol R and whether the Joseph form is the Gram matrix (wc ≥ 0 and R factors), as the NumPy UKF decides."""
    if not np.all(wc >= 0):
        return np.zeros_like(R), False
    try:
        return np.ascontiguousarray(np.linalg.cholesky(R)), True
    except np.linalg.LinAlgError:
        return np.zeros_like(R), False


def upf_step(filt, specs: tuple[MotionSpec, MeasurementSpec], state: ParticleState, z: np.ndarray, k: int, dt):
    """One compiled partial-UPF step; same result layout as ``PartialUPF.numpy_step``."""
    _, hs = specs
    work = state.work
    rng = state.rng
    addrs, per_run = run_stream_addresses(rng, work)
    if not per_run:  # the NumPy draw order runs across the batch: the NumPy step, same numbers
        return filt.numpy_step(state, z, k, dt)
    ms = motion_spec(filt.model)  # the full-rank model the filter uses (the filter checked it compiles)
    batch, B = flat_batch(state.particles)
    N, n = state.particles.shape[-2:]
    m = hs.dim
    X = np.ascontiguousarray(state.particles, dtype=float).reshape(B, N, n)
    P = np.ascontiguousarray(state.particle_cov, dtype=float).reshape(B, N, n, n)
    logw = np.ascontiguousarray(state.logw, dtype=float).reshape(B, N)
    zf = np.ascontiguousarray(z, dtype=float).reshape(B, m)
    valid = ~np.isnan(zf)
    Q = np.ascontiguousarray(ms.cov(k, dt))
    Qi, Qld = _transition(Q)
    cscale, wm, wc = filt.ukf.sigma_weights(n)
    Rc, gram = _gram_factor(hs.R, wc)
    P0 = np.ascontiguousarray(np.broadcast_to(np.asarray(state.memory, dtype=float), (*batch, n, n))).reshape(B, n, n)
    args = UPFArgs(
        filt.n_ukf, _SELECT[filt.select], bool(state.uniform), UK.COV_CODES[filt.cov_mode], float(cscale),
        np.ascontiguousarray(wm, dtype=float), np.ascontiguousarray(wc, dtype=float), Q, Qi, Qld, Rc, gram, P0,
    )
    thr = -1.0 if filt.ess_threshold is None else float(filt.ess_threshold)
    Xout, logw_out = np.empty((B, N, n)), np.empty((B, N))
    Pout = np.empty((B, N, n * n))
    mean, cov = np.empty((B, n)), np.empty((B, n, n))
    innov, S = np.empty((B, m)), np.empty((B, m, m))
    nis, loglik, ess = np.empty(B), np.empty(B), np.empty(B)
    dof = np.empty(B, dtype=np.int64)
    reset, need, repaired = np.empty(B, dtype=np.bool_), np.empty(B, dtype=np.bool_), np.empty(B, dtype=np.bool_)
    out = PFOutputs(Xout, logw_out, mean, cov, innov, S, nis, dof, loglik, reset, ess, need)
    kernel = UK.upf_step_parallel if use_parallel(B) else UK.upf_step_serial
    kernel(
        (X, P, logw), (zf, valid), Draws(addrs, True), Motion(ms.kind, *ms.arrays(k, dt)), measurement_args(hs), args,
        PFOptions(RESAMPLER_CODES[filt.resampler], thr), out, UPFOutputs(Pout, repaired),
    )
    info = _step_info(batch, m, innov, S, nis, dof, loglik, reset, ess, need)
    info["n_ukf"] = np.full(batch, filt.n_ukf)
    info["repaired"] = repaired.reshape(batch)
    new = ParticleState(
        Xout.reshape(*batch, N, n), logw_out.reshape(*batch, N), mean.reshape(*batch, n), cov.reshape(*batch, n, n),
        rng, k, bool(need.all()), Pout.reshape(*batch, N, n, n), state.memory, work,
    )
    return new, info


UPF = CompiledPath(step=upf_step)
"""The compiled partial UPF (``PartialUPF.compiled_path``); stepped from Python, no whole-sequence path."""
