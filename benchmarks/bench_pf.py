"""Particle filters: pursuit (NumPy and numba) against the `particles` library, 2-D CV target, ICS-PF cost.

Run from the repository root::

    python benchmarks/bench_pf.py            # full sizes (a few minutes)
    python benchmarks/bench_pf.py --quick    # smaller sizes, for a smoke test

It prints a markdown table and returns the numbers from :func:`main`.  The
peers (``benchmarks/requirements-peers.txt``) are optional: install them in a
separate environment (see that file); a peer that is not importable is
reported as skipped.

What is measured (wall clock, median of ``--repeat`` runs, one process):

* bootstrap PF on UNGM (Gordon et al. 1993; paper P1 eq. 15-16, Q = R = 1):
  M runs of T steps with N particles, systematic resampling at every step,
  in particle-steps per second (M·T·N / seconds).  pursuit filters the M runs
  as one batch through :func:`pursuit.run` (keeping estimates, covariances and
  the step info); ``particles`` runs ``SMC(Bootstrap(...))`` once per run,
  with the same model, N, T and resampling, and stores nothing;
* ICS-PF (10 cuckoo iterations) time per step relative to the bootstrap PF,
  same M, N, T;
* bootstrap PF on a 2-D constant-velocity target ranged by three anchors
  (M = 100, T = 100, N = 1000 and 10 000), NumPy and numba against
  ``particles`` with the same F, Q, anchors, noise, priors and measurements;
* the whole ``p1-wsn`` experiment (7 filters, both layouts, 100 runs, N = 200, 100 steps)
  end to end, NumPy and with ``--compute-backend numba``;
* pursuit's numba rows use ``numba.set_num_threads(1)`` or ``(2)``.

Stone Soup's particle filter is not measured: it filters one run at a time
through Python objects per step, and at N = 1000 a single run of the UNGM
work takes minutes on this machine kind.

NumPy's BLAS runs on one thread when this runs through ``benchmarks/run.py``
(``make bench``), which pins it before NumPy is imported; the PF code itself
is single-threaded NumPy.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

from _timing import median_time  # noqa: E402 (benchmarks/ is on sys.path when run as a script)

import pursuit as pu  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.ungm import UNGM  # noqa: E402


# The clock of every timing here: the wall clock, or the process's CPU time with --cpu (a loaded
# machine: pursuit's numba rows run on one thread and `particles` on one BLAS thread, so CPU time is
# the time on one core).
_CLOCK = time.perf_counter


def _best(fn, repeat: int) -> float:
    """Median time (``_CLOCK``) of ``repeat`` calls of ``fn``."""
    return median_time(fn, repeat, _CLOCK)


def _ungm_data(M: int, T: int, seed: int = 1):
    sc = UNGM(steps=T)
    sim = sc.simulate(run_streams(seed, range(M), 0), M)
    return sc, sim


def _threads(n) -> int | None:
    """Set numba's thread count to ``n`` (None: leave it); return the count before, to restore."""
    if n is None:
        return None
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(n)
    return before


def bench_pursuit_pf(M: int, T: int, N: int, repeat: int, backend: str = "numpy", threads=None, scenario=None) -> float:
    """Seconds for pursuit's bootstrap PF on M runs of T steps (UNGM unless ``scenario``)."""
    if scenario is None:
        sc, sim = _ungm_data(M, T)
    else:
        sc = scenario
        sim = sc.simulate(run_streams(1, range(M), 0), M)
    filt = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=N, backend=backend)
    before = _threads(threads)
    pu.run(filt, sim.measurements[:2], sim.prior, rng=run_streams(2, range(M), 1))  # compile / warm up
    t = _best(lambda: pu.run(filt, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)
    _threads(before)  # as it was (a pinned process may have one thread only)
    return t


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


def bench_particles_cv(scenario, M: int, T: int, N: int, repeat: int) -> float | None:
    """Seconds for the `particles` library on the 2-D CV range-only work, or None if it is not installed.

    Same motion (F and the noise factor G of the scenario's constant-velocity model), the same
    three range anchors and noise, each run's own prior mean and the same
    measurements as pursuit's rows; systematic resampling at every step.
    """
    try:
        import particles
        from particles import distributions as dists
        from particles import state_space_models as ssm
    except ImportError:
        return None
    sim = scenario.simulate(run_streams(1, range(M), 0), M)
    F = np.asarray(scenario.motion.transition_matrix())
    G = np.asarray(scenario.motion.noise_factor())  # Q = G Gᵀ is singular (discrete white-noise acceleration)
    anchors = np.asarray(scenario.anchors)
    R = scenario.sigma**2 * np.eye(len(anchors))
    P0 = np.asarray(sim.prior.cov)

    class LinearGaussianMove(dists.ProbDist):
        """x = loc + G ξ, ξ ~ N(0, I): what the bootstrap filter draws (MvNormal needs a full-rank Q)."""

        dim = 4

        def __init__(self, loc):
            self.loc = loc

        def rvs(self, size=None):
            return self.loc + np.random.standard_normal((self.loc.shape[0], G.shape[1])) @ G.T

    class RangeCV(ssm.StateSpaceModel):
        default_params = {"mu0": np.zeros(4)}

        def PX0(self):
            return dists.MvNormal(loc=self.mu0, cov=P0)

        def PX(self, t, xp):
            return LinearGaussianMove(xp @ F.T)

        def PY(self, t, xp, x):
            pos = x[:, [0, 2]]
            ranges = np.sqrt(((pos[:, None, :] - anchors[None, :, :]) ** 2).sum(-1))
            return dists.MvNormal(loc=ranges, cov=R)

    models = [RangeCV(mu0=np.asarray(sim.prior.mean)[i]) for i in range(M)]
    data = [sim.measurements[:, i, :] for i in range(M)]

    def go():
        for model, y in zip(models, data):
            fk = ssm.Bootstrap(ssm=model, data=y)
            particles.SMC(fk=fk, N=N, resampling="systematic", ESSrmin=1.0, store_history=False, collect=None).run()

    return _best(go, repeat)


def bench_ics_ratio(M: int, T: int, N: int, repeat: int) -> tuple[float, float]:
    """Seconds per step of ICS-PF and of the bootstrap PF on UNGM."""
    sc, sim = _ungm_data(M, T)
    pf = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=N)
    ics = pu.ICSPF(sc.motion, sc.measurement, particles=N)
    t_pf = _best(lambda: pu.run(pf, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)
    t_ics = _best(lambda: pu.run(ics, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeat)
    return t_ics / T, t_pf / T


def bench_p1_wsn(runs: int, backend: str = "numpy") -> tuple[float, dict[str, float]]:
    """Seconds for the whole p1-wsn experiment, and each filter's filtering time.

    ``backend`` is the default compute backend of the experiment's filters
    (what ``--compute-backend`` sets); the numba kernels are compiled by a
    short warm-up run first, so compile time is not counted.
    """
    from pursuit.compute import CompiledBackendWarning, set_default_backend
    from pursuit.experiment import find_experiment, load_experiment

    set_default_backend(backend)
    try:
        warnings.simplefilter("ignore", CompiledBackendWarning)  # the UPF has no compiled path: expected
        exp = load_experiment(find_experiment(str(ROOT / "experiments" / "p1-wsn.toml")))
        if backend != "numpy":
            exp.run(runs=2)
        t0 = time.perf_counter()
        out = exp.run(runs=runs)
        total = time.perf_counter() - t0
    finally:
        set_default_backend(None)
    summary = out.tables[0]
    i_f, i_t = summary.columns.index("filter"), summary.columns.index("wall_time_s")
    i_v = summary.columns.index("variant") if "variant" in summary.columns else None  # the layouts (one node, grid)
    return total, {(row[i_f] if i_v is None else f"{row[i_f]} [{row[i_v]}]"): float(row[i_t]) for row in summary.rows}


def machine() -> str:
    """The machine line of ``benchmarks/run.py``, with the load average at the start."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import machine as describe

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{describe()}; load average {load:.2f} at start"


def main(quick: bool = False, repeat: int = 3) -> dict[str, Any]:
    """Run the benchmarks, print a markdown table, return the numbers.

    ``quick`` uses small sizes (a smoke test); ``repeat``: median of this many
    timings of pursuit (the peer is timed once on fewer runs: it takes much
    longer, and its cost per run does not depend on the number of runs).
    """
    try:
        import numba  # noqa: F401

        has_numba = True
    except ImportError:
        has_numba = False
    M, T = (10, 20) if quick else (100, 100)
    sizes = (1000,) if quick else (1000, 10000)
    peer_runs = 2 if quick else 10
    rows: list[tuple[str, str, str]] = []
    numbers: dict[str, Any] = {"machine": machine(), "M": M, "T": T}

    def add(label, key, secs, work, ref=None, note=""):
        rate = work / secs
        numbers[key] = rate
        ratio = f"{rate / ref:.1f}x" if ref else ""
        rows.append((label, f"{rate / 1e6:.1f}", ratio, note))
        return rate

    for N in sizes:
        work = M * T * N
        t_peer = bench_particles_pf(peer_runs, T, N, 1)
        ref = None
        if t_peer is not None:
            ref = peer_runs * T * N / t_peer
        add(f"UNGM N={N}: pursuit numpy", f"numpy_N{N}", bench_pursuit_pf(M, T, N, repeat), work, ref, f"M={M}")
        if has_numba:
            for th in (1, 2):
                add(f"UNGM N={N}: pursuit numba, {th} thread{'s' if th > 1 else ''}", f"numba{th}_N{N}",
                    bench_pursuit_pf(M, T, N, repeat, "numba", th), work, ref, f"M={M}")
        if ref is None:
            rows.append((f"UNGM N={N}: particles (Chopin)", "not installed", "", ""))
        else:
            numbers[f"particles_N{N}"] = ref
            rows.append((f"UNGM N={N}: particles (Chopin)", f"{ref / 1e6:.1f}", "1.0x", f"one run at a time; {peer_runs} runs"))

    from pursuit.scenarios.wsn import WSNRange

    cv = WSNRange(anchors=[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], sigma=2.0, steps=T)
    for N in sizes:
        work = M * T * N
        t_peer = bench_particles_cv(cv, peer_runs, T, N, 1)
        ref = None if t_peer is None else peer_runs * T * N / t_peer
        add(f"2-D CV, 3 range anchors, N={N}: pursuit numpy", f"cv_numpy_N{N}", bench_pursuit_pf(M, T, N, repeat, scenario=cv), work, ref, f"M={M}")
        if has_numba:
            for th in (1, 2):
                add(f"2-D CV, 3 range anchors, N={N}: pursuit numba, {th} thread{'s' if th > 1 else ''}", f"cv_numba{th}_N{N}",
                    bench_pursuit_pf(M, T, N, repeat, "numba", th, scenario=cv), work, ref, f"M={M}")
        if ref is None:
            rows.append((f"2-D CV, 3 range anchors, N={N}: particles (Chopin)", "not installed", "", ""))
        else:
            numbers[f"cv_particles_N{N}"] = ref
            rows.append((f"2-D CV, 3 range anchors, N={N}: particles (Chopin)", f"{ref / 1e6:.1f}", "1.0x", f"one run at a time; {peer_runs} runs"))

    N_ics = 100 if quick else 1000
    T_ics = 10 if quick else 20
    per_ics, per_pf = bench_ics_ratio(M, T_ics, N_ics, 1)
    numbers["ics_over_pf"] = per_ics / per_pf
    rows.append((f"ICS-PF (10 iterations) vs bootstrap PF, UNGM, M={M}, N={N_ics}, numpy", f"{per_ics / per_pf:.1f}x the time per step", "",
                 f"{per_ics * 1e3:.1f} ms vs {per_pf * 1e3:.2f} ms per step"))

    wsn_runs = 4 if quick else 100
    backends = ("numpy", "numba") if has_numba else ("numpy",)
    for backend in backends:
        total, per_filter = bench_p1_wsn(wsn_runs, backend)
        numbers[f"p1_wsn_{backend}"] = {"total": total, **per_filter}
        parts = ", ".join(f"{name} {secs:.1f} s" for name, secs in per_filter.items())
        rows.append((f"p1-wsn end to end ({wsn_runs} runs, 7 filters, N = 200, both layouts), {backend}", f"{total:.1f} s wall", "", parts))

    print(f"Machine: {numbers['machine']}\n")
    print("| work: implementation | M particle-steps/s | vs particles | note |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} |")
    return numbers


def main_cv(N: int = 1000, repeat: int = 5, peer_runs: int = 10) -> dict[str, Any]:
    """The 2-D CV range-anchor rows alone at one N (issue 22): ``particles``, then pursuit numba on one thread, then again ``particles``.

    The peer is timed before and after pursuit, and the ratio is taken to
    the mean of its two rates, so a change of load during the run shows as
    the spread of the two peer figures.  The UNGM row (same M, T, N, numba,
    one thread) gives the cost per particle-step of the 2-D path relative to
    the 1-D one.
    """
    from pursuit.scenarios.wsn import WSNRange

    M, T = 100, 100
    cv = WSNRange(anchors=[[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]], sigma=2.0, steps=T)
    work = M * T * N
    # The peer's first call pays its imports and first-use costs: time it as median of 3, before and after.
    peer1 = peer_runs * T * N / bench_particles_cv(cv, peer_runs, T, N, 3)
    numba1 = work / bench_pursuit_pf(M, T, N, repeat, "numba", 1, scenario=cv)
    ungm1 = work / bench_pursuit_pf(M, T, N, repeat, "numba", 1)
    peer2 = peer_runs * T * N / bench_particles_cv(cv, peer_runs, T, N, 3)
    ref = 0.5 * (peer1 + peer2)
    print(f"Machine: {machine()}\n")
    print("| work: implementation | M particle-steps/s | vs particles | note |")
    print("|---|---|---|---|")
    print(f"| 2-D CV, 3 range anchors, N={N}: pursuit numba, 1 thread | {numba1 / 1e6:.1f} | {numba1 / ref:.1f}x | M={M} |")
    print(f"| UNGM N={N}: pursuit numba, 1 thread | {ungm1 / 1e6:.1f} | | M={M}; the 2-D path costs {ungm1 / numba1:.1f}x more per particle-step |")
    print(f"| 2-D CV, 3 range anchors, N={N}: particles (Chopin), before / after | {peer1 / 1e6:.2f} / {peer2 / 1e6:.2f} | 1.0x | one run at a time; {peer_runs} runs, median of 3 |")
    return {"cv_numba1": numba1, "ungm_numba1": ungm1, "particles": (peer1, peer2)}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    ap.add_argument("--repeat", type=int, default=3, help="median of this many timings")
    ap.add_argument("--cv", action="store_true", help="only the 2-D CV range-anchor rows at N = 1000, numba on one thread")
    ap.add_argument("--cpu", action="store_true", help="time with the process's CPU time (a loaded machine; run with OPENBLAS_NUM_THREADS=1)")
    cli = ap.parse_args()
    if cli.cpu and not cli.cv:
        ap.error("--cpu goes with --cv: the full table has two-thread rows, whose CPU time is not the time on one core")
    if cli.cpu:
        _CLOCK = time.process_time
        print("(CPU time of this process: time.process_time)\n")
    if cli.cv:
        main_cv(repeat=cli.repeat)
    else:
        main(quick=cli.quick, repeat=cli.repeat)
