"""pursuit's compiled KF (one thread) against the JAX KF of ``_jax_kf``, taking turns, wall and CPU time.

bench_kf's KF work (4-state CV, position measured, M = 1000 runs x T = 1000
steps).  Each pass times ``pursuit.run`` (numba, one thread, per-run P, the
divergence flag included, as a user gets it) and then each JAX variant, so
a change of machine load hits all of them alike; medians over the passes.
CPU seconds (``time.process_time``) are printed beside the wall seconds: on
a loaded machine they are the steadier measure of work per core.

Run (pinned to one core)::

    cd benchmarks && PYTHONPATH=../src taskset -c 1 ../.bench-venv/bin/python _jax_vs_pursuit.py [passes]
"""

from __future__ import annotations

import _one_core

_one_core.pin()

import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import _jax_kf  # noqa: E402
import numpy as np  # noqa: E402
from bench_kf import kf_work  # noqa: E402

import pursuit as pu  # noqa: E402


def _clock(fn) -> tuple[float, float]:
    c0, t0 = time.process_time(), time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main(passes: int = 7, runs: int = 1000, steps: int = 1000) -> None:
    import numba

    numba.set_num_threads(1)
    jax = _jax_kf.configure()
    motion, meas, zs = kf_work(runs, steps)
    F, Q, H, R = (np.array(a) for a in (motion.transition_matrix(), motion.cov(), meas.matrix(), meas.cov()))
    filt = pu.KalmanFilter(motion, meas, backend="numba")
    prior = pu.Gaussian(np.zeros(4), np.eye(4))
    pu.run(filt, zs[:2], prior, keep_cov=False)  # numba compile, not timed
    jobs = {"pursuit.run, numba 1 thread": lambda: pu.run(filt, zs, prior, keep_cov=False)}
    if jax is not None:
        import jax.numpy as jnp

        z, x0, P0 = jnp.asarray(zs), jnp.zeros(4), jnp.eye(4)
        for label, inverse, full in (("JAX, jnp.linalg.solve", "solve", False), ("JAX, 2x2 inverse", "2x2", False),
                                     ("JAX, 2x2 inverse, pursuit's outputs", "2x2", True)):
            f = _jax_kf.make_filter(F, Q, H, R, inverse=inverse, full=full)
            jax.block_until_ready(f(z, x0, P0))  # XLA compile, not timed
            jobs[label] = (lambda f=f: jax.block_until_ready(f(z, x0, P0)))
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in jobs}
    for _ in range(passes):
        for label, fn in jobs.items():
            times[label].append(_clock(fn))
    ref = "pursuit.run, numba 1 thread"
    med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in times.items()}
    print(f"{runs} runs x {steps} steps, median of {passes} passes taking turns\n")
    print("| implementation | M filter-steps/s (wall) | M filter-steps/s (CPU time) | pursuit / this (wall) | pursuit / this (CPU) |")
    print("|---|---|---|---|---|")
    for k, (w, c) in med.items():
        print(f"| {k} | {runs * steps / w / 1e6:.2f} | {runs * steps / c / 1e6:.2f} | {w / med[ref][0]:.2f} | {c / med[ref][1]:.2f} |")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
