"""Partial unscented particle filter (p3-upf's scenario): NumPy and numba, each against the bootstrap PF in the same run.

Run from the repository root, on one core::

    taskset -c 1 .venv/bin/python benchmarks/bench_upf.py            # full sizes (about a minute)
    .venv/bin/python benchmarks/bench_upf.py --quick                 # smaller sizes, for a smoke test

Work: the scenario of ``experiments/p3-upf.toml`` (a 2-D constant-velocity
target with continuous white-noise acceleration ranged by one node,
N = 200 particles, 100 steps, 100 runs, resampling when ESS < N/2), filtered
through :func:`pursuit.run` with every run's own stream, as the experiments
do.  Rows: the bootstrap PF and the partial UPF at l = 0.1, 0.5 and 1, with
NumPy and with numba on one thread (``numba.set_num_threads(1)``); the time
is the median of ``REPEATS`` calls after a warm-up (compilation excluded).
"× PF" is the ratio to the bootstrap PF of the same backend measured in the
same run, "numba speed-up" the NumPy time of the row's filter over its
numba time.  NumPy's BLAS runs on one thread through ``benchmarks/run.py``
(:mod:`_one_core`).
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

from _timing import median_time  # noqa: E402 (benchmarks/ is on sys.path when run as a script)

import pursuit as pu  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios import WSNRange  # noqa: E402

REPEATS = 3
FRACTIONS = (0.1, 0.5, 1.0)


def scenario(steps: int) -> WSNRange:
    """p3-upf's scenario (its first variant, one node)."""
    return WSNRange(
        anchors=np.array([[0.0, 0.0]]), sigma=0.848528137423857, steps=steps, dt=1.0, q=0.01, noise="continuous",
        x0=np.array([10.0, 0.5, 40.0, 0.8]), P0=np.diag([1.5, 1.4, 0.9, 0.03]), prior_mean="truth",
    )


def _filter(sc, fraction: float | None, backend: str, N: int):
    if fraction is None:
        return pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=N, ess_threshold=0.5, backend=backend)
    return pu.PartialUPF(sc.motion, sc.measurement, particles=N, fraction=fraction, ess_threshold=0.5, backend=backend)


def seconds(sc, sim, fraction: float | None, backend: str, M: int, N: int, repeats: int) -> float:
    """Median seconds of ``pursuit.run`` over the M runs (after a two-step warm-up that compiles)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a fallback to NumPy would make the numba row meaningless
        filt = _filter(sc, fraction, backend, N)
    if backend == "numba":
        import numba

        numba.set_num_threads(1)
    pu.run(filt, sim.measurements[:2], sim.prior, rng=run_streams(2, range(M), 1))
    return median_time(lambda: pu.run(filt, sim.measurements, sim.prior, rng=run_streams(2, range(M), 1)), repeats)


def main(quick: bool = False) -> list[dict]:
    """Measure and print a markdown table; returns the rows."""
    M, T, N = (10, 20, 100) if quick else (100, 100, 200)
    repeats = 1 if quick else REPEATS
    sc = scenario(T)
    sim = sc.simulate(run_streams(1, range(M), 0), M)
    rows = []
    for backend in ("numpy", "numba"):
        for fraction in (None, *FRACTIONS):
            rows.append({"fraction": fraction, "backend": backend, "seconds": seconds(sc, sim, fraction, backend, M, N, repeats)})
    pf = {r["backend"]: r["seconds"] for r in rows if r["fraction"] is None}
    numpy_time = {r["fraction"]: r["seconds"] for r in rows if r["backend"] == "numpy"}
    print(f"M = {M} runs, T = {T} steps, N = {N} particles, ESS < N/2; one thread\n")
    print("| filter | backend | s | × PF (same backend) | numba speed-up |")
    print("|---|---|---|---|---|")
    for r in rows:
        name = "bootstrap PF" if r["fraction"] is None else f"UPF l = {r['fraction']:g}"
        r["vs_pf"] = r["seconds"] / pf[r["backend"]]
        r["speedup"] = numpy_time[r["fraction"]] / r["seconds"]
        up = f"{r['speedup']:.1f}x" if r["backend"] == "numba" else ""
        print(f"| {name} | {r['backend']} | {r['seconds']:.3f} | {r['vs_pf']:.1f}x | {up} |")
    return rows


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
