"""GM-PHD against GNN on the same detections: GOSPA and run-scans per second (crossing, Williams 2015).

Work: ``crossing()`` (GOSPA c = 5) and ``williams15()`` (c = 10), 100 runs from root seed 2015,
the same simulated detections for both trackers, a KF per component / track, all runs in one batch
on one core. GM-PHD: adaptive two-point births (``birth_rate`` 0.1), T = 1e-5, U = 4, J_max = 100,
extraction at w ≥ 0.5; GNN: two-point initiation, 2 of 3, 3 misses. GOSPA (p = 2, α = 2) mean over
scans and runs with the 95 % interval over runs. A *scan* is one run's scan: the rate is
runs × K / wall time.

Run::

    .venv/bin/python benchmarks/bench_gmphd.py        # 100 runs
    .venv/bin/python benchmarks/run.py --quick --only gmphd
"""

from __future__ import annotations

import _one_core  # first: NumPy on one core (benchmarks/ is on sys.path when a benchmark runs)

_one_core.pin()

import time  # noqa: E402

import pursuit as pu  # noqa: E402
from pursuit.multitarget import GMPHDTracker, GNNTracker, gospa, gospa_summary, track_scans, track_switches  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios import crossing, williams15  # noqa: E402


def main(quick: bool = False) -> None:
    runs = 5 if quick else 100
    print(f"{runs} runs, one core, the same detections for both trackers\n")
    print("| scenario | tracker | GOSPA (± 95 %) | localisation | missed | false | switches / run | run-scans / s |")
    print("|---|---|---|---|---|---|---|---|")
    for name, scenario, c in (("crossing (c = 5)", crossing(), 5.0), ("williams15 (c = 10)", williams15(), 10.0)):
        truth, scans = scenario.simulate(run_streams(2015, range(runs), 0))
        kf = pu.KalmanFilter(scenario.motion, scenario.measurement)
        pos = list(scenario.motion.position_indices)
        args = (kf, scenario.p_detect, scenario.clutter_density)
        for tracker in (GMPHDTracker(*args, max_speed=scenario.max_speed), GNNTracker(*args, max_speed=scenario.max_speed)):
            t = time.perf_counter()
            if isinstance(tracker, GMPHDTracker):
                res = tracker.track(scans.z, times=scans.times)
            else:
                res = track_scans(tracker, scans.z, times=scans.times)
            wall = time.perf_counter() - t
            est, mask = res.positions(pos)
            g = gospa(truth.positions(pos), truth.exists, est, mask, c=c)
            switches = track_switches(truth.positions(pos), truth.exists, est, res.label, mask, c=c).sum(-1).mean()
            s = gospa_summary(g)
            print(
                f"| {name} | {tracker.name} | {s['total'].mean:.2f} ± {s['total'].half_width:.2f} | {s['localisation'].mean:.2f} "
                f"| {s['missed'].mean:.2f} | {s['false'].mean:.2f} | {switches:.2f} | {scans.z.shape[0] * runs / wall:.0f} |"
            )
            name = ""


if __name__ == "__main__":
    import sys

    main(quick="--quick" in sys.argv)
