"""Particle-filter speed: pursuit's bootstrap PF against the `particles` library, ICS-PF cost, p1-wsn.

Run from the repository root::

    python benchmarks/bench_pf.py            # full sizes (a few minutes)
    python benchmarks/bench_pf.py --quick    # smaller sizes, for a smoke test

It prints a markdown table and returns the numbers from :func:`main`.  The
peers (``benchmarks/requirements-peers.txt``) are optional: install them in a
separate environment (see that file); a peer that is not importable is
reported as skipped.

What is measured (wall clock, best of ``--repeat`` runs, one process):

* bootstrap PF on UNGM (Gordon et al. 1993; paper P1 eq. 15-16, Q = R = 1):
  M runs of T steps with N particles, systematic resampling at every step,
  in particle-steps per second (M·T·N / seconds).  pursuit filters the M runs
  as one batch through :func:`pursuit.run` (keeping estimates, covariances and
  the step info); ``particles`` runs ``SMC(Bootstrap(...))`` once per run,
  with the same model, N, T and resampling, and stores nothing;
* ICS-PF (10 cuckoo iterations) time per step relative to the bootstrap PF,
  same M, N, T;
* the whole ``p1-wsn`` experiment (100 runs, N = 200, 100 steps, seven
  filters) end to end, with the filtering time of each filter.

numpy and BLAS are used single-threaded only if the caller sets
``OMP_NUM_THREADS=1``; the PF code itself is single-threaded NumPy.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

import pursuit as pu  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.ungm import UNGM  # noqa: E402


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _ungm_data(M: int, T: int, seed: int = 1):
    sc = UNGM(steps=T)
    sim = sc.simulate(run_streams(seed, range(M), 0), M)
    return sc, sim


def bench_pursuit_pf(M: int, T: int, N: int, repeat: int) -> float:
    """Seconds for pursuit's bootstrap PF on M UNGM runs of T steps."""
    sc, sim = _ungm_data(M, T)
    filt = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=N)
    return _best(lambda: pu.run(filt, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)


def bench_particles_pf(M: int, T: int, N: int, repeat: int) -> float | None:
    """Seconds for the `particles` library on the same M runs, or None if it is not installed."""
    try:
        import particles
        from particles import distributions as dists
        from particles import state_space_models as ssm
    except ImportError:
        return None

    class UNGMModel(ssm.StateSpaceModel):
        default_params = {"sigmaX": 1.0, "sigmaY": 1.0}

        def PX0(self):
            return dists.Normal(loc=0.1, scale=np.sqrt(2.0))

        def PX(self, t, xp):  # X_t | X_{t-1}: the forcing term uses k - 1 = t - 1
            return dists.Normal(loc=0.5 * xp + 25.0 * xp / (1.0 + xp**2) + 8.0 * np.cos(1.2 * (t - 1)), scale=self.sigmaX)

        def PY(self, t, xp, x):
            return dists.Normal(loc=x**2 / 20.0, scale=self.sigmaY)

    _, sim = _ungm_data(M, T)
    model = UNGMModel()
    data = [list(sim.measurements[:, i, 0]) for i in range(M)]

    def go():
        for y in data:
            fk = ssm.Bootstrap(ssm=model, data=y)
            alg = particles.SMC(fk=fk, N=N, resampling="systematic", ESSrmin=1.0, store_history=False, collect=None)
            alg.run()

    return _best(go, repeat)


def bench_ics_ratio(M: int, T: int, N: int, repeat: int) -> tuple[float, float]:
    """Seconds per step of ICS-PF and of the bootstrap PF on UNGM."""
    sc, sim = _ungm_data(M, T)
    pf = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=N)
    ics = pu.ICSPF(sc.motion, sc.measurement, particles=N)
    t_pf = _best(lambda: pu.run(pf, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)
    t_ics = _best(lambda: pu.run(ics, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)
    return t_ics / T, t_pf / T


def bench_p1_wsn(runs: int) -> tuple[float, dict[str, float]]:
    """Seconds for the whole p1-wsn experiment, and each filter's filtering time."""
    from pursuit.experiment import find_experiment, load_experiment

    exp = load_experiment(find_experiment(str(ROOT / "experiments" / "p1-wsn.toml")))
    t0 = time.perf_counter()
    out = exp.run(runs=runs)
    total = time.perf_counter() - t0
    summary = out.tables[0]
    i_f, i_t = summary.columns.index("filter"), summary.columns.index("wall_time_s")
    return total, {row[i_f]: float(row[i_t]) for row in summary.rows}


def machine() -> str:
    """The machine line of ``benchmarks/run.py``, with the load average at the start."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import machine as describe

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{describe()}; load average {load:.2f} at start"


def main(quick: bool = False, repeat: int = 2) -> dict[str, Any]:
    """Run the benchmarks, print a markdown table, return the numbers.

    ``quick`` uses small sizes (a smoke test); ``repeat``: best of this many
    timings of pursuit (the peer is timed once: it takes much longer).
    """
    args = argparse.Namespace(quick=quick, repeat=repeat)
    M, T = (20, 20) if args.quick else (100, 100)
    sizes = (1000,) if args.quick else (1000, 10000)
    wsn_runs = 5 if args.quick else 100
    rows: list[tuple[str, str, str]] = []
    numbers: dict[str, Any] = {"machine": machine(), "M": M, "T": T}

    for N in sizes:
        work = M * T * N
        t_ours = bench_pursuit_pf(M, T, N, args.repeat)
        rate = work / t_ours
        numbers[f"pursuit_pf_N{N}"] = rate
        rows.append((f"bootstrap PF, UNGM, M={M}, T={T}, N={N}: pursuit", f"{rate / 1e6:.1f} M particle-steps/s", f"{t_ours:.2f} s"))
        t_peer = bench_particles_pf(M, T, N, 1)
        if t_peer is None:
            rows.append(("same work: particles (Chopin)", "skipped (not installed)", ""))
        else:
            prate = work / t_peer
            numbers[f"particles_pf_N{N}"] = prate
            rows.append(
                ("same work: particles (Chopin)", f"{prate / 1e6:.1f} M particle-steps/s", f"{t_peer:.2f} s; pursuit {rate / prate:.1f}x faster")
            )

    N_ics = 100 if args.quick else 1000
    T_ics = 10 if args.quick else 20
    per_ics, per_pf = bench_ics_ratio(M, T_ics, N_ics, 1)
    numbers["ics_over_pf"] = per_ics / per_pf
    rows.append(
        (f"ICS-PF (10 iterations) vs bootstrap PF, UNGM, M={M}, N={N_ics}", f"{per_ics / per_pf:.1f}x the time per step", f"{per_ics * 1e3:.1f} ms vs {per_pf * 1e3:.2f} ms per step")
    )

    total, per_filter = bench_p1_wsn(wsn_runs)
    numbers["p1_wsn_total_s"] = total
    numbers["p1_wsn_filters_s"] = per_filter
    rows.append((f"p1-wsn experiment end to end ({wsn_runs} runs, N=200, 100 steps)", f"{total:.1f} s", ""))
    for name, sec in per_filter.items():
        rows.append((f"  filtering time: {name}", f"{sec:.2f} s", ""))

    print(f"Machine: {numbers['machine']}\n")
    print("| benchmark | result | detail |")
    print("|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} |")
    return numbers


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--repeat", type=int, default=2, help="best of this many timings")
    cli = ap.parse_args()
    main(quick=cli.quick, repeat=cli.repeat)
