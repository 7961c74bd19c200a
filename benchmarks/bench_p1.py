"""Paper P1's three particle filters on the ``p1-wsn`` workload, compiled (numba, one thread).

Run from the repository root (one core: ``taskset -c 1``)::

    taskset -c 1 python benchmarks/bench_p1.py            # 100 runs, N = 200, 100 steps
    taskset -c 1 python benchmarks/bench_p1.py --quick    # 20 runs, 30 steps
    taskset -c 1 python benchmarks/bench_p1.py --floor    # where a cuckoo step's time goes

What is measured (wall clock, median of ``--repeat`` runs, one process, after
one untimed run that compiles the kernels; then the process CPU time of one
more run, steadier than the wall clock on a shared machine): :func:`pursuit.run` of the
bootstrap PF, CS-PF and ICS-PF (10 cuckoo iterations, the default MH
acceptance, and the paper-literal greedy one) on the ``p1-wsn`` scenario
(one range node, CV target, discrete white-noise acceleration), all runs as
one batch with ``backend="numba"`` and ``numba.set_num_threads(1)``, each
with its time relative to the bootstrap PF.  Issue 19's target: PF + CS-PF +
ICS-PF under 1 s together, the cuckoo filters within about 4x the PF.

``--floor`` splits the MH cuckoo step's cost, in the same run: the
bootstrap PF per particle-step; CS-PF with 0 and 10 iterations (the step
without moves, and the cost of one proposal from the difference: 10
iterations make 2·10 proposals per particle); and inside numba, one
fitness (likelihood) evaluation of the kernel and one Lévy step entry
(Mantegna's ``cbrt``).  From these it prints the smallest ratio to the PF
that 20 proposals a particle allow, and the proposal cost 4x would need.
Times here are process CPU time (``time.process_time``), less disturbed by
other processes on a shared machine than the wall clock.
"""

from __future__ import annotations

import argparse
import sys
import time
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
    cpu: dict[str, float] = {}
    for name, make in FILTERS.items():
        filt = make(sc.motion, sc.measurement, N)

        def once():
            return pu.run(filt, sim.measurements, sim.prior, rng=run_streams(7, range(runs), 1))

        once()  # compile (or load the cached kernels)
        secs[name] = median_time(once, repeat)
        cpu[name] = _cpu_time(once, 1)
    pf, pf_cpu = secs["PF"], cpu["PF"]
    print(f"### P1 filters on p1-wsn, numba, one thread (M = {runs}, N = {N}, T = {steps}, 10 cuckoo iterations)\n")
    print("| filter | seconds | × PF | CPU seconds | × PF (CPU) |")
    print("|---|---|---|---|---|")
    for name, s in secs.items():
        print(f"| {name} | {s:.3f} | {s / pf:.1f} | {cpu[name]:.3f} | {cpu[name] / pf_cpu:.1f} |")
    total = secs["PF"] + secs["CS-PF (mh)"] + secs["ICS-PF (mh)"]
    print(f"\nPF + CS-PF + ICS-PF (mh): {total:.3f} s (target: under 1 s at full size)\n")
    return secs


def _cpu_time(fn, repeat: int) -> float:
    """Smallest process CPU seconds of ``repeat`` calls of ``fn``."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def floor(quick: bool = False, repeat: int = 3) -> dict[str, float]:
    """Measure and print where an MH cuckoo step's time goes (module docstring); returns nanoseconds."""
    import dataclasses
    import math

    import numba
    from numba import njit

    from pursuit._compiled import cuckoo_kernels as CK
    from pursuit._compiled.particle import measurement_args
    from pursuit._compiled.specs import measurement_spec
    from pursuit.filters.cuckoo import mantegna_sigma
    from pursuit.filters.cuckoo_mh import noise_factor

    numba.set_num_threads(1)
    runs, steps, N = (20, 30, 200) if quick else (100, 100, 200)
    sc = p1_wsn(steps)
    sim = sc.simulate(run_streams(20220702, range(runs), 0), runs)
    ps = runs * steps * N

    def timed(filt) -> float:
        def once():
            return pu.run(filt, sim.measurements, sim.prior, rng=run_streams(7, range(runs), 1))

        once()
        return _cpu_time(once, repeat)

    pf = timed(FILTERS["PF"](sc.motion, sc.measurement, N))
    cs = pu.CSPF(sc.motion, sc.measurement, particles=N, backend="numba")
    n_iter = cs.search.n_iter
    t0 = timed(dataclasses.replace(cs, search=dataclasses.replace(cs.search, n_iter=0)))
    t10 = timed(cs)
    per_prop = (t10 - t0) / (ps * 2 * n_iter)

    @njit(cache=False)
    def fitness_loop(sensor, X, z, valid, cst, H, F, reps):
        for _ in range(reps):
            CK._fitness_rows(sensor, X, 0, X.shape[0], z, valid, True, False, cst, H, F)
        return F[0]

    @njit(cache=False)
    def levy_loop(u, v, sigma_u, reps):
        s = 0.0
        for _ in range(reps):
            for i in range(u.shape[0]):
                s += CK._mantegna(u[i], v[i], 1.5, sigma_u)
        return s

    rng = np.random.default_rng(0)
    sensor = measurement_args(measurement_spec(sc.measurement))
    X = np.array([10.0, 0.5, 40.0, 0.8]) + rng.standard_normal((N, 4))
    z, valid = np.array([math.hypot(10.0, 40.0)]), np.array([True])
    F, H = np.empty(N), np.empty((N, 1))
    args = (sensor, X, z, valid, CK._fit_consts(sensor.R, False), H, F)
    reps = 2000
    fitness_loop(*args, 1)
    fit = _cpu_time(lambda: fitness_loop(*args, reps), repeat) / (reps * N)
    u, v = rng.standard_normal(N), rng.standard_normal(N)
    assert cs.search.beta == 1.5  # the cbrt branch of the Lévy step, timed below
    levy_loop(u, v, mantegna_sigma(1.5), 1)
    levy = _cpu_time(lambda: levy_loop(u, v, mantegna_sigma(1.5), reps), repeat) / (reps * N)
    r = noise_factor(sc.motion, 1, 1.0).shape[1]  # Mantegna entries per Lévy proposal
    ns = {
        "pf_particle_step": pf / ps * 1e9,
        "cuckoo_step_without_moves": t0 / ps * 1e9,
        "proposal": per_prop * 1e9,
        "fitness": fit * 1e9,
        "levy_entry": levy * 1e9,
    }
    need = (4 * pf - t0) / (ps * 2 * n_iter) * 1e9
    print(f"### Cost floor of the MH cuckoo step on p1-wsn, numba, one thread (M = {runs}, N = {N}, T = {steps})\n")
    print("| piece | ns |")
    print("|---|---|")
    print(f"| bootstrap PF, one particle-step | {ns['pf_particle_step']:.0f} |")
    print(f"| CS-PF step without moves (n_iter = 0), one particle | {ns['cuckoo_step_without_moves']:.0f} |")
    print(f"| one MH proposal (from n_iter = {n_iter} minus 0; 2·{n_iter} a particle) | {ns['proposal']:.0f} |")
    print(f"| one fitness (likelihood) evaluation in the kernel | {ns['fitness']:.1f} |")
    print(f"| one Lévy step entry (Mantegna, cbrt); r = {r} a Lévy proposal | {ns['levy_entry']:.1f} |")
    print(
        f"\nCS-PF / PF = {t10 / pf:.1f}; with {2 * n_iter} proposals a particle, 4x the PF needs "
        f"{need:.0f} ns a proposal (the step without moves included), against {ns['proposal']:.0f} measured; "
        f"a Lévy proposal's {r} entries alone take {r * ns['levy_entry']:.0f} ns and its fitness {ns['fitness']:.0f} ns.\n"
    )
    return ns


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--floor", action="store_true", help="split the MH cuckoo step's cost instead (module docstring)")
    a = ap.parse_args()
    (floor if a.floor else main)(quick=a.quick, repeat=a.repeat)
