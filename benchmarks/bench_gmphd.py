"""GM-PHD: pursuit's against GNN and against Stone Soup's GM-PHD on the same detections (crossing, Williams 2015).

Work: ``crossing()`` (GOSPA c = 5) and ``williams15()`` (c = 10), 100 runs from root seed 2015,
the same simulated detections for both trackers, a KF per component / track, all runs in one batch
on one core. GM-PHD: adaptive two-point births (``birth_rate`` 0.1), T = 1e-5, U = 4, J_max = 100,
extraction at w ≥ 0.5; GNN: two-point initiation, 2 of 3, 3 misses. GOSPA (p = 2, α = 2) mean over
scans and runs with the 95 % interval over runs. A *scan* is one run's scan: the rate is
runs × K / wall time.

Against Stone Soup (second table, Williams 2015): Stone Soup's ``PointProcessMultiTargetTracker``
with ``PHDUpdater`` (``benchmarks/_stonesoup_mt.py``) has one fixed birth component, so pursuit runs
with the same one (``birth=`` a Gaussian: N((150, 0, 150, 0), diag(100², 2², 100², 2²)), weight 0.1
per scan) besides its default adaptive births; p_S = 0.99, T = 1e-5, U = 4, J_max = 100, extraction
at 0.5; Stone Soup pairs components and detections within Mahalanobis distance 5 (pursuit weighs
every pair).  Stone Soup runs one run at a time on 5 runs (one pass); pursuit on 100 runs (one pass) and on
the peer's 5 (median of 3).  Each rate is given by the wall clock and by the process's CPU time (on a
shared machine the wall clock also counts the waits for the core).  Differences that remain: Stone Soup
adds its birth component at the scan's time (pursuit predicts it from the previous scan) and extracts
each component of weight > 0.5 once (pursuit: round(w) copies of each of weight ≥ 0.5).

Run::

    .venv/bin/python benchmarks/bench_gmphd.py        # 100 runs
    .bench-venv/bin/python benchmarks/bench_gmphd.py  # with the Stone Soup table
    .venv/bin/python benchmarks/run.py --quick --only gmphd
"""

from __future__ import annotations

import _one_core  # first: NumPy on one core (benchmarks/ is on sys.path when a benchmark runs)

_one_core.pin()

import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import pursuit as pu  # noqa: E402
from _timing import median_time  # noqa: E402
from pursuit.multitarget import GMPHDTracker, GNNTracker, gospa, gospa_summary, track_scans, track_switches  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios import crossing, williams15  # noqa: E402


# the one fixed birth component both libraries use on Williams 2015 (Stone Soup's GM-PHD has no adaptive births)
BIRTH_MEAN = np.array([150.0, 0.0, 150.0, 0.0])
BIRTH_COV = np.diag([100.0**2, 2.0**2, 100.0**2, 2.0**2])
BIRTH_RATE = 0.1
SS_GATE = 5.0


def _pursuit_gmphd_row(label, scenario, truth, scans, birth, repeats=1) -> dict:
    kf = pu.KalmanFilter(scenario.motion, scenario.measurement)
    tracker = GMPHDTracker(kf, scenario.p_detect, scenario.clutter_density, birth=birth, birth_rate=BIRTH_RATE, max_speed=scenario.max_speed)
    out = {}
    cpu = []

    def go():
        t0 = time.process_time()
        out["res"] = tracker.track(scans.z, times=scans.times)
        cpu.append(time.process_time() - t0)

    wall = median_time(go, repeats)
    runs = scans.z.shape[1]
    est, mask = out["res"].positions([0, 2])
    s = gospa_summary(gospa(truth.positions([0, 2]), truth.exists, est, mask, c=10.0))["total"]
    scans_done = runs * scenario.steps
    return {
        "implementation": label, "runs": runs, "rate": scans_done / wall, "cpu_rate": scans_done / statistics.median(cpu),
        "gospa": s.mean, "ci": s.half_width,
    }  # fmt: skip


def _stonesoup_gmphd_row(scenario, truth, scans) -> dict | None:
    try:
        import stonesoup  # noqa: F401

        from _stonesoup_mt import gmphd_one_run
    except ImportError:  # pragma: no cover - depends on the environment
        return None
    K, runs = scans.z.shape[:2]
    L = 64
    est = np.full((K, runs, L, 2), np.nan)
    mask = np.zeros((K, runs, L), dtype=bool)
    t0, c0 = time.perf_counter(), time.process_time()
    for r in range(runs):
        per_scan = [zk[np.isfinite(zk).all(axis=-1)] for zk in scans.z[:, r]]
        out = gmphd_one_run(
            per_scan, q=float(scenario.motion.q), R=np.asarray(scenario.measurement.cov(1)), dt=scenario.dt,
            p_detect=scenario.p_detect, p_survive=0.99, clutter_density=scenario.clutter_density, birth_mean=BIRTH_MEAN,
            birth_cov=BIRTH_COV, birth_rate=BIRTH_RATE, prune=1e-5, merge=4.0, max_components=100, extract=0.5, gate=SS_GATE,
        )  # fmt: skip
        for k, pos in enumerate(out):
            n = min(len(pos), L)
            est[k, r, :n] = pos[:n]
            mask[k, r, :n] = True
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = gospa_summary(gospa(truth.positions([0, 2]), truth.exists, est, mask, c=10.0))["total"]
    return {
        "implementation": "Stone Soup GM-PHD, the same fixed birth (one run at a time)", "runs": runs, "rate": runs * K / wall,
        "cpu_rate": runs * K / cpu, "gospa": s.mean, "ci": s.half_width,
    }  # fmt: skip


def stonesoup_table(quick: bool) -> None:
    """pursuit's GM-PHD against Stone Soup's on Williams 2015 (markdown table)."""
    sc = williams15()
    runs, peer_runs = (3, 1) if quick else (100, 5)
    truth, scans = sc.simulate(run_streams(2015, range(runs), 0))
    sel = range(peer_runs)
    t_p, s_p = truth.select_runs(sel), scans.select_runs(sel)
    fixed = pu.Gaussian(BIRTH_MEAN[None], BIRTH_COV[None])
    ours = _pursuit_gmphd_row("pursuit GM-PHD, the same fixed birth", sc, truth, scans, fixed)
    rows = [
        ours,
        _pursuit_gmphd_row(f"pursuit GM-PHD, the same fixed birth (the peer's {peer_runs} runs)", sc, t_p, s_p, fixed, repeats=3),
        _pursuit_gmphd_row("pursuit GM-PHD, adaptive two-point births (its default)", sc, truth, scans, "two-point"),
        _pursuit_gmphd_row(f"pursuit GM-PHD, adaptive births (the peer's {peer_runs} runs)", sc, t_p, s_p, "two-point", repeats=3),
    ]
    peer = _stonesoup_gmphd_row(sc, t_p, s_p)
    print("\n**Against Stone Soup's GM-PHD, Williams 2015 (c = 10)**\n")
    # scans per CPU second beside the wall-clock rate: on a shared machine the wall clock also counts the
    # time the process waited for the core, which differs between the two libraries' turns
    print(
        "| implementation | runs | scans/s (one core) | scans per CPU second | GOSPA mean ± 95 % "
        "| pursuit / Stone Soup speed (wall, CPU) |"
    )
    print("|---|---|---|---|---|---|")
    for r in [*rows, peer]:
        if r is None:
            continue
        ratio = ""
        if peer is not None and r is ours:
            ratio = f"{ours['rate'] / peer['rate']:.0f}x, {ours['cpu_rate'] / peer['cpu_rate']:.0f}x"
        rates = f"{r['rate']:.1f} | {r['cpu_rate']:.1f}"
        print(f"| {r['implementation']} | {r['runs']} | {rates} | {r['gospa']:.3f} ± {r['ci']:.3f} | {ratio} |")


def main(quick: bool = False) -> None:
    gnn_table(quick)
    stonesoup_table(quick)


def gnn_table(quick: bool) -> None:
    runs = 5 if quick else 100
    print(f"{runs} runs, one core, the same detections for both trackers\n")
    print(
        "| scenario | tracker | GOSPA (± 95 %) | localisation | missed | false | switches / run | run-scans / s "
        "| run-scans per CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, scenario, c in (("crossing (c = 5)", crossing(), 5.0), ("williams15 (c = 10)", williams15(), 10.0)):
        truth, scans = scenario.simulate(run_streams(2015, range(runs), 0))
        kf = pu.KalmanFilter(scenario.motion, scenario.measurement)
        pos = list(scenario.motion.position_indices)
        args = (kf, scenario.p_detect, scenario.clutter_density)
        for tracker in (GMPHDTracker(*args, max_speed=scenario.max_speed), GNNTracker(*args, max_speed=scenario.max_speed)):
            t, c0 = time.perf_counter(), time.process_time()
            if isinstance(tracker, GMPHDTracker):
                res = tracker.track(scans.z, times=scans.times)
            else:
                res = track_scans(tracker, scans.z, times=scans.times)
            wall, cpu = time.perf_counter() - t, time.process_time() - c0
            est, mask = res.positions(pos)
            g = gospa(truth.positions(pos), truth.exists, est, mask, c=c)
            switches = track_switches(truth.positions(pos), truth.exists, est, res.label, mask, c=c).sum(-1).mean()
            s = gospa_summary(g)
            print(
                f"| {name} | {tracker.name} | {s['total'].mean:.2f} ± {s['total'].half_width:.2f} | {s['localisation'].mean:.2f} "
                f"| {s['missed'].mean:.2f} | {s['false'].mean:.2f} | {switches:.2f} | {scans.z.shape[0] * runs / wall:.0f} "
                f"| {scans.z.shape[0] * runs / cpu:.0f} |"
            )
            name = ""


if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv)
