"""The one driver over time: ``run(filter, zs, prior, rng) -> Track``."""

from __future__ import annotations

import time
from typing import Any, Iterable, Sequence

import numpy as np

from ..divergence import DIVERGED_KEY, DivergenceMonitor, DivergenceTest, detect_divergence
from ..rng import RNGLike, as_rng
from ..track import SMOOTHER_KEYS, Track

__all__ = ["Track", "run", "SMOOTHER_KEYS"]


def run(
    filt: Any,
    zs: np.ndarray,
    prior: Any,
    rng: RNGLike = None,
    *,
    dts: Sequence[float] | np.ndarray | None = None,
    keep_cov: bool = True,
    store_predictions: bool = False,
    keep_info: Iterable[str] | None = None,
    sequence: bool = True,
    divergence: DivergenceTest | None = DivergenceTest(),
) -> Track:
    """Run a filter over a sequence of measurements.

    Parameters
    ----------
    filt
        Any pursuit filter (an object with ``init`` and ``step``).
    zs
        ``(K, *batch, m)`` measurements, time first; NaN = missing.
    prior
        The filter's prior, usually a :class:`pursuit.Gaussian` (its mean
        may carry the batch axes).
    rng
        Randomness for filters that draw (particle filters): a seed, a
        Generator, or :class:`pursuit.RunStreams` with one stream per run.
    dts
        Optional ``(K,)`` time since the previous step, for irregular
        sampling; default: the motion model's ``dt``.
    keep_cov
        Keep the ``(K, *batch, n, n)`` covariances (the largest output).
    store_predictions
        Keep the predicted means and covariances and the cross-covariances
        the RTS smoother needs.
    keep_info
        Info keys to keep; default all except the smoother's.
    sequence
        Let a filter that can compute all steps in one call, without
        Python between steps: a compiled KF/EKF with a time-invariant
        model, no gate and one batch axis, or a compiled bootstrap PF with
        one batch axis and per-run PCG64 streams (:class:`pursuit.RunStreams`).
        The results are the same bits as step by step.  ``False`` always
        steps from Python.
    divergence
        The thresholds of the divergence test (:mod:`pursuit.divergence`):
        the step info then carries ``diverged``, ``(K, *batch)`` bool, True
        from the first step of a run's divergence on, whatever
        ``keep_info`` says.  None: no test, no flag.

    Returns
    -------
    Track
    """
    zs = np.asarray(zs, dtype=float)
    if zs.ndim < 2:
        raise ValueError(f"zs: expected (K, *batch, m), got shape {zs.shape}")
    K = zs.shape[0]
    batch = zs.shape[1:-1]
    if dts is not None:
        dts = np.asarray(dts, dtype=float)
        if dts.shape != (K,):
            raise ValueError(f"dts: expected shape ({K},), got {dts.shape}")
        if not np.all(np.isfinite(dts)) or np.any(dts <= 0):
            raise ValueError("dts: time steps must be finite and positive")
    rng = as_rng(rng)

    t0 = time.perf_counter()
    state = filt.init(prior, batch=batch, rng=rng)
    infos: dict[str, np.ndarray] = {}
    wanted = None if keep_info is None else set(keep_info)
    whole = getattr(filt, "run_sequence", None)
    if sequence and whole is not None and dts is None and not store_predictions:
        done = whole(state, zs, keep_cov=keep_cov)
        if done is not None:
            means, covs, infos = done
            wall = time.perf_counter() - t0
            flags = None
            if divergence is not None:
                flags = detect_divergence(infos.get("nis"), infos.get("dof"), means, covs, test=divergence)
            if wanted is not None:
                infos = {key: value for key, value in infos.items() if key in wanted}
            if flags is not None:
                infos = {**infos, DIVERGED_KEY: flags}
            return Track(mean=means, cov=covs, info=infos, name=getattr(filt, "name", type(filt).__name__), wall_time=wall)
    means = np.empty((K, *state.mean.shape))
    covs = np.empty((K, *state.mean.shape, state.mean.shape[-1])) if keep_cov else None
    monitor = None if divergence is None else DivergenceMonitor(state.mean.shape[:-1], divergence)
    t_monitor = 0.0
    for i in range(K):
        dt = None if dts is None else float(dts[i])
        state, info = filt.step(state, zs[i], k=i + 1, dt=dt)
        if monitor is not None:  # not the filter's time: left out of wall_time
            t1 = time.perf_counter()
            monitor.update(info.get("nis"), info.get("dof"), state.mean, getattr(state, "cov", None))
            t_monitor += time.perf_counter() - t1
        means[i] = state.mean
        if keep_cov:
            covs[i] = state.cov
        for key, value in info.items():
            if key in SMOOTHER_KEYS and not store_predictions:
                continue
            if wanted is not None and key not in wanted and key not in SMOOTHER_KEYS:
                continue
            value = np.asarray(value)
            if key in SMOOTHER_KEYS:
                value = np.broadcast_to(value, (*batch, *value.shape[-(1 if key == "pred_mean" else 2):]))
            buf = infos.get(key)
            if buf is None:
                buf = infos[key] = np.empty((K, *value.shape), dtype=value.dtype)
            buf[i] = value
    wall = time.perf_counter() - t0 - t_monitor
    if monitor is not None:
        infos[DIVERGED_KEY] = monitor.flags()
    return Track(mean=means, cov=covs, info=infos, name=getattr(filt, "name", type(filt).__name__), wall_time=wall)
