"""Keeping a particle filter's particle sets at chosen steps (for figures)."""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from ..rng import RNGLike, as_rng

__all__ = ["particle_snapshots"]


def particle_snapshots(
    filt: Any,
    zs: np.ndarray,
    prior: Any,
    rng: RNGLike,
    steps: Iterable[int],
    dts: np.ndarray | None = None,
) -> dict[int, dict[str, np.ndarray]]:
    """Run a particle filter and copy its particle set after the given steps.

    Parameters
    ----------
    filt
        A particle filter (its state has ``particles`` and ``logw``).
    zs
        ``(K, *batch, m)`` measurements.
    prior
        The filter's prior.
    rng
        The filter's random streams; pass the Monte Carlo engine's streams of
        a run (``run_streams(seed, [i], 1)``) to reproduce run i exactly.
    steps
        1-based steps to keep; steps beyond K are ignored.
    dts
        Optional ``(K,)`` time steps.

    Returns
    -------
    dict
        ``{step: {"particles": (*batch, N, n), "weights": (*batch, N), "mean": (*batch, n)}}``
        with the particles after the step (after resampling, or after the
        cuckoo moves).
    """
    zs = np.asarray(zs, dtype=float)
    wanted = {int(s) for s in steps}
    state = filt.init(prior, batch=zs.shape[1:-1], rng=as_rng(rng))
    out: dict[int, dict[str, np.ndarray]] = {}
    for i in range(zs.shape[0]):
        dt = None if dts is None else float(dts[i])
        state, _ = filt.step(state, zs[i], k=i + 1, dt=dt)
        if i + 1 in wanted:
            out[i + 1] = {
                "particles": np.array(state.particles, copy=True),
                "weights": np.exp(np.asarray(state.logw)),
                "mean": np.array(state.mean, copy=True),
            }
    return out
