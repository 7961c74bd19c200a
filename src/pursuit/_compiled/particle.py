"""Glue between the particle filters and their compiled kernels (imports numba).

:func:`bootstrap_step` is what ``BootstrapParticleFilter.step`` calls when
the filter computes with numba: it prepares contiguous arrays and the random
streams, runs :mod:`pursuit._compiled.pf_kernels`, and builds the same
``ParticleState`` and info keys as the NumPy step.  :func:`bootstrap_sequence`
is what ``BootstrapParticleFilter.run_sequence`` calls: every step of every
run in one kernel call, returned in :class:`pursuit.Track`'s layout.

The filters reach this module only through their ``compiled_path``
(:data:`BOOTSTRAP`, :data:`CUCKOO`, loaded by
:func:`pursuit.compute.compiled_implementation`); it uses only the filters'
public API.
"""

from __future__ import annotations

import os
import threading
from typing import Any

import numpy as np

from ..filters.base import CompiledPath
from ..filters.cuckoo import mantegna_sigma
from ..filters.cuckoo_mh import mh_layout, propagate_in_noise_space
from ..filters.particle import ParticleState, propagate_particles, rows_rng
from ..filters.workspace import memo, recycled, scratch
from ..rng import RunStreams
from . import pf_kernels as K
from .common import R_MULTINOMIAL, R_RESIDUAL, R_STRATIFIED, R_SYSTEMATIC
from .kernel_args import CuckooOptions, CuckooOutputs, Draws, MHOptions, Motion, PFOptions, PFOutputs, SearchArgs, Sensor
from .specs import MeasurementSpec, MotionSpec
from .streams import stream_addresses

__all__ = [
    "bootstrap_step",
    "bootstrap_sequence",
    "cuckoo_step",
    "run_stream_addresses",
    "use_parallel",
    "RESAMPLER_CODES",
    "measurement_args",
    "BOOTSTRAP",
    "CUCKOO",
]

RESAMPLER_CODES = {
    "systematic": R_SYSTEMATIC,
    "stratified": R_STRATIFIED,
    "multinomial": R_MULTINOMIAL,
    "residual": R_RESIDUAL,
}


def _parallel_allowed(environ=os.environ) -> bool:
    """``PURSUIT_NUMBA_PARALLEL``: ``1`` (the default) lets batches run on numba's threads, ``0`` keeps every kernel serial.

    The parallel builds are the same source as the serial ones (``common.serial_and_parallel``) and
    give the same bits; they cost about four times the serial build's compile time (numba's
    parallel passes), which is most of a cold cache's compile time.  ``0`` skips them: one thread,
    no parallel compiles (``make test`` sets it; ``make test-slow`` checks the parallel builds
    against the serial ones, docs/compiled-backend.md#threads).
    """
    value = environ.get("PURSUIT_NUMBA_PARALLEL", "1").strip()
    if value not in ("0", "1"):
        raise ValueError(f"environment variable PURSUIT_NUMBA_PARALLEL: expected 0 or 1, got {value!r}")
    return value == "1"


PARALLEL = _parallel_allowed()


def use_parallel(runs: int) -> bool:
    """Parallel kernels only where allowed (:data:`PARALLEL`), from the main thread (numba's default
    threading layer is not re-entrant) and for > 1 run."""
    return PARALLEL and runs > 1 and threading.current_thread() is threading.main_thread()


_NO_STREAMS = np.zeros(1, dtype=np.uint64)


def run_stream_addresses(rng: Any, work) -> tuple[np.ndarray, bool]:
    """``(state addresses, per_run)``: the runs' PCG64 states for the kernels to draw from.

    ``per_run`` is False where the kernels cannot draw themselves (one
    Generator shared by the batch, or streams that are not distinct PCG64
    generators; see :func:`pursuit._compiled.streams.stream_addresses`): the
    caller then draws with NumPy, in the NumPy filter's order.
    """
    if not isinstance(rng, RunStreams):
        return _NO_STREAMS, False
    addrs = memo(work, "compiled.streams", rng, lambda: stream_addresses(rng.generators))
    return (_NO_STREAMS, False) if addrs is None else (addrs, True)


def measurement_args(hs: MeasurementSpec) -> Sensor:
    """The measurement model packed for the kernels."""
    return hs.kernel_args()


def flat_batch(state_particles: np.ndarray) -> tuple[tuple[int, ...], int]:
    """Batch shape and the number of runs B of a particle array (*batch, N, n)."""
    batch = state_particles.shape[:-2]
    return batch, int(np.prod(batch, dtype=int))


def _resample_with_numpy_draws(rng, need: np.ndarray, rkind: int, N: int, logw_out: np.ndarray, Xout: np.ndarray) -> None:
    """Resample the runs flagged in ``need`` with uniforms drawn by NumPy (only those runs' streams), in NumPy's order."""
    if not need.any():
        return
    rows = np.flatnonzero(need)
    U = np.zeros((need.size, K.n_uniforms(rkind, N)))
    U[rows] = rows_rng(rng, rows).random((rows.size, U.shape[1]))
    kernel = K.pf_resample_parallel if use_parallel(need.size) else K.pf_resample_serial
    kernel(logw_out, need, U, rkind, Xout)


def _step_info(batch, m, innov, S, nis, dof, loglik, reset, ess, need) -> dict[str, np.ndarray]:
    """The info keys every particle filter step reports, reshaped to ``batch`` (``(T, *batch)`` for a whole sequence)."""
    return {
        "innovation": innov.reshape(*batch, m),
        "S": S.reshape(*batch, m, m),
        "nis": nis.reshape(batch),
        "dof": dof.reshape(batch),
        "loglik": loglik.reshape(batch),
        "weights_reset": reset.reshape(batch),
        "ess": ess.reshape(batch),
        "resampled": need.reshape(batch),
    }


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
    addrs, per_run = run_stream_addresses(rng, work)
    if per_run:
        noise = scratch(work, "compiled.noise", (B, N * q))
    else:  # the NumPy filter's draw, in its order, for the whole batch
        noise = np.ascontiguousarray(rng.standard_normal((*batch, N, q)).reshape(B, N * q))
    rkind = RESAMPLER_CODES[filt.resampler]
    thr = -1.0 if filt.ess_threshold is None else float(filt.ess_threshold)
    # the particle arrays are large: reuse those of the step before last when they are free (no page faults)
    Xout = recycled(work, "compiled.particles", (B, N, n))
    logw_out = recycled(work, "compiled.logw", (B, N))
    mean, cov = np.empty((B, n)), np.empty((B, n, n))
    innov, S = np.empty((B, m)), np.empty((B, m, m))
    nis, loglik, ess = np.empty(B), np.empty(B), np.empty(B)
    dof = np.empty(B, dtype=np.int64)
    reset, need = np.empty(B, dtype=np.bool_), np.empty(B, dtype=np.bool_)
    kernel = K.pf_step_parallel if use_parallel(B) else K.pf_step_serial
    kernel(
        (X, logw), noise, (zf, valid), Draws(addrs, per_run), Motion(ms.kind, F, G, par), measurement_args(hs), PFOptions(rkind, thr),
        PFOutputs(Xout, logw_out, mean, cov, innov, S, nis, dof, loglik, reset, ess, need),
    )
    if not per_run:
        _resample_with_numpy_draws(rng, need, rkind, N, logw_out, Xout)
    info = {
        **_step_info(batch, m, innov, S, nis, dof, loglik, reset, ess, need),
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


def bootstrap_sequence(filt, specs: tuple[MotionSpec, MeasurementSpec], state: ParticleState, zs: np.ndarray, keep_cov: bool):
    """All steps of ``zs (T, *batch, m)`` in one compiled call, or ``None`` where the runs cannot draw themselves.

    The same bits as T calls of :func:`bootstrap_step` (the kernel runs the
    same step body, run by run, in the same draw order), returned as
    ``(means, covs, info)`` with time first, the layout of
    :class:`pursuit.Track`.  Each run's stream is left where T steps would
    leave it.
    """
    ms, hs = specs
    batch, B = flat_batch(state.particles)
    N, n = state.particles.shape[-2:]
    m = hs.dim
    T = zs.shape[0]
    addrs, per_run = run_stream_addresses(state.rng, state.work)
    if not per_run or T == 0:
        return None
    X0 = np.ascontiguousarray(state.particles, dtype=float).reshape(B, N, n)
    logw0 = np.ascontiguousarray(state.logw, dtype=float).reshape(B, N)
    zf = np.ascontiguousarray(zs, dtype=float).reshape(T, B, m)
    valid = ~np.isnan(zf)
    motion = ms.sequence_args(T)
    q = motion.G.shape[2] if ms.kind == 0 else 1
    noise = np.empty((B, N * q))
    buffers = (np.empty((2, B, N, n)), np.empty((2, B, N)))  # step k reads one, writes the other
    means = np.empty((T, B, n))
    covs = np.empty((T if keep_cov else 1, B, n, n))
    innov, S = np.empty((T, B, m)), np.empty((T, B, m, m))
    nis, loglik, ess = np.empty((T, B)), np.empty((T, B)), np.empty((T, B))
    dof = np.empty((T, B), dtype=np.int64)
    reset, need = np.empty((T, B), dtype=np.bool_), np.empty((T, B), dtype=np.bool_)
    kernel = K.pf_sequence_parallel if use_parallel(B) else K.pf_sequence_serial
    opts = PFOptions(RESAMPLER_CODES[filt.resampler], -1.0 if filt.ess_threshold is None else float(filt.ess_threshold))
    kernel(
        (X0, logw0), noise, (zf, valid), Draws(addrs, True), motion, measurement_args(hs), opts, buffers,
        PFOutputs(buffers[0], buffers[1], means, covs, innov, S, nis, dof, loglik, reset, ess, need), keep_cov,
    )
    info = _step_info((T, *batch), m, innov, S, nis, dof, loglik, reset, ess, need)
    return means.reshape(T, *batch, n), covs.reshape(T, *batch, n, n) if keep_cov else None, info


def cuckoo_step(filt, specs: tuple[MotionSpec, MeasurementSpec], state: ParticleState, z: np.ndarray, k: int, dt):
    """One compiled CS-PF / ICS-PF step; same result layout as ``CuckooParticleFilter.step``."""
    from . import cuckoo_kernels as CK

    if filt.acceptance == "mh":
        return _mh_step(filt, specs, state, z, k, dt)

    ms, hs = specs
    search = filt.search
    batch, B = flat_batch(state.particles)
    N, n = state.particles.shape[-2:]
    m = hs.dim
    work = state.work
    rng = state.rng
    Xp = np.ascontiguousarray(propagate_particles(filt.motion, state.particles, k, dt, rng), dtype=float).reshape(B, N, n)
    logw = np.ascontiguousarray(state.logw, dtype=float).reshape(B, N)
    zf = np.ascontiguousarray(z, dtype=float).reshape(B, m)
    valid = ~np.isnan(zf)
    kk = 3 if search.scaling == "relative" else 2
    n_norm = search.n_iter * kk * N * n
    n_unif = search.n_iter * (N * n + 1 + 2 * N)
    addrs, per_run = run_stream_addresses(rng, work)
    if per_run:
        normals = scratch(work, "compiled.cuckoo.normals", (B, n_norm))
        uniforms = scratch(work, "compiled.cuckoo.uniforms", (B, n_unif))
    elif search.n_iter > 0:  # the NumPy filter's draws, in its order, for the whole batch
        normals = np.ascontiguousarray(rng.standard_normal((*batch, n_norm)).reshape(B, n_norm))
        uniforms = np.ascontiguousarray(rng.random((*batch, n_unif)).reshape(B, n_unif))
    else:
        normals, uniforms = np.empty((B, 0)), np.empty((B, 0))
    sequential = filt.mode == "sequential"
    # an angle model's fitness always carries the normalising constant; the kernels add it, run by run,
    # where a run has a missing component (the NumPy fitness's choice, made per run)
    include_const = bool(hs.angle)
    rkind = RESAMPLER_CODES[filt.resampler]
    out = _cuckoo_outputs(B, N, n, m)
    pf = out.pf
    kernel = CK.cuckoo_step_parallel if use_parallel(B) else CK.cuckoo_step_serial
    opts = CuckooOptions(bool(state.uniform), sequential, include_const, filt.estimate == "best", rkind, filt.greedy_ess_threshold)
    kernel((Xp, logw), (normals, uniforms, Draws(addrs, per_run)), (zf, valid), measurement_args(hs), _search_args(search, n), opts, out)
    if not per_run:
        _resample_with_numpy_draws(rng, pf.need, rkind, N, pf.logw, pf.particles)
    info = _cuckoo_info(batch, m, out, out.accepted / (2.0 * N * np.maximum(out.iterations, 1)))
    return _cuckoo_state(batch, out, rng, k, bool(sequential and pf.need.all()), work), info


def _cuckoo_outputs(B: int, N: int, n: int, m: int) -> CuckooOutputs:
    """Fresh output buffers of a compiled CS-PF / ICS-PF step (greedy or MH) for B runs."""
    pf = PFOutputs(
        np.empty((B, N, n)), np.empty((B, N)), np.empty((B, n)), np.empty((B, n, n)), np.empty((B, m)), np.empty((B, m, m)),
        np.empty(B), np.empty(B, dtype=np.int64), np.empty(B), np.empty(B, dtype=np.bool_), np.empty(B), np.empty(B, dtype=np.bool_),
    )
    return CuckooOutputs(pf, np.empty(B), np.empty(B, dtype=np.int64), np.empty(B, dtype=np.int64))


def _cuckoo_info(batch: tuple[int, ...], m: int, out: CuckooOutputs, acceptance: np.ndarray) -> dict[str, np.ndarray]:
    """The step info of a compiled CS-PF / ICS-PF step: the PF's keys and the search's."""
    pf = out.pf
    return {
        **_step_info(batch, m, pf.innov, pf.S, pf.nis, pf.dof, pf.loglik, pf.reset, pf.ess, pf.need),
        "fitness_best": out.fitness_best.reshape(batch),
        "iterations": out.iterations.reshape(batch),
        "acceptance": np.asarray(acceptance).reshape(batch),
    }


def _cuckoo_state(batch: tuple[int, ...], out: CuckooOutputs, rng, k: int, uniform: bool, work) -> ParticleState:
    """The filter state after a compiled CS-PF / ICS-PF step."""
    pf = out.pf
    N, n = pf.particles.shape[1:]
    return ParticleState(
        pf.particles.reshape(*batch, N, n), pf.logw.reshape(*batch, N), pf.mean.reshape(*batch, n), pf.cov.reshape(*batch, n, n),
        rng, k, uniform, work=work,
    )


def _search_args(search, n: int) -> SearchArgs:
    """The search's schedules and switches packed for the kernels."""
    from . import cuckoo_kernels as CK

    alphas = np.array([search.alpha(t) for t in range(search.n_iter)] or [0.0])
    pas = np.array([search.pa(t) for t in range(search.n_iter)] or [0.0])
    trend = {"off": CK.TREND_OFF, "exp": CK.TREND_EXP, "linear": CK.TREND_LINEAR}[search.trend]
    scaling = {"relative": CK.SCALE_RELATIVE, "absolute": CK.SCALE_ABSOLUTE, "std": CK.SCALE_STD}[search.scaling]
    lower = np.full(n, -np.inf) if search.lower is None else np.broadcast_to(np.asarray(search.lower, float), (n,)).copy()
    upper = np.full(n, np.inf) if search.upper is None else np.broadcast_to(np.asarray(search.upper, float), (n,)).copy()
    use_stop = search.f_stop is not None
    log_stop = float(np.log(search.f_stop)) if use_stop else 0.0
    return SearchArgs(
        search.n_iter, alphas, pas, float(search.alpha_min), float(search.alpha_max), trend, float(search.kappa),
        float(search.beta), mantegna_sigma(search.beta), scaling, search.discovery == "yang", log_stop, use_stop, lower, upper,
    )


def _mh_step(filt, specs: tuple[MotionSpec, MeasurementSpec], state: ParticleState, z: np.ndarray, k: int, dt):
    """One compiled CS-PF / ICS-PF step with ``acceptance="mh"``; same result layout as the NumPy step.

    ξ, m = f(x_{k−1}) and the propagated particles come from the NumPy code
    (:func:`pursuit.filters.cuckoo_mh.propagate_in_noise_space`); the kernel
    weighs, resamples and moves, drawing the resampler's uniforms and the
    moves' numbers from each run's stream (or the caller draws them with
    NumPy, in the NumPy filter's order, where the runs cannot draw themselves).
    """
    from . import cuckoo_kernels as CK

    _, hs = specs
    search = filt.search
    batch, B = flat_batch(state.particles)
    N, n = state.particles.shape[-2:]
    m = hs.dim
    work = state.work
    rng = state.rng
    Xp, Mp, XI, G = propagate_in_noise_space(filt.motion, state.particles, k, dt, rng)
    r = G.shape[1]
    Xp = np.ascontiguousarray(Xp, dtype=float).reshape(B, N, n)
    Mp = np.ascontiguousarray(Mp, dtype=float).reshape(B, N, n)
    XI = np.ascontiguousarray(XI, dtype=float).reshape(B, N, r)
    logw = np.ascontiguousarray(state.logw, dtype=float).reshape(B, N)
    zf = np.ascontiguousarray(z, dtype=float).reshape(B, m)
    valid = ~np.isnan(zf)
    rkind = RESAMPLER_CODES[filt.resampler]
    nu = K.n_uniforms(rkind, N)
    n_norm = search.n_iter * 2 * N * r
    n_unif = search.n_iter * mh_layout(N, r)[-1]
    addrs, per_run = run_stream_addresses(rng, work)
    if per_run:
        ures = scratch(work, "compiled.mh.resample", (B, nu))
        normals = scratch(work, "compiled.mh.normals", (B, n_norm))
        uniforms = scratch(work, "compiled.mh.uniforms", (B, n_unif))
    else:  # the NumPy filter's draws, in its order: the resampler's (runs with a measurement), then the moves'
        ures = np.zeros((B, nu))
        rows = np.flatnonzero(valid.any(axis=1))
        if rows.size:
            ures[rows] = rows_rng(rng, rows).random((rows.size, nu))
        if search.n_iter > 0:
            normals = np.ascontiguousarray(rng.standard_normal((*batch, n_norm)).reshape(B, n_norm))
            uniforms = np.ascontiguousarray(rng.random((*batch, n_unif)).reshape(B, n_unif))
        else:
            normals, uniforms = np.empty((B, 0)), np.empty((B, 0))
    # an angle model's fitness always carries the normalising constant; the kernels add it, run by run,
    # where a run has a missing component (the NumPy fitness's choice, made per run)
    include_const = bool(hs.angle)
    out = _cuckoo_outputs(B, N, n, m)
    kernel = CK.mh_step_parallel if use_parallel(B) else CK.mh_step_serial
    opts = MHOptions(include_const, filt.estimate == "weighted", rkind)
    kernel(
        (Xp, Mp, XI, logw), (ures, normals, uniforms), Draws(addrs, per_run), (zf, valid), G, measurement_args(hs),
        _search_args(search, n), opts, out.pf, (out.fitness_best, out.iterations, out.accepted),
    )
    h = N // 2
    proposals = search.n_iter * (N + (h if N - h >= 2 else 0) + ((N - h) if h >= 2 else 0))
    info = _cuckoo_info(batch, m, out, out.accepted / max(proposals, 1))
    return _cuckoo_state(batch, out, rng, k, bool(out.pf.need.all()), work), info


BOOTSTRAP = CompiledPath(step=bootstrap_step, sequence=bootstrap_sequence)
"""The compiled bootstrap PF (``BootstrapParticleFilter.compiled_path``)."""

CUCKOO = CompiledPath(step=cuckoo_step)
"""The compiled CS-PF / ICS-PF (``CuckooParticleFilter.compiled_path``); no whole-sequence path."""
