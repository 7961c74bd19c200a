"""Cold compile CPU of each compiled kernel family the test suite uses: what a user waits for on first use.

Each family runs in a fresh Python process with an empty ``NUMBA_CACHE_DIR``
and ``PURSUIT_KERNEL_DIR`` (a temporary folder), so numba compiles every
kernel it needs; the number printed is that process's CPU seconds (user +
system, ``resource.getrusage(RUSAGE_CHILDREN)``) minus those of a process that
only imports pursuit and builds the filters.  CPU
time, not wall time, so that the figure holds on a shared machine (it is
steady to a few per cent; the wall time is printed beside it).  A second
column runs the family again with the cache the first left behind: what a
later process pays to load the kernels.

Families (each: one ``pursuit.monte_carlo`` run, which compiles the batched
kernel, then one ``filt.step`` from Python on batch ``()``, which compiles
the one-run kernel):

* ``kf``: the linear KF on ``LinearCV`` (a generated kernel),
* ``ekf``, ``ukf``: range-bearing on a 2-D CV target,
* ``pf``: the bootstrap PF on ``WSNRange``; ``pf-ungm``: on ``UNGM``,
* ``ics-pf``: the improved cuckoo-search PF (MH moves) on ``WSNRange``,
* ``upf``: the partial UPF (l = 0.5) on ``WSNRange``,
* ``observer``: EKF and UKF with ``ObserverBearings`` (the moving observer).

Run from the repository root, on one core::

    PYTHONPATH=src taskset -c 1 .venv/bin/python benchmarks/compile_times.py            # every family
    PYTHONPATH=src taskset -c 1 .venv/bin/python benchmarks/compile_times.py ukf upf    # some
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_SETUP = """
import warnings
import numpy as np
import pursuit as pu
from pursuit.filters.cuckoo import ICSPF, CuckooSearch
from pursuit.models import ConstantVelocity, ObserverBearings, RangeBearing
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, WSNRange
from pursuit.scenarios.ungm import UNGM
warnings.simplefilter("error")  # a fallback to NumPy would time nothing
NB = dict(backend="numba")
M = 3

def _simulate(motion, sensor, prior):
    rng = np.random.default_rng(0)
    x = np.tile(prior.mean, (M, 1))
    zs = np.empty((5, M, sensor.dim))
    for k in range(5):
        x = motion.sample(x, k + 1, rng)
        zs[k] = sensor.sample(x, k + 1, rng)
    return zs, prior

def build(name):
    \"\"\"(measurements (K, M, m), prior, filters) of one family.\"\"\"
    cv = ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")
    prior4 = pu.Gaussian(np.array([3000.0, 1.0, 4000.0, 0.5]), np.diag([1e4, 1.0, 1e4, 1.0]))
    sc = {"kf": LinearCV(ndim=2, steps=5), "pf-ungm": UNGM(steps=5)}.get(name, WSNRange(steps=5))
    if name in ("ekf", "ukf"):
        zs, prior = _simulate(cv, RangeBearing(np.array([0.0, -50.0]), 1.0, 0.02), prior4)
    elif name == "observer":
        t = np.arange(1, 6)
        ob = ObserverBearings(np.column_stack([200.0 * np.sin(t / 5.0), 30.0 * t]), 2e-3, position_indices=(0, 2))
        zs, prior = _simulate(cv, ob, prior4)
    else:
        sim = sc.simulate(run_streams(1, range(M), 0), M)
        zs, prior = sim.measurements, sim.prior
    if name == "kf":
        filters = [pu.KalmanFilter(sc.motion, sc.measurement, **NB)]
    elif name == "ekf":
        filters = [pu.ExtendedKalmanFilter(cv, RangeBearing(np.array([0.0, -50.0]), 1.0, 0.02), **NB)]
    elif name == "ukf":
        filters = [pu.UnscentedKalmanFilter(cv, RangeBearing(np.array([0.0, -50.0]), 1.0, 0.02), **NB)]
    elif name == "observer":
        filters = [pu.ExtendedKalmanFilter(cv, ob, **NB), pu.UnscentedKalmanFilter(cv, ob, **NB)]
    elif name in ("pf", "pf-ungm"):
        filters = [pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=100, **NB)]
    elif name == "ics-pf":
        filters = [ICSPF(sc.motion, sc.measurement, particles=100, search=CuckooSearch(n_iter=3), **NB)]
    elif name == "upf":
        filters = [pu.PartialUPF(sc.motion, sc.measurement, particles=100, fraction=0.5, **NB)]
    else:
        raise SystemExit(f"unknown family {name!r}")
    return zs, prior, filters

def work(zs, prior, filters):
    \"\"\"The batched run over M runs, then one step of one run from Python.\"\"\"
    one = pu.Gaussian(prior.mean if prior.mean.ndim == 1 else prior.mean[0], prior.cov)
    for filt in filters:
        particles = hasattr(filt, "particles")
        pu.run(filt, zs, prior, rng=run_streams(1, range(M), 1) if particles else None)
        s = filt.init(one, rng=np.random.default_rng(1)) if particles else filt.init(one)
        filt.step(s, zs[0, 0])
"""

FAMILIES = ("kf", "ekf", "ukf", "pf", "pf-ungm", "ics-pf", "upf", "observer")


def _cpu(code: str, env: dict[str, str]) -> tuple[float, float]:
    """CPU seconds (user + system) and wall seconds of ``python -c code`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, check=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def measure(name: str) -> tuple[float, float, float]:
    """(cold compile CPU s, its wall s, warm load CPU s) of one family, each net of import and set-up."""
    with tempfile.TemporaryDirectory(prefix="pursuit-compile-") as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=f"{tmp}/numba", PURSUIT_KERNEL_DIR=f"{tmp}/kernels", NUMBA_NUM_THREADS="1")
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT / "src"), env.get("PYTHONPATH")]))
        base, _ = _cpu(_SETUP + f"build({name!r})\n", env)
        code = _SETUP + f"work(*build({name!r}))\n"
        cold, wall = _cpu(code, env)
        warm, _ = _cpu(code, env)
    return cold - base, wall, warm - base


def main(argv: list[str]) -> None:
    names = argv or list(FAMILIES)
    print("| family | cold compile CPU s | wall s | load from cache CPU s |")
    print("|---|---|---|---|")
    total = 0.0
    for name in names:
        cold, wall, warm = measure(name)
        total += cold
        print(f"| {name} | {cold:.1f} | {wall:.1f} | {warm:.1f} |", flush=True)
    print(f"| total | {total:.1f} | | |")


if __name__ == "__main__":
    main(sys.argv[1:])
