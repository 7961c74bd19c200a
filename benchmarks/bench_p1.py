"""Paper P1's three particle filters on the ``p1-wsn`` workload, compiled (numba, one thread).

Run from the repository root (one core: ``taskset -c 1``)::

    taskset -c 1 python benchmarks/bench_p1.py            # 100 runs, N = 200, 100 steps
    taskset -c 1 python benchmarks/bench_p1.py --quick    # 20 runs, 30 steps

What is measured (wall clock, median of ``--repeat`` runs, one process, after
one untimed run that compiles the kernels): :func:`pursuit.run` of the
bootstrap PF, CS-PF and ICS-PF (10 cuckoo iterations, the default MH
acceptance, and the paper-literal greedy one) on the ``p1-wsn`` scenario
(one range node, CV target, discrete white-noise acceleration), all runs as
one batch with ``backend="numba"`` and ``numba.set_num_threads(1)``, each
with its time relative to the bootstrap PF.  Issue 19's target: PF + CS-PF +
ICS-PF under 1 s together, the cuckoo filters within about 4x the PF.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

from _timing import median_time  # noqa: E402 (benchmarks/ is on sys.path when run as a script)

import pursuit as pu  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.wsn import WSNRange  # noqa: E402


def p1_wsn(steps: int) -> WSNRange:
    """The scenario of ``experiments/p1-wsn.toml``."""
    return WSNRange(
        anchors=[[0.0, 0.0]], sigma=float(np.sqrt(0.72)), steps=steps, dt=1.0, q=0.01, noise="discrete",
        x0=[10.0, 0.5, 40.0, 0.8], P0=np.diag([1.5, 1.4, 0.9, 0.03]), prior_mean="truth",
    )


FILTERS = {
    "PF": lambda m, h, N: pu.BootstrapParticleFilter(m, h, particles=N, backend="numba"),
    "CS-PF (mh)": lambda m, h, N: pu.CSPF(m, h, particles=N, backend="numba"),
    "ICS-PF (mh)": lambda m, h, N: pu.ICSPF(m, h, particles=N, backend="numba"),
    "CS-PF (greedy)": lambda m, h, N: pu.CSPF(m, h, particles=N, acceptance="greedy", backend="numba"),
    "ICS-PF (greedy)": lambda m, h, N: pu.ICSPF(m, h, particles=N, acceptance="greedy", backend="numba"),
}


def main(quick: bool = False, repeat: int = 3) -> dict[str, float]:
    """Measure and print the table; returns seconds per filter."""
    try:
        import numba
    except ImportError:
        print("numba is not installed: nothing to measure")
        return {}
    numba.set_num_threads(1)
    runs, steps, N = (20, 30, 200) if quick else (100, 100, 200)
    sc = p1_wsn(steps)
    sim = sc.simulate(run_streams(20220702, range(runs), 0), runs)
    secs: dict[str, float] = {}
    for name, make in FILTERS.items():
        filt = make(sc.motion, sc.measurement, N)

        def once():
            return pu.run(filt, sim.measurements, sim.prior, rng=run_streams(7, range(runs), 1))

        once()  # compile (or load the cached kernels)
        secs[name] = median_time(once, repeat)
    pf = secs["PF"]
    print(f"### P1 filters on p1-wsn, numba, one thread (M = {runs}, N = {N}, T = {steps}, 10 cuckoo iterations)\n")
    print("| filter | seconds | × PF |")
    print("|---|---|---|")
    for name, s in secs.items():
        print(f"| {name} | {s:.3f} | {s / pf:.1f} |")
    total = secs["PF"] + secs["CS-PF (mh)"] + secs["ICS-PF (mh)"]
    print(f"\nPF + CS-PF + ICS-PF (mh): {total:.3f} s (target: under 1 s at full size)\n")
    return secs


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    main(quick=a.quick, repeat=a.repeat)
