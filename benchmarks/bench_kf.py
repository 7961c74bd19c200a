"""Kalman filter throughput: pursuit (batched over runs) against FilterPy (one run at a time).

Work: a 4-state constant-velocity model with 2-D position measurements,
M = 1000 runs x T = 1000 steps.  A filter-step is one predict + update of one
run.  pursuit filters all runs at once; FilterPy has no batch mode, so it
filters runs one after another, and its rate is measured on fewer runs (its
cost per step does not depend on the number of runs).

Rows:

* ``pursuit KF (shared P)``: the usual Monte Carlo case — every run starts
  from the same prior covariance, so the Riccati recursion is computed once
  for the batch (exact, not an approximation).
* ``pursuit KF (per-run P)``: each run has its own prior covariance stack,
  so every run carries its own covariance — the general path.
* ``pursuit UKF``: the same work through the unscented filter.
* ``FilterPy KF``: ``filterpy.kalman.KalmanFilter.predict`` + ``update``.

Run::

    .venv/bin/python benchmarks/bench_kf.py            # FilterPy row if filterpy is importable
    make bench                                          # all benchmarks, peers in .bench-venv
"""

from __future__ import annotations

import statistics
import time

import numpy as np

import pursuit as pu
from pursuit.models import ConstantVelocity, LinearGaussian

REPEATS = 3


def _work(runs: int, steps: int, seed: int = 0):
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
    meas = LinearGaussian.position(motion.dim, motion.position_indices, 1.0)
    zs = np.random.default_rng(seed).standard_normal((steps, runs, 2)) * 3.0
    return motion, meas, zs


def _time(fn, repeats: int = REPEATS) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def pursuit_rate(kind: str, runs: int, steps: int) -> float:
    """Filter-steps per second for pursuit's batched filters."""
    motion, meas, zs = _work(runs, steps)
    if kind == "kf-shared":
        filt, prior = pu.KalmanFilter(motion, meas), pu.Gaussian(np.zeros(4), np.eye(4))
    elif kind == "kf-per-run":
        filt = pu.KalmanFilter(motion, meas)
        prior = pu.Gaussian(np.zeros((runs, 4)), np.broadcast_to(np.eye(4), (runs, 4, 4)).copy())
    elif kind == "ukf":
        filt, prior = pu.UnscentedKalmanFilter(motion, meas), pu.Gaussian(np.zeros(4), np.eye(4))
    else:
        raise ValueError(kind)
    t = _time(lambda: pu.run(filt, zs, prior, keep_cov=False))
    return runs * steps / t


def filterpy_rate(runs: int, steps: int) -> float | None:
    """Filter-steps per second for FilterPy, one run at a time (None if not installed)."""
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        return None
    motion, meas, zs = _work(runs, steps)

    def go():
        for i in range(runs):
            kf = KalmanFilter(dim_x=4, dim_z=2)
            kf.F = np.array(motion.transition_matrix())
            kf.Q = np.array(motion.cov())
            kf.H = np.array(meas.matrix())
            kf.R = np.array(meas.cov())
            kf.x = np.zeros((4, 1))
            kf.P = np.eye(4)
            for k in range(steps):
                kf.predict()
                kf.update(zs[k, i].reshape(2, 1))

    return runs * steps / _time(go)


def main(quick: bool = False) -> list[dict]:
    """Measure and print a markdown table; returns the rows."""
    runs, steps = (200, 200) if quick else (1000, 1000)
    fp_runs = 5 if quick else 20
    rows = []
    for kind, label in (("kf-shared", "pursuit KF (shared P)"), ("kf-per-run", "pursuit KF (per-run P)"), ("ukf", "pursuit UKF")):
        rows.append({"implementation": label, "runs": runs, "steps": steps, "rate": pursuit_rate(kind, runs, steps)})
    fp = filterpy_rate(fp_runs, steps)
    if fp is not None:
        rows.append({"implementation": "FilterPy KF (one run at a time)", "runs": fp_runs, "steps": steps, "rate": fp})
    print("| implementation | runs x steps | M filter-steps/s | vs FilterPy |")
    print("|---|---|---|---|")
    for r in rows:
        ratio = f"{r['rate'] / fp:.1f}x" if fp else "n/a (filterpy not installed)"
        r["vs_filterpy"] = r["rate"] / fp if fp else None
        print(f"| {r['implementation']} | {r['runs']} x {r['steps']} | {r['rate'] / 1e6:.3f} | {ratio} |")
    return rows


if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv)
