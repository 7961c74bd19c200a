"""Glue between the Kalman-family filters and their compiled lane-major kernels (imports numba).

The filter state keeps the public layout (``mean (M, n)``, ``cov (M, n, n)``)
as transposed *views* of lane-major arrays ``(n, M)`` and ``(n, n, M)``, so
consecutive compiled steps pass their arrays without copying.  Runs whose
covariance does not factor are recomputed with the NumPy step (which
repairs them) and spliced in; every other run never sees NumPy, so a run's
result does not depend on its neighbours.

A KF/EKF with a linear measurement (``H x``) runs the unrolled kernels
generated for its model's structure (:mod:`pursuit._compiled.kf_codegen`),
for the step path and the whole-sequence path alike, so both give the same
bits; other measurements run the block kernels of
:mod:`pursuit._compiled.gauss_kernels`.

One run stepped from Python (batch ``()`` or ``(1,)``) takes the online
lane of :mod:`pursuit._compiled.online` first (the same kernels, a fraction
of the Python around them), and this step where that lane does not apply.

The filters reach this module only through their ``compiled_path``
(:data:`EKF`, :data:`SIGMA`, :data:`CS`, loaded by :func:`pursuit.compute.compiled_implementation`);
it uses only the filters' public API.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ..filters.base import CompiledPath
from ..filters.gating import apply_gate
from ..filters.gaussian import GaussianState
from ..gaussian import Gaussian
from . import gauss_kernels as GK
from . import generated, kf_codegen
from .kernel_args import GaussOutputs, GaussSequenceOutputs, GaussUpdateOutputs, Prediction, SigmaPoints
from .online import online_lane
from .particle import measurement_args, use_parallel
from .specs import M_LINEAR, frozen

__all__ = ["gaussian_step", "gaussian_sequence", "cs_step", "lanes", "EKF", "SIGMA", "CS"]


def lanes(a: np.ndarray, core: int) -> np.ndarray:
    """Lane-major contiguous copy (or the underlying array) of ``a (M, *core_shape)``: ``(*core_shape, M)``.

    Always writable: a broadcast covariance is a read-only view, and numba
    would compile the kernels once more for a read-only argument.
    """
    order = tuple(range(1, core + 1)) + (0,)
    t = a.transpose(order)
    return t if t.flags.c_contiguous and t.flags.writeable else np.array(t, order="C")


def _linear_kernels(kind: str, hs, F: np.ndarray, Q: np.ndarray):
    """The generated kernels for a KF/EKF with a linear measurement, else ``None`` (block kernels)."""
    if kind != "ekf" or hs.kind != M_LINEAR:
        return None
    return generated.linear_kf_kernels(F, Q, np.ascontiguousarray(hs.A), np.ascontiguousarray(hs.R))


def gaussian_step(filt, specs, state: GaussianState, z: np.ndarray, k: int, dt, kind: str):
    """One compiled step of a KF/EKF (``kind="ekf"``) or UKF/CKF (``kind="sigma"``)."""
    ms, hs = specs
    batch = state.batch
    M = int(np.prod(batch, dtype=int))
    n = state.mean.shape[-1]
    m = hs.dim
    mean = state.mean.reshape(M, n)
    cov = np.broadcast_to(state.cov, (*batch, n, n)).reshape(M, n, n)
    x = lanes(mean, 1)
    P = lanes(cov, 2)
    # writable: one run's measurement broadcast is a read-only view, another signature for numba
    zl = np.require(np.broadcast_to(z, (*batch, m)).reshape(M, m).T, requirements=("C", "W"))
    valid = ~np.isnan(zl)
    F, _, _ = ms.arrays(k, dt)
    F, Q = frozen(F, np.float64), frozen(ms.cov(k, dt), np.float64)  # one read-only signature (specs.frozen)
    lam = float(filt.fading.lam)
    par = use_parallel(M)
    gen = _linear_kernels(kind, hs, F, Q)
    if gen is not None:  # one lane-major output array; the results are views of its rows
        rows = kf_codegen.step_rows(n, m)
        out = np.empty((sum(c for _, c in rows.values()), M))
        sensor = hs.kernel_args(k)  # A and R read-only, as in every other kernel call
        generated.run_blocks(gen.step, (x, P, zl, valid, F, Q, lam, sensor.A, sensor.R, out), M, gen.STEP_BLOCK, par)

        def part(name, shape):
            first, count = rows[name]
            return out[first:first + count].reshape(*shape, M)

        x_out, xp, P_out, Pp, cross = part("x", (n,)), part("xp", (n,)), part("P", (n, n)), part("Pp", (n, n)), part("cross", (n, n))
        innov, S = part("innov", (m,)), part("S", (m, m))
        nis, loglik = out[rows["nis"][0]], out[rows["loglik"][0]]
        dof, ok = out[rows["dof"][0]].astype(np.int64), out[rows["ok"][0]] > 0.0
    else:  # the block kernels write into arrays of their own
        x_out, P_out = np.empty((n, M)), np.empty((n, n, M))
        xp, Pp, cross = np.empty((n, M)), np.empty((n, n, M)), np.empty((n, n, M))
        innov, S = np.empty((m, M)), np.empty((m, m, M))
        nis, loglik = np.empty(M), np.empty(M)
        dof = np.empty(M, dtype=np.int64)
        ok = np.ones(M, dtype=np.bool_)
        args = ((x, P), (zl, valid), Prediction(F, Q, lam), hs.kernel_args(k))
        outs = GaussOutputs(x_out, P_out, xp, Pp, cross, innov, S, nis, dof, loglik, ok)
        if kind == "ekf":
            (GK.ekf_step_parallel if par else GK.ekf_step_serial)(*args, outs)
        else:
            (GK.sigma_step_parallel if par else GK.sigma_step_serial)(*args, _sigma_points(filt, n), outs)
    info = {
        "innovation": innov.T,
        "S": S.transpose(2, 0, 1),
        "nis": nis,
        "dof": dof,
        "loglik": loglik,
        "fading": np.full(M, lam),
        "faded": np.full(M, lam > 1.0),
        "repaired": np.zeros(M, dtype=bool),
        "pred_mean": xp.T,
        "pred_cov": Pp.transpose(2, 0, 1),
        "cross_cov": cross.transpose(2, 0, 1),
    }
    new_mean, new_cov = x_out.T, P_out.transpose(2, 0, 1)
    gated = np.zeros(M, dtype=bool)
    if filt.gate is not None:  # the chi-square gate of the NumPy step, on the compiled results
        new_mean, new_cov, gated = apply_gate(filt.gate, info, info["pred_mean"], info["pred_cov"], new_mean, new_cov)
    info["gated"] = gated
    if not ok.all():  # recompute the runs whose covariance needs the NumPy repair
        rows = np.flatnonzero(~ok)
        sub = GaussianState(mean=mean[rows], cov=cov[rows], k=state.k, memory=None)
        s2, i2 = filt.numpy_step(sub, np.broadcast_to(z, (*batch, m)).reshape(M, m)[rows], k, dt)
        new_mean, new_cov = new_mean.copy(), new_cov.copy()
        new_mean[rows], new_cov[rows] = s2.mean, s2.cov
        for key, value in i2.items():
            if key in info:
                info[key] = np.array(info[key], copy=True)
                info[key][rows] = np.broadcast_to(value, info[key][rows].shape)
    if batch != (M,):  # () for one unbatched run: reshape takes the shape as one tuple, which may be empty
        new_mean = new_mean.reshape(batch + (n,))
        new_cov = new_cov.reshape(batch + (n, n))
        info = {key: v.reshape(batch + v.shape[1:]) for key, v in info.items()}
    return GaussianState(mean=new_mean, cov=new_cov, k=k, memory=None), info


def gaussian_sequence(filt, specs, state: GaussianState, zs: np.ndarray, keep_cov: bool, kind: str = "ekf"):
    """All steps of a compiled KF/EKF (``kind="ekf"``) or UKF/CKF (``kind="sigma"``) over ``zs (K, *batch, m)``.

    Applies to a linear motion model whose ``F`` and ``Q`` are the same at
    every step (the models' own ``dt``), a fixed sensor, one batch axis
    (the UKF/CKF also an unbatched run, batch ``()``) and no gate: then
    nothing needs Python between steps.  Returns ``(means, covs, info)`` in
    the layout of :func:`pursuit.run`, with the info keys of
    :func:`gaussian_step` (without the smoother's), or ``None`` where it
    does not apply.  Runs whose covariance needed the NumPy repair at some
    step are recomputed step by step, alone.
    """
    ms, hs = specs
    batch = state.batch
    if filt.gate is not None or hs.moving:
        return None  # a moving observer's sensor is packed per step: the step path
    if len(batch) != 1 and not (kind == "sigma" and batch == ()):
        return None
    F, _, _ = ms.arrays(1, None)
    F, Q = frozen(F, np.float64), frozen(ms.cov(1, None), np.float64)  # one read-only signature (specs.frozen)
    F2, _, _ = ms.arrays(2, None)
    if not (np.array_equal(F, F2) and np.array_equal(Q, ms.cov(2, None))):
        return None  # time-varying model: the step path evaluates it per step
    if batch == ():  # one unbatched run: the kernels' one lane, the results reshaped back
        one = GaussianState(mean=state.mean.reshape(1, -1), cov=np.reshape(state.cov, (1, *np.shape(state.cov)[-2:])),
                            k=state.k, memory=None)
        means, covs, info = gaussian_sequence(filt, specs, one, zs[:, None], keep_cov, kind)
        return means[:, 0], (None if covs is None else covs[:, 0]), {key: v[:, 0] for key, v in info.items()}
    (M,) = batch
    K = zs.shape[0]
    n = state.mean.shape[-1]
    m = hs.dim
    x = lanes(state.mean, 1)
    P = lanes(np.broadcast_to(state.cov, (M, n, n)), 2)
    lam = float(filt.fading.lam)
    means = np.empty((K, M, n))
    covs = np.empty((K, M, n, n) if keep_cov else (1, 1, 1, 1))
    innov, S = np.empty((K, M, m)), np.empty((K, M, m, m))
    nis, loglik = np.empty((K, M)), np.empty((K, M))
    dof = np.empty((K, M), dtype=np.int64)
    ok = np.ones(M, dtype=np.bool_)
    gen = _linear_kernels(kind, hs, F, Q)
    if gen is not None:  # reads the measurements and writes the outputs in the track's layout, flattened per step
        sensor = hs.kernel_args()  # A and R read-only, as in every other kernel call
        args = (x, P, np.ascontiguousarray(zs, dtype=float).reshape(K, M * m), F, Q, lam, sensor.A, sensor.R, keep_cov,
                means.reshape(K, M * n), covs.reshape(covs.shape[0], -1), innov.reshape(K, M * m), S.reshape(K, M * m * m),
                nis, dof, loglik, ok)
        generated.run_blocks(gen.sequence, args, M, gen.SEQUENCE_BLOCK, use_parallel(M))
    else:
        zl = np.ascontiguousarray(np.moveaxis(zs, 2, 1))  # (K, m, M)
        obs = (zl, ~np.isnan(zl))
        outs = GaussSequenceOutputs(means, covs, innov, S, nis, dof, loglik, ok)
        if kind == "ekf":
            kernel = GK.ekf_sequence_parallel if use_parallel(M) else GK.ekf_sequence_serial
            kernel((x, P), obs, Prediction(F, Q, lam), measurement_args(hs), keep_cov, outs)
        else:
            kernel = GK.sigma_sequence_parallel if use_parallel(M) else GK.sigma_sequence_serial
            kernel((x, P), obs, Prediction(F, Q, lam), measurement_args(hs), _sigma_points(filt, n), keep_cov, outs)
    info = {
        "innovation": innov,
        "S": S,
        "nis": nis,
        "dof": dof,
        "loglik": loglik,
        "fading": np.full((K, M), lam),
        "faded": np.full((K, M), lam > 1.0),
        "repaired": np.zeros((K, M), dtype=bool),
        "gated": np.zeros((K, M), dtype=bool),
    }
    if not ok.all():  # recompute, step by step, the runs whose covariance needed the NumPy repair
        rows = np.flatnonzero(~ok)
        sub = filt.init(Gaussian(state.mean[rows], np.broadcast_to(state.cov, (M, n, n))[rows]), batch=(rows.size,))
        for i in range(K):  # the filter's own steps, as pursuit.run would take them
            sub, step_info = filt.step(sub, zs[i, rows], k=i + 1)
            means[i, rows] = sub.mean
            if keep_cov:
                covs[i, rows] = sub.cov
            for key in info:
                info[key][i, rows] = step_info[key]
    return means, (covs if keep_cov else None), info


def _sigma_points(filt, n: int) -> SigmaPoints:
    """The UKF/CKF's sigma-point weights as the kernels take them (the centre point first where there is one)."""
    cscale, wm, wc = filt.sigma_weights(n)
    return SigmaPoints(float(cscale), np.ascontiguousarray(wm), np.ascontiguousarray(wc), wm.shape[0] % 2 == 1)


EKF = CompiledPath(step=partial(gaussian_step, kind="ekf"), sequence=gaussian_sequence, online=partial(online_lane, kind="ekf"))
"""The compiled KF/EKF (``ExtendedKalmanFilter.compiled_path``)."""

SIGMA = CompiledPath(step=partial(gaussian_step, kind="sigma"), sequence=partial(gaussian_sequence, kind="sigma"),
                     online=partial(online_lane, kind="sigma"))
"""The compiled UKF/CKF (``UnscentedKalmanFilter.compiled_path``)."""


def measurement_correct(filt, hs, x_pred: np.ndarray, P_pred: np.ndarray, z: np.ndarray, k: int):
    """The compiled EKF or UKF measurement update at ``(x_pred (*b, n), P_pred (*b, n, n))``: ``(mean, cov, info)``.

    The ``correct`` of :meth:`pursuit.filters.NonlinearCSFilter.numpy_step`:
    the update kernel of the filter's ``update`` with the sensor packed for
    step ``k``.  Runs whose covariance does not factor are recomputed with
    the filter's NumPy :meth:`~pursuit.filters.NonlinearCSFilter.measurement_update`
    (which repairs them), as :func:`gaussian_step` does.
    """
    batch = x_pred.shape[:-1]
    M = int(np.prod(batch, dtype=int))
    n = x_pred.shape[-1]
    m = hs.dim
    mean = x_pred.reshape(M, n)
    cov = np.broadcast_to(P_pred, (*batch, n, n)).reshape(M, n, n)
    zs = np.broadcast_to(z, (*batch, m)).reshape(M, m)
    zl = np.require(zs.T, requirements=("C", "W"))  # writable, as in gaussian_step: one signature
    valid = ~np.isnan(zl)
    outs = GaussUpdateOutputs(np.empty((n, M)), np.empty((n, n, M)), np.empty((m, M)), np.empty((m, m, M)), np.empty(M),
                              np.empty(M, dtype=np.int64), np.empty(M), np.ones(M, dtype=np.bool_))
    sigma = None
    if filt.update != "ekf":
        cscale, wm, wc = filt.update_filter.sigma_weights(n)
        sigma = SigmaPoints(float(cscale), np.ascontiguousarray(wm), np.ascontiguousarray(wc), wm.shape[0] % 2 == 1)
    kernel = GK.correct_parallel if use_parallel(M) else GK.correct_serial
    kernel((lanes(mean, 1), lanes(cov, 2)), (zl, valid), hs.kernel_args(k), sigma, outs)
    # C order, as the NumPy update's: the filter's NumPy prediction (einsum, matmul) then takes the same
    # path, whose last bits depend on the layout, for a batch and for one run alone
    new_mean, new_cov = np.ascontiguousarray(outs.x.T), np.ascontiguousarray(outs.P.transpose(2, 0, 1))
    info = {
        "innovation": outs.innov.T,
        "S": outs.S.transpose(2, 0, 1),
        "nis": outs.nis,
        "dof": outs.dof,
        "loglik": outs.loglik,
        "repaired": np.zeros(M, dtype=bool),
    }
    if not outs.ok.all():  # the NumPy update repairs these runs' covariances
        rows = np.flatnonzero(~outs.ok)
        m2, c2, i2 = filt.measurement_update(mean[rows], cov[rows], zs[rows], k)
        new_mean, new_cov = new_mean.copy(), new_cov.copy()
        new_mean[rows], new_cov[rows] = m2, c2
        for key in info:
            info[key] = np.array(info[key], copy=True)
            info[key][rows] = np.broadcast_to(i2[key], info[key][rows].shape)
    if batch != (M,):
        new_mean, new_cov = new_mean.reshape(batch + (n,)), new_cov.reshape(batch + (n, n))
        info = {key: v.reshape(batch + v.shape[1:]) for key, v in info.items()}
    return new_mean, new_cov, info


def cs_step(filt, specs, state, z: np.ndarray, k: int, dt):
    """One step of the CS-model filter with compiled measurement updates (its NumPy prediction and adaptation)."""
    _, hs = specs
    return filt.numpy_step(state, z, k, dt, correct=partial(measurement_correct, filt, hs))


CS = CompiledPath(step=cs_step)
"""The CS-model filter for nonlinear measurements (``NonlinearCSFilter.compiled_path``); no whole-sequence path."""
