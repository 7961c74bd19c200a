"""Glue between the particle filters and their compiled kernels (imports numba).

:func:`bootstrap_step` is what ``BootstrapParticleFilter.step`` calls when
the filter computes with numba: it prepares contiguous arrays and the random
streams, runs :mod:`pursuit._compiled.pf_kernels`, and builds the same
``ParticleState`` and info keys as the NumPy step.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numba.typed import List

from ..filters._workspace import memo, scratch
from ..filters.particle import ParticleState
from ..rng import RunStreams
from . import pf_kernels as K
from .common import R_MULTINOMIAL, R_RESIDUAL, R_STRATIFIED, R_SYSTEMATIC
from .specs import MeasurementSpec, MotionSpec

__all__ = ["bootstrap_step", "typed_generators", "use_parallel", "RESAMPLER_CODES", "measurement_args"]

RESAMPLER_CODES = {
    "systematic": R_SYSTEMATIC,
    "stratified": R_STRATIFIED,
    "multinomial": R_MULTINOMIAL,
    "residual": R_RESIDUAL,
}


def use_parallel(runs: int) -> bool:
    """Parallel kernels only from the main thread (numba's default threading layer is not re-entrant) and for > 1 run."""
    return runs > 1 and threading.current_thread() is threading.main_thread()


def typed_generators(rng: Any, work) -> tuple[List, bool]:
    """``(typed list of Generators, per_run)``: one per run for RunStreams, else the one shared Generator."""
    per_run = isinstance(rng, RunStreams)
    gens = memo(work, "compiled.generators", rng, lambda: List(rng.generators if per_run else [rng]))
    return gens, per_run


def measurement_args(hs: MeasurementSpec) -> tuple:
    """The measurement model's arguments for the kernels."""
    return hs.kind, hs.A, hs.idx, hs.scale, hs.R, hs.angle


def flat_batch(state_particles: np.ndarray) -> tuple[tuple[int, ...], int]:
    """Batch shape and the number of runs B of a particle array (*batch, N, n)."""
    batch = state_particles.shape[:-2]
    return batch, int(np.prod(batch, dtype=int))


def bootstrap_step(filt, specs: tuple[MotionSpec, MeasurementSpec], state: ParticleState, z: np.ndarray, k: int, dt):
    """One compiled bootstrap-PF step; same result layout as ``BootstrapParticleFilter.step``."""
    ms, hs = specs
    batch, B = flat_batch(state.particles)
    N, n = state.particles.shape[-2:]
    m = hs.dim
    work = state.work
    rng = state.rng
    X = np.ascontiguousarray(state.particles, dtype=float).reshape(B, N, n)
    logw = np.ascontiguousarray(state.logw, dtype=float).reshape(B, N)
    zf = np.ascontiguousarray(z, dtype=float).reshape(B, m)
    valid = ~np.isnan(zf)
    F, G, par = ms.arrays(k, dt)
    q = G.shape[1] if ms.kind == 0 else 1
    gens, per_run = typed_generators(rng, work)
    if per_run:
        noise = scratch(work, "compiled.noise", (B, N * q))
    else:  # the NumPy filter's draw, in its order, for the whole batch
        noise = np.ascontiguousarray(rng.standard_normal((*batch, N, q)).reshape(B, N * q))
    rkind = RESAMPLER_CODES[filt.resampler]
    thr = -1.0 if filt.ess_threshold is None else float(filt.ess_threshold)
    Xout = np.empty((B, N, n))
    logw_out = np.empty((B, N))
    mean, cov = np.empty((B, n)), np.empty((B, n, n))
    innov, S = np.empty((B, m)), np.empty((B, m, m))
    nis, loglik, ess = np.empty(B), np.empty(B), np.empty(B)
    dof = np.empty(B, dtype=np.int64)
    reset, need = np.empty(B, dtype=np.bool_), np.empty(B, dtype=np.bool_)
    kernel = K.pf_step_parallel if use_parallel(B) else K.pf_step_serial
    kernel(
        X, logw, noise, zf, valid, gens, per_run, ms.kind, F, G, par, *measurement_args(hs), rkind, thr,
        Xout, logw_out, mean, cov, innov, S, nis, dof, loglik, reset, ess, need,
    )
    if not per_run and need.any():
        rows = np.flatnonzero(need)
        U = np.zeros((B, K.n_uniforms(rkind, N)))
        U[rows] = rng.random((rows.size, U.shape[1]))
        K.pf_resample_parallel(logw_out, need, U, rkind, Xout)
    info = {
        "innovation": innov.reshape(*batch, m),
        "S": S.reshape(*batch, m, m),
        "nis": nis.reshape(batch),
        "dof": dof.reshape(batch),
        "loglik": loglik.reshape(batch),
        "weights_reset": reset.reshape(batch),
        "ess": ess.reshape(batch),
        "resampled": need.reshape(batch),
    }
    new = ParticleState(
        Xout.reshape(*batch, N, n),
        logw_out.reshape(*batch, N),
        mean.reshape(*batch, n),
        cov.reshape(*batch, n, n),
        rng,
        k,
        bool(need.all()),
        work=work,
    )
    return new, info
