"""Small seeded multi-target scenes for the tracker tests (plain arrays, the shared detection contract)."""

from __future__ import annotations

import numpy as np

from pursuit.models import ConstantVelocity, LinearGaussian


def cv_models(q: float = 0.01, sigma: float = 1.0):
    """2-D CV motion (dt = 1) and a position sensor."""
    cv = ConstantVelocity(ndim=2, dt=1.0, q=q)
    return cv, LinearGaussian.position(4, cv.position_indices, sigma)


def simulate(
    starts,
    K: int,
    runs: int,
    seed: int,
    *,
    motion=None,
    measurement=None,
    p_detect: float = 1.0,
    clutter_rate: float = 0.0,
    region=((-50.0, 50.0), (-50.0, 50.0)),
    clutter_sampler=None,
    shuffle: bool = True,
):
    """Truth ``(K, M, N, n)`` and detections ``(K, M, D, m)`` (NaN-padded, shuffled within a scan).

    Clutter: Poisson(``clutter_rate``) points uniform over ``region`` (or
    drawn by ``clutter_sampler(rng, count)`` in measurement space).
    """
    if motion is None or measurement is None:
        motion, measurement = cv_models()
    rng = np.random.default_rng(seed)
    x = np.broadcast_to(np.asarray(starts, dtype=float), (runs, *np.shape(starts))).copy()
    truth, scans = [], []
    for k in range(1, K + 1):
        x = motion.sample(x, k, rng)
        z = measurement.sample(x, k, rng)  # (M, N, m)
        truth.append(x.copy())
        per_run = []
        for m in range(runs):
            det = z[m][rng.random(z.shape[1]) < p_detect]
            nc = rng.poisson(clutter_rate)
            if clutter_sampler is not None:
                c = clutter_sampler(rng, nc)
            else:
                lo = np.array([r[0] for r in region])
                hi = np.array([r[1] for r in region])
                c = lo + (hi - lo) * rng.random((nc, len(region)))
            rows = np.concatenate([det, c])
            if shuffle:
                rows = rows[rng.permutation(len(rows))]
            per_run.append(rows)
        scans.append(per_run)
    D = max(1, max(len(r) for s in scans for r in s))
    m_dim = scans[0][0].shape[-1] if len(scans[0][0]) else measurement.dim
    out = np.full((K, runs, D, m_dim), np.nan)
    for k, s in enumerate(scans):
        for m, rows in enumerate(s):
            out[k, m, : len(rows)] = rows
    return np.array(truth), out
