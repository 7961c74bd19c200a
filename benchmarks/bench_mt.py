"""Multi-target trackers: pursuit's GNN and JPDA (all runs in one batch) against Stone Soup's (one run at a time).

Work: the Williams (2015) scenario (``mt-williams``: four 2-D CV targets, 10 false alarms per
scan, P_D = 0.9, 81 scans), the same simulated detections for both libraries, the same models
(q = 0.01, R = I), gate probability, P_D and clutter density.  A *scan* is one run's scan: the
rate is runs × 81 / wall time on one core.  Both libraries' tracks are scored by the same GOSPA
(c = 10, p = 2, α = 2; ``pursuit.multitarget.metrics``), mean over scans and runs with the 95 %
interval over runs.

Track management is each library's own: pursuit starts tracks by two-point differencing and
confirms 2 of 3; Stone Soup's ``MultiMeasurementInitiator`` holds a tentative track until it has
3 updates, from a prior with velocity variance 4 m²/s² (``benchmarks/_stonesoup_mt.py``; the values
that served it best on this scenario, see ``SS_MIN_POINTS``).  Both delete a track after 3 scans without an update.
Stone Soup's GOSPA counts every track it reports (it has no tentative state outside the
initiator); pursuit's counts the confirmed tracks.

Run::

    .bench-venv/bin/python benchmarks/bench_mt.py          # needs stonesoup (make bench installs it)
    .venv/bin/python benchmarks/run.py --quick               # smoke run
"""

from __future__ import annotations

import time

import numpy as np

from pursuit.multitarget.gnn import GNNTracker
from pursuit.multitarget.jpda import JPDATracker
from pursuit.multitarget.metrics import gospa, gospa_summary
from pursuit.multitarget.tracking import track_scans
from pursuit.filters import KalmanFilter
from pursuit.rng import run_streams
from pursuit.scenarios.multitarget import williams15

GATE = 0.99
C, P, ALPHA = 10.0, 2.0, 2.0
# Stone Soup's initiator, tuned on this scenario (3 runs, GOSPA): min_points = 2 with its tutorials' wide
# velocity prior confirmed about 17 tracks per scan (GOSPA 26); 3 points and a velocity variance of
# 4 m^2/s^2 (the 5 m/s maximum speed as 2.5 sigma) gave 3.6 over the same runs.
SS_MIN_POINTS = 3
SS_PRIOR_VEL_VAR = 4.0


def _scenario_and_data(runs: int):
    sc = williams15()
    truth, scans = sc.simulate(run_streams(0, range(runs), 0), runs)
    return sc, truth, scans


def _pursuit_tracker(sc, method: str):
    filt = KalmanFilter(sc.motion, sc.measurement)
    cls = GNNTracker if method == "gnn" else JPDATracker
    return cls(filt, sc.p_detect, sc.clutter_density, gate=GATE, max_speed=sc.max_speed)


def _score(sc, truth, est: np.ndarray, est_mask: np.ndarray) -> tuple[float, float]:
    tp = truth.positions(sc.position_indices)
    s = gospa_summary(gospa(tp, truth.exists, est, est_mask, C, P, ALPHA))["total"]
    return s.mean, s.half_width


def pursuit_row(method: str, runs: int, sc, truth, scans) -> dict:
    tracker = _pursuit_tracker(sc, method)
    track_scans(tracker, scans.z[:3, :2], times=scans.times[:3])  # warm caches (imports, first calls)
    t0 = time.perf_counter()
    res = track_scans(tracker, scans.z, times=scans.times)
    wall = time.perf_counter() - t0
    est, mask = res.positions(sc.position_indices)
    mean, half = _score(sc, truth, est, mask)
    return {"implementation": f"pursuit {method.upper()}", "runs": runs, "rate": runs * sc.steps / wall, "gospa": mean, "ci": half}


def stonesoup_row(method: str, runs: int, sc, truth, scans) -> dict | None:
    try:
        from _stonesoup_mt import track_one_run
    except ImportError:  # pragma: no cover - depends on the environment
        return None
    try:
        import stonesoup  # noqa: F401
    except ImportError:
        return None
    q = float(sc.motion.q) if np.ndim(getattr(sc.motion, "q", None)) == 0 else None
    R = np.asarray(sc.measurement.cov(1), dtype=float)
    K = sc.steps
    L = 64
    est = np.full((K, runs, L, 2), np.nan)
    mask = np.zeros((K, runs, L), dtype=bool)
    t0 = time.perf_counter()
    for r in range(runs):
        z = scans.z[:, r]
        per_scan = [zk[np.isfinite(zk).all(axis=-1)] for zk in z]
        out = track_one_run(
            per_scan, method=method, q=q, R=R, dt=sc.dt, p_detect=sc.p_detect,
            clutter_density=sc.clutter_density, gate_probability=GATE,
            min_points=SS_MIN_POINTS, prior_vel_var=SS_PRIOR_VEL_VAR,
        )
        for k, pos in enumerate(out):
            n = min(len(pos), L)
            est[k, r, :n] = pos[:n]
            mask[k, r, :n] = True
    wall = time.perf_counter() - t0
    mean, half = _score(sc, truth, est, mask)
    return {"implementation": f"Stone Soup {method.upper()} (one run at a time)", "runs": runs, "rate": runs * K / wall, "gospa": mean, "ci": half}


def main(quick: bool = False) -> list[dict]:
    """Measure and print a markdown table; returns the rows."""
    runs = 10 if quick else 100
    peer_runs = 2 if quick else 10
    sc, truth, scans = _scenario_and_data(runs)
    rows = []
    for method in ("gnn", "jpda"):
        ours = pursuit_row(method, runs, sc, truth, scans)
        peer = stonesoup_row(method, peer_runs, sc, truth.select_runs(range(peer_runs)), scans.select_runs(range(peer_runs)))
        ours_same = pursuit_row(method, peer_runs, sc, truth.select_runs(range(peer_runs)), scans.select_runs(range(peer_runs)))
        ours_same["implementation"] += f" (the peer's {peer_runs} runs)"
        for r in (ours, ours_same, peer):
            if r is not None:
                r["vs_peer"] = ours["rate"] / peer["rate"] if (peer and r is ours) else None
                rows.append(r)
    print("| implementation | runs | scans/s (one core) | GOSPA mean ± 95 % | pursuit / Stone Soup speed |")
    print("|---|---|---|---|---|")
    for r in rows:
        ratio = f"{r['vs_peer']:.0f}x" if r.get("vs_peer") else ""
        print(f"| {r['implementation']} | {r['runs']} | {r['rate']:.0f} | {r['gospa']:.3f} ± {r['ci']:.3f} | {ratio} |")
    return rows


if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv)
