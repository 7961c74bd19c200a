"""CPU time of a particle filter's likelihood with the components no run measured left out.

``PYTHONPATH=src taskset -c 1 python benchmarks/_missing_components.py``

1. p1-wsn's 4 x 4 grid as the cuckoo searches see it: 100 runs x 200 particles, 16 range nodes of
   which 10 are out of every run's range (NaN) and one more is missed by a third of the runs.  The
   log-likelihood over all 16 columns (what the filters computed before 2026-12-05) against the
   columns some run measured (what they compute now): ``gaussian_loglik`` on the residuals, and
   ``BootstrapParticleFilter._likelihoods`` with the ranges of all nodes or (``predicted=False``,
   the cuckoo fitness) of the heard ones only.  The values are the same bits (asserted).

Medians of several repetitions, ``time.process_time``.
"""

from __future__ import annotations

import time

import numpy as np

from pursuit.filters.particle import BootstrapParticleFilter
from pursuit.models import RangeSensors, gaussian_loglik


def _median_cpu(fn, repeat: int, number: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        for _ in range(number):
            fn()
        times.append((time.process_time() - t0) / number)
    return float(np.median(times))


def likelihood_widths() -> None:
    rng = np.random.default_rng(0)
    grid = np.array([[x, y] for y in (5.0, 55.0, 105.0, 155.0) for x in (-40.0, 10.0, 60.0, 110.0)])
    meas = RangeSensors(grid, 0.85)
    X = rng.normal([35.0, 1.0, 80.0, 0.5], 20.0, (100, 200, 4))
    z = meas.h(X[:, 0], 1) + rng.normal(0.0, 0.85, (100, 16))
    z[:, [0, 2, 3, 6, 7, 8, 10, 11, 12, 14]] = np.nan
    z[::3, 5] = np.nan
    R = meas.cov(1)
    valid = ~np.isnan(z)
    cols = np.flatnonzero(valid.any(axis=0))
    Zp = meas.h(X, 1)
    full = gaussian_loglik(z[:, None, :] - Zp, R)
    narrow = gaussian_loglik(z[:, None, cols] - Zp[..., cols], R[np.ix_(cols, cols)], in_order=True)
    assert np.array_equal(full, narrow)
    t_full = _median_cpu(lambda: gaussian_loglik(z[:, None, :] - Zp, R), 7, 20)
    t_narrow = _median_cpu(lambda: gaussian_loglik(z[:, None, cols] - Zp[..., cols], R[np.ix_(cols, cols)], in_order=True), 7, 20)
    print(f"gaussian_loglik, 16 columns: {t_full * 1e3:.2f} ms; the {cols.size} heard: {t_narrow * 1e3:.2f} ms ({t_narrow / t_full:.2f}x)")
    pf = BootstrapParticleFilter(_Walk(), meas, particles=200)
    measured = valid.any(axis=-1)
    with_h = _median_cpu(lambda: pf._likelihoods(X, z, 1, valid, measured), 7, 20)
    fitness = _median_cpu(lambda: pf._likelihoods(X, z, 1, valid, measured, predicted=False), 7, 20)
    h_all = _median_cpu(lambda: meas.h(X, 1), 7, 20)
    print(f"_likelihoods with every node's range (the weighing): {with_h * 1e3:.2f} ms; the cuckoo fitness "
          f"(heard nodes' ranges only): {fitness * 1e3:.2f} ms ({fitness / with_h:.2f}x); h alone {h_all * 1e3:.2f} ms")


class _Walk:
    dim = 4

    def f(self, x, k=None, dt=None):
        return x

    def cov(self, k=None, dt=None):
        return np.eye(4)

    def sample(self, x, k, rng, dt=None):
        return x


if __name__ == "__main__":
    likelihood_widths()
