"""Kalman filters: pursuit (NumPy and numba) against FilterPy, simdkalman, JAX and Stone Soup on identical work.

Work (the same model, sizes and measurements for every implementation):

* **KF**: 2-D constant-velocity target (4 states, continuous white-noise
  acceleration q = 0.01, dt = 1), position measured with unit variance,
  M = 1000 runs x T = 1000 steps.  A filter-step is one predict + update of
  one run.
* **UKF**: the same motion with a range-bearing sensor at (0, -50)
  (σ = 1 m, 0.02 rad), scaled sigma points α = 1, β = 2, κ = 0, M = 1000
  runs x T = 200 steps.

pursuit, simdkalman and JAX filter all runs at once (JAX: ``jax.vmap`` over
runs of a ``lax.scan`` filter, written for this benchmark in ``_jax_kf.py``;
XLA's compile is left out of its time as numba's is out of pursuit's; its
means are checked against pursuit's to 1e-9).  FilterPy and Stone Soup
have no batch mode: they filter one run after another, and their rate is
measured on fewer runs (their cost per step does not depend on the number of
runs); the table says how many.  ``numba 1 thread`` / ``2 threads`` use
``numba.set_num_threads``.  Every other row is one core: NumPy's BLAS and
OpenMP get one thread (``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
``MKL_NUM_THREADS`` = 1, set before NumPy is imported, ``_one_core.py``);
JAX's XLA gets one thread (``XLA_FLAGS``, ``_jax_kf.XLA_ONE_CORE``) and
its row says the CPU time it used per wall second.

Run::

    make bench                                        # everything, peers in .bench-venv
    .bench-venv/bin/python benchmarks/run.py --only kf
"""

from __future__ import annotations

import _one_core  # first: the NumPy rows run on one core (benchmarks/ is on sys.path when a benchmark runs)

ONE_CORE = _one_core.pin()

import warnings  # noqa: E402
from datetime import datetime, timedelta  # noqa: E402

import numpy as np  # noqa: E402
from _timing import median_time  # noqa: E402

import pursuit as pu  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing  # noqa: E402

REPEATS = 3
SENSOR = (0.0, -50.0)
SIG_R, SIG_B = 1.0, 0.02


def _time(fn, repeats: int = REPEATS) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls."""
    return median_time(fn, repeats)


def _motion():
    return ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")


def kf_work(runs: int, steps: int, seed: int = 0):
    motion = _motion()
    meas = LinearGaussian.position(4, motion.position_indices, 1.0)
    zs = np.random.default_rng(seed).standard_normal((steps, runs, 2)) * 3.0
    return motion, meas, zs


def ukf_work(runs: int, steps: int, seed: int = 0):
    motion = _motion()
    meas = RangeBearing(np.array(SENSOR), SIG_R, SIG_B)
    rng = np.random.default_rng(seed)
    x = np.tile([0.0, 1.0, 0.0, 0.5], (runs, 1))
    zs = np.empty((steps, runs, 2))
    for k in range(steps):
        x = motion.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    return motion, meas, zs


def _threads(n: int | None):
    if n is not None:
        import numba

        # under taskset numba's thread count defaults to the cores it may use: at most that many
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def pursuit_rate(kind: str, runs: int, steps: int, backend: str = "numpy", shared: bool = True, threads: int | None = None) -> float:
    """Filter-steps per second of pursuit's batched filters."""
    if kind == "kf":
        motion, meas, zs = kf_work(runs, steps)
        cls = pu.KalmanFilter
    else:
        motion, meas, zs = ukf_work(runs, steps)
        cls = pu.UnscentedKalmanFilter
    filt = cls(motion, meas, backend=backend)
    prior = pu.Gaussian(np.zeros(4), np.eye(4)) if shared else pu.Gaussian(
        np.zeros((runs, 4)), np.broadcast_to(np.eye(4), (runs, 4, 4)).copy()
    )
    _threads(threads)
    pu.run(filt, zs[:2], prior, keep_cov=False)  # compile / warm up
    rate = runs * steps / _time(lambda: pu.run(filt, zs, prior, keep_cov=False))
    _threads(2)
    return rate


def filterpy_rate(kind: str, runs: int, steps: int) -> float | None:
    """Filter-steps per second for FilterPy, one run at a time (None if not installed)."""
    try:
        from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
    except ImportError:
        return None
    if kind == "kf":
        motion, meas, zs = kf_work(runs, steps)

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

    else:
        motion, meas, zs = ukf_work(runs, steps)
        F = np.array(motion.transition_matrix())

        def fx(x, dt):
            return F @ x

        def hx(x):
            return meas.h(x)

        def residual(a, b):
            return meas.residual(a, b)

        def go():
            for i in range(runs):
                pts = MerweScaledSigmaPoints(4, alpha=1.0, beta=2.0, kappa=0.0)
                ukf = UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=1.0, fx=fx, hx=hx, points=pts, residual_z=residual)
                ukf.Q = np.array(motion.cov())
                ukf.R = np.array(meas.cov())
                ukf.x = np.zeros(4)
                ukf.P = np.eye(4)
                for k in range(steps):
                    ukf.predict()
                    ukf.update(zs[k, i])

    return runs * steps / _time(go, 1)


def simdkalman_rate(runs: int, steps: int) -> float | None:
    """Filter-steps per second for simdkalman (batched over runs; None if not installed)."""
    try:
        import simdkalman
    except ImportError:
        return None
    motion, meas, zs = kf_work(runs, steps)
    kf = simdkalman.KalmanFilter(
        state_transition=np.array(motion.transition_matrix()),
        process_noise=np.array(motion.cov()),
        observation_model=np.array(meas.matrix()),
        observation_noise=np.array(meas.cov()),
    )
    data = np.ascontiguousarray(np.moveaxis(zs, 0, 1))  # (runs, steps, 2)

    def go():
        kf.compute(data, 0, initial_value=np.zeros(4), initial_covariance=np.eye(4), filtered=True, smoothed=False)

    return runs * steps / _time(go)


def stonesoup_rate(kind: str, runs: int, steps: int) -> float | None:
    """Filter-steps per second for Stone Soup, one run at a time (None if not installed)."""
    try:
        from stonesoup.models.measurement.linear import LinearGaussian as SSLinear
        from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
        from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel
        from stonesoup.models.transition.linear import ConstantVelocity as SSCV
        from stonesoup.predictor.kalman import KalmanPredictor, UnscentedKalmanPredictor
        from stonesoup.types.detection import Detection
        from stonesoup.types.hypothesis import SingleHypothesis
        from stonesoup.types.state import GaussianState
        from stonesoup.updater.kalman import KalmanUpdater, UnscentedKalmanUpdater
    except ImportError:
        return None
    warnings.simplefilter("ignore")
    trans = CombinedLinearGaussianTransitionModel([SSCV(0.01), SSCV(0.01)])
    if kind == "kf":
        _, _, zs = kf_work(runs, steps)
        mm = SSLinear(ndim_state=4, mapping=(0, 2), noise_covar=np.eye(2))
        predictor, updater = KalmanPredictor(trans), KalmanUpdater(mm)
        zz = zs
    else:
        _, _, zs = ukf_work(runs, steps)
        # Stone Soup orders the measurement (bearing, range); the same numbers, swapped
        mm = CartesianToBearingRange(
            ndim_state=4, mapping=(0, 2), noise_covar=np.diag([SIG_B**2, SIG_R**2]),
            translation_offset=np.array([[SENSOR[0]], [SENSOR[1]]]),
        )
        predictor = UnscentedKalmanPredictor(trans, alpha=1.0, beta=2.0, kappa=0.0)
        updater = UnscentedKalmanUpdater(mm, alpha=1.0, beta=2.0, kappa=0.0)
        zz = zs[..., ::-1]
    t0 = datetime(2024, 1, 1)

    def go():
        for i in range(runs):
            prior = GaussianState(np.zeros((4, 1)), np.eye(4), timestamp=t0)
            for k in range(steps):
                ts = t0 + timedelta(seconds=k + 1)
                pred = predictor.predict(prior, timestamp=ts)
                det = Detection(zz[k, i].reshape(2, 1), timestamp=ts, measurement_model=mm)
                prior = updater.update(SingleHypothesis(pred, det))

    return runs * steps / _time(go, 1)


def jax_rows(rows, runs: int, steps: int) -> None:
    """The JAX rows of the KF table (``_jax_kf``: ``jax.vmap`` over runs of a ``lax.scan`` filter, one core).

    Each variant's means are checked against pursuit's (NumPy backend) on
    the same work: a difference beyond 1e-9 relative raises.  Float32 is
    measured for the record; the comparison is float64, pursuit's precision.
    """
    import _jax_kf

    if _jax_kf.configure() is None:
        _row(rows, "JAX vmap(lax.scan)", runs, steps, None)
        return
    motion, meas, zs = kf_work(runs, steps)
    F, Q, H, R = (np.array(a) for a in (motion.transition_matrix(), motion.cov(), meas.matrix(), meas.cov()))
    ref = pu.run(pu.KalmanFilter(motion, meas, backend="numpy"), zs, pu.Gaussian(np.zeros(4), np.eye(4)),
                 keep_cov=False, divergence=None).mean
    variants = [("solve", True, False, "jnp.linalg.solve"), ("2x2", True, False, "closed-form 2x2 inverse"),
                ("2x2", True, True, "2x2 inverse; also innovations, S, NIS (pursuit's outputs)"),
                ("2x2", False, False, "2x2 inverse; float32, not pursuit's precision")]
    for inverse, x64, full, what in variants:
        rate, cpu, means = _jax_kf.jax_rate(F, Q, H, R, zs, np.zeros(4), np.eye(4), REPEATS,
                                            inverse=inverse, x64=x64, full=full)
        err = float(np.max(np.abs(means - ref) / np.maximum(1.0, np.abs(ref))))
        if x64 and not err <= 1e-9:
            raise AssertionError(f"JAX ({what}) differs from pursuit by {err:.2e} (relative), beyond 1e-9")
        _row(rows, f"JAX vmap(lax.scan), {'float64' if x64 else 'float32'}", runs, steps, rate,
             f"{what}; XLA compile excluded; CPU/wall {cpu:.2f}; max rel. diff. from pursuit {err:.0e}")


def _row(rows, label, runs, steps, rate, note=""):
    rows.append({"implementation": label, "runs": runs, "steps": steps, "rate": rate, "note": note})


def _table(title, rows, ref_label):
    ref = next((r["rate"] for r in rows if r["implementation"] == ref_label and r["rate"]), None)
    print(f"**{title}**\n")
    print(f"| implementation | runs x steps measured | M filter-steps/s | vs {ref_label} | note |")
    print("|---|---|---|---|---|")
    for r in rows:
        if r["rate"] is None:
            print(f"| {r['implementation']} | | | | not installed |")
            continue
        ratio = f"{r['rate'] / ref:.2f}x" if ref else "n/a"
        print(f"| {r['implementation']} | {r['runs']} x {r['steps']} | {r['rate'] / 1e6:.3f} | {ratio} | {r['note']} |")
    print()


def _jax_ratio(rows) -> None:
    """Print pursuit's compiled KF (one thread) over the fastest float64 JAX row of the same run."""
    ours = next((r["rate"] for r in rows if r["implementation"] == "pursuit KF numba, 1 thread"), None)
    peers = [r["rate"] for r in rows if r["implementation"] == "JAX vmap(lax.scan), float64" and r["rate"]]
    if ours and peers:
        print(f"pursuit KF numba (1 thread) / fastest float64 JAX row: {ours / max(peers):.2f}x per core\n")


def main(quick: bool = False) -> dict[str, list[dict]]:
    """Measure and print two markdown tables (KF, UKF); returns the rows."""
    try:
        import numba  # noqa: F401

        has_numba = True
    except ImportError:
        has_numba = False
    runs, steps = (200, 100) if quick else (1000, 1000)
    few = 3 if quick else 10
    kf: list[dict] = []
    _row(kf, "pursuit KF numpy (shared P)", runs, steps, pursuit_rate("kf", runs, steps), "Riccati once for the batch")
    _row(kf, "pursuit KF numpy (per-run P)", runs, steps, pursuit_rate("kf", runs, steps, shared=False))
    if has_numba:
        for th in (1, 2):
            _row(kf, f"pursuit KF numba, {th} thread{'s' if th > 1 else ''}", runs, steps,
                 pursuit_rate("kf", runs, steps, "numba", threads=th), "per-run P, runs across SIMD lanes")
    jax_rows(kf, runs, steps)
    _row(kf, "simdkalman", runs, steps, simdkalman_rate(runs, steps), "batched over runs")
    _row(kf, "FilterPy KalmanFilter", few, steps, filterpy_rate("kf", few, steps), f"one run at a time; {few} runs")
    ss_runs = 1 if quick else 2
    _row(kf, "Stone Soup KalmanPredictor/Updater", ss_runs, steps if not quick else 50,
         stonesoup_rate("kf", ss_runs, steps if not quick else 50), f"one run at a time; {ss_runs} runs")
    _table("KF, 4-state CV, position measured (M = %d, T = %d)" % (runs, steps), kf, "FilterPy KalmanFilter")
    _jax_ratio(kf)

    u_runs, u_steps = (200, 50) if quick else (1000, 200)
    ukf: list[dict] = []
    _row(ukf, "pursuit UKF numpy", u_runs, u_steps, pursuit_rate("ukf", u_runs, u_steps))
    if has_numba:
        for th in (1, 2):
            _row(ukf, f"pursuit UKF numba, {th} thread{'s' if th > 1 else ''}", u_runs, u_steps,
                 pursuit_rate("ukf", u_runs, u_steps, "numba", threads=th))
    _row(ukf, "FilterPy UnscentedKalmanFilter", few, u_steps, filterpy_rate("ukf", few, u_steps), f"one run at a time; {few} runs")
    _row(ukf, "Stone Soup UnscentedKalmanPredictor/Updater", ss_runs, u_steps,
         stonesoup_rate("ukf", ss_runs, u_steps), f"one run at a time; {ss_runs} runs")
    _table("UKF, range-bearing sensor (M = %d, T = %d)" % (u_runs, u_steps), ukf, "FilterPy UnscentedKalmanFilter")
    if ONE_CORE:
        print("Rows other than numba's: one core (BLAS / OpenMP thread variables set to 1 before NumPy was imported).")
    else:
        print("Warning: NumPy was imported before its BLAS / OpenMP thread counts could be set to 1; "
              "the NumPy rows may have used several cores.")
    return {"kf": kf, "ukf": ukf}


def main_ukf(repeat: int = 5) -> dict[str, float]:
    """The compiled UKF's row alone on one thread, between two FilterPy timings (issue 22, item 2).

    FilterPy is timed before and after pursuit and the ratio is taken to
    the mean of its two rates, so a change of load during the run shows as
    the spread of the two peer figures.
    """
    u_runs, u_steps, few = 1000, 200, 10
    peer1 = filterpy_rate("ukf", few, u_steps)
    rates = [pursuit_rate("ukf", u_runs, u_steps, "numba", threads=1) for _ in range(repeat)]
    peer2 = filterpy_rate("ukf", few, u_steps)
    if peer1 is None or peer2 is None:
        print("FilterPy is not installed: no ratio.")
        return {"numba1": float(np.median(rates))}
    ref = 0.5 * (peer1 + peer2)
    rate = float(np.median(rates))
    print(f"**UKF, range-bearing sensor (M = {u_runs}, T = {u_steps}), compiled, one thread, median of {repeat}**\n")
    print("| implementation | M filter-steps/s | ns per filter-step | vs FilterPy UnscentedKalmanFilter |")
    print("|---|---|---|---|")
    print(f"| pursuit UKF numba, 1 thread | {rate / 1e6:.3f} | {1e9 / rate:.0f} | {rate / ref:.0f}x (runs: {', '.join(f'{r / ref:.0f}' for r in rates)}) |")
    print(f"| FilterPy UnscentedKalmanFilter, before / after | {peer1 / 1e6:.5f} / {peer2 / 1e6:.5f} | "
          f"{1e9 / peer1:.0f} / {1e9 / peer2:.0f} | 1x |")
    return {"numba1": rate, "filterpy": (peer1, peer2)}


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--ukf", action="store_true", help="only the compiled UKF on one thread against FilterPy (timed before and after)")
    ap.add_argument("--repeat", type=int, default=5, help="with --ukf: the median of this many timings of pursuit")
    cli = ap.parse_args()
    if cli.ukf:
        main_ukf(cli.repeat)
    else:
        main(quick=cli.quick)
