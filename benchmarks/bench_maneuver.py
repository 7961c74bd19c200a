"""Maneuvering-target filters: pursuit (batched over runs) against FilterPy's IMM (one run at a time).

Work: paper P4's scenario (``maneuver-3d``, spec default schedule): 9-state
target, 3-D position measurements, 98 filter steps; M runs.  A filter-step
is one predict + update of one run (all three axes).

Rows:

* ``pursuit CS``, ``pursuit APCS``, ``pursuit MS``: the per-axis CS-family
  filters, batched over runs and axes.
* ``pursuit IMM-Singer``: IMM over three Singer-model Kalman filters.
* ``pursuit APCS, one run at a time``: the same filter called with a batch
  of one, run after run (what a loop over runs would cost).
* ``FilterPy IMM-Singer``: ``filterpy.kalman.IMMEstimator`` over three
  ``KalmanFilter`` objects with the same Singer F and Q, one run at a time.
* ``pursuit CS / APCS / MS / IMM-Singer, step, batch ()``: one target stepped
  from Python, ``state, info = filt.step(state, z)`` on a state without a
  batch axis (the one-run path), over the same runs as FilterPy's IMM and
  taking turns with it in each pass; medians of the passes, wall and CPU
  time per step (``--steps`` prints only these rows).
* ``pursuit CS-EKF / ACS-EKF / ACS-UKF, bearings 3-D``: the joint CS-model
  filter (``NonlinearCSFilter``: fixed, or α and a_max adapted) on the
  ``bearings`` scenario (azimuth and elevation, strong maneuvers, 138 steps),
  batched and one run at a time, with the NumPy backend and (``[numba]``
  rows, if numba is importable) the compiled measurement updates.

Run::

    .venv/bin/python benchmarks/bench_maneuver.py              # FilterPy row if filterpy is importable
    .venv/bin/python benchmarks/bench_maneuver.py --bearings   # only the bearings rows, NumPy and numba
    .venv/bin/python benchmarks/bench_maneuver.py --steps      # only the one-run step rows and FilterPy
    make bench                                                   # all benchmarks, peers in .bench-venv
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from _timing import median_time  # benchmarks/ is on sys.path when a benchmark runs as a script

import pursuit as pu
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, InteractingMultipleModel, ModifiedSingerFilter, NonlinearCSFilter
from pursuit.models import Singer
from pursuit.rng import run_streams
from pursuit.scenarios import ManeuveringTarget
from pursuit.scenarios.bearings import BearingsOnlyTarget

REPEATS = 3
SINGER_MODES = ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))


def _time(fn, repeats: int = REPEATS) -> float:
    return median_time(fn, repeats)


BEARINGS = ("CS-EKF", "ACS-EKF", "ACS-UKF")


def _work(runs: int, name: str = ""):
    sc = BearingsOnlyTarget(dims=3) if name in BEARINGS else ManeuveringTarget()
    return sc, sc.simulate(run_streams(0, range(runs), 0), runs)


def _filters(sc, backend: str = "numpy"):
    meas = sc.measurement
    if isinstance(sc, BearingsOnlyTarget):
        kw = dict(adaptation="limit", alpha0=0.05, a_max=2.0, a_max_cap=20.0, fading="none", backend=backend)
        return {
            "CS-EKF": NonlinearCSFilter(meas, adaptation="none", alpha0=0.05, a_max=10.0, backend=backend),
            "ACS-EKF": NonlinearCSFilter(meas, **kw),
            "ACS-UKF": NonlinearCSFilter(meas, update="ukf", **kw),
        }
    return {
        "CS": CurrentStatisticalFilter(meas),
        "APCS": AdaptiveCSFilter(meas),
        "MS": ModifiedSingerFilter(meas),
        "IMM-Singer": InteractingMultipleModel(
            [pu.KalmanFilter(Singer(alpha=a, sigma=s, ndim=3), meas) for a, s in SINGER_MODES], 0.95
        ),
    }


def pursuit_rate(name: str, runs: int, backend: str = "numpy") -> float:
    """Filter-steps per second, all runs in one batch."""
    sc, sim = _work(runs, name)
    filt = _filters(sc, backend)[name] if name in BEARINGS else _filters(sc)[name]
    t = _time(lambda: pu.run(filt, sim.measurements, sim.prior, keep_cov=False))
    return runs * sc.steps / t


def pursuit_loop_rate(name: str, runs: int, backend: str = "numpy") -> float:
    """Filter-steps per second when the same filter is called one run at a time."""
    sc, sim = _work(runs, name)
    filt = _filters(sc, backend)[name] if name in BEARINGS else _filters(sc)[name]

    def go():
        for i in range(runs):
            prior = pu.Gaussian(sim.prior.mean[i : i + 1], sim.prior.cov)
            pu.run(filt, sim.measurements[:, i : i + 1], prior, keep_cov=False)

    return runs * sc.steps / _time(go)


def filterpy_rate(runs: int) -> float | None:
    """FilterPy IMMEstimator over three Singer KFs, one run at a time (None if not installed)."""
    sc, sim = _work(runs)
    go = _filterpy_imm_loop(sc, sim, runs)
    return None if go is None else runs * sc.steps / _time(go)


def _filterpy_imm_loop(sc, sim, runs: int):
    """A function that runs FilterPy's IMMEstimator over three Singer KFs on runs 0..runs-1, or None."""
    try:
        from filterpy.kalman import IMMEstimator, KalmanFilter
    except ImportError:
        return None
    H = np.array(sc.measurement.matrix())
    R = np.array(sc.measurement.cov())
    models = [Singer(alpha=a, sigma=s, ndim=3) for a, s in SINGER_MODES]
    M = np.full((3, 3), 0.025)
    np.fill_diagonal(M, 0.95)

    def go():
        for i in range(runs):
            kfs = []
            for m in models:
                kf = KalmanFilter(dim_x=9, dim_z=3)
                kf.F = np.array(m.transition_matrix())
                kf.Q = np.array(m.cov())
                kf.H, kf.R = H, R
                kf.x = sim.prior.mean[i].reshape(9, 1).copy()
                kf.P = np.array(sim.prior.cov)
                kfs.append(kf)
            imm = IMMEstimator(kfs, np.full(3, 1 / 3), M)
            for k in range(sc.steps):
                imm.predict()
                imm.update(sim.measurements[k, i].reshape(3, 1))

    return go


def _step_loop(filt, sim, runs: int, steps: int):
    """A function that steps ``filt`` one run at a time, batch (), through ``state, info = filt.step(state, z)``."""
    priors = [pu.Gaussian(sim.prior.mean[i], sim.prior.cov) for i in range(runs)]
    zs = [[np.ascontiguousarray(sim.measurements[k, i]) for k in range(steps)] for i in range(runs)]

    def go():
        for i in range(runs):
            state = filt.init(priors[i])
            for z in zs[i]:
                state, info = filt.step(state, z)

    return go


STEP_FILTERS = ("CS", "APCS", "MS", "IMM-Singer")


def step_rows(runs: int, passes: int = 5) -> list[dict]:
    """One run at a time through ``filt.step`` (batch ()), each pass timing FilterPy's IMM and every filter in turn.

    Rows carry ``us``/``cpu_us`` (median µs per step, wall and CPU) and
    ``vs_filterpy`` (FilterPy's median wall time over the filter's, the
    same passes); FilterPy's row is first (absent without filterpy).
    """
    sc, sim = _work(runs)
    fs = _filters(sc)
    loops = {}
    fp = _filterpy_imm_loop(sc, sim, runs)
    if fp is not None:
        loops["FilterPy IMM-Singer, predict + update"] = fp
    for name in STEP_FILTERS:
        loops[f"pursuit {name}, step, batch ()"] = _step_loop(fs[name], sim, runs, sc.steps)
    for go in loops.values():  # warm up: caches, imports
        go()
    wall = {k: [] for k in loops}
    cpu = {k: [] for k in loops}
    per = 1e6 / (runs * sc.steps)
    for _ in range(passes):
        for key, go in loops.items():
            t0, c0 = time.perf_counter(), time.process_time()
            go()
            wall[key].append((time.perf_counter() - t0) * per)
            cpu[key].append((time.process_time() - c0) * per)
    fp_us = statistics.median(wall[next(iter(loops))]) if fp is not None else None
    rows = []
    for key in loops:
        us = statistics.median(wall[key])
        rows.append({
            "implementation": key, "runs": runs, "steps": sc.steps, "rate": 1e6 / us, "us": us,
            "cpu_us": statistics.median(cpu[key]), "vs_filterpy": fp_us / us if fp_us else None,
        })
    return rows


def _print_steps(rows: list[dict]) -> None:
    print("| implementation | runs x steps | µs per step (wall) | µs per step (CPU) | vs FilterPy IMM |")
    print("|---|---|---|---|---|")
    for r in rows:
        ratio = f"{r['vs_filterpy']:.2f}x" if r["vs_filterpy"] else "n/a (filterpy not installed)"
        print(f"| {r['implementation']} | {r['runs']} x {r['steps']} | {r['us']:.1f} | {r['cpu_us']:.1f} | {ratio} |")


def bearings_rows(runs: int, loop_runs: int) -> list[dict]:
    """The bearings rows: CS-EKF and ACS-UKF (ACS-EKF batched only), batched and one run at a time, NumPy and numba."""
    from pursuit.compute import numba_available

    backends = ("numpy", "numba") if numba_available() else ("numpy",)
    steps = BearingsOnlyTarget(dims=3).steps
    if "numba" in backends:  # compile outside the timings
        for name in BEARINGS:
            pursuit_rate(name, 2, "numba")
    rows = []
    for backend in backends:
        tag = "" if backend == "numpy" else " [numba]"
        for name in BEARINGS:
            rate = pursuit_rate(name, runs, backend)
            rows.append({"implementation": f"pursuit {name}, bearings 3-D{tag}", "runs": runs, "steps": steps, "rate": rate})
        for name in ("CS-EKF", "ACS-UKF"):
            rows.append({
                "implementation": f"pursuit {name}, bearings 3-D, one run at a time{tag}",
                "runs": loop_runs, "steps": steps, "rate": pursuit_loop_rate(name, loop_runs, backend),
            })
    return rows


def _print(rows: list[dict], fp: float | None) -> None:
    print("| implementation | runs x steps | k filter-steps/s | vs FilterPy IMM |")
    print("|---|---|---|---|")
    for r in rows:
        ratio = f"{r['rate'] / fp:.1f}x" if fp else "n/a (filterpy not installed)"
        r["vs_filterpy"] = r["rate"] / fp if fp else None
        print(f"| {r['implementation']} | {r['runs']} x {r.get('steps', 98)} | {r['rate'] / 1e3:.3g} | {ratio} |")


def main(quick: bool = False, bearings_only: bool = False, steps_only: bool = False) -> list[dict]:
    """Measure and print markdown tables; returns the rows."""
    runs = 100 if quick else 1000
    loop_runs = 5 if quick else 20
    if bearings_only:
        rows = bearings_rows(runs, loop_runs)
        _print(rows, None)
        return rows
    if steps_only:
        rows = step_rows(2 if quick else 5, 3 if quick else 7)
        _print_steps(rows)
        return rows
    rows = []
    for name in ("CS", "APCS", "MS", "IMM-Singer"):
        rows.append({"implementation": f"pursuit {name}", "runs": runs, "rate": pursuit_rate(name, runs)})
    rows += bearings_rows(runs, loop_runs)
    rows.append({"implementation": "pursuit APCS, one run at a time", "runs": loop_runs, "rate": pursuit_loop_rate("APCS", loop_runs)})
    rows.append({"implementation": "pursuit IMM-Singer, one run at a time", "runs": loop_runs, "rate": pursuit_loop_rate("IMM-Singer", loop_runs)})
    fp = filterpy_rate(loop_runs)
    if fp is not None:
        rows.append({"implementation": "FilterPy IMM-Singer (one run at a time)", "runs": loop_runs, "rate": fp})
    _print(rows, fp)
    print()
    steps = step_rows(2 if quick else 5, 3 if quick else 7)
    _print_steps(steps)
    return rows + steps

if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv, bearings_only="--bearings" in sys.argv, steps_only="--steps" in sys.argv)
