"""One run at a time: pursuit's `step` called from Python for one run, against FilterPy and `particles`.

Work (the same model and measurements for every implementation; one run of
T = 2000 steps, the time per step is the median of ``REPEATS`` passes):

* **KF**: 2-D constant-velocity target (4 states, continuous white-noise
  acceleration q = 0.01, dt = 1), position measured with unit variance.
  Peer: FilterPy ``KalmanFilter.predict(); update(z)``.
* **EKF** and **UKF**: the same motion with a range-bearing sensor at
  (0, -50) (σ = 1 m, 0.02 rad); UKF with α = 1, β = 2, κ = 0.  Peers:
  FilterPy ``ExtendedKalmanFilter.predict(); update(z, HJacobian, Hx,
  residual=...)`` and ``UnscentedKalmanFilter`` with
  ``MerweScaledSigmaPoints``.
* **PF**: bootstrap particle filter, N = 1000 particles, systematic
  resampling at every step, the same CV motion ranged by three anchors
  (σ = 2 m).  Peer: ``particles`` (Chopin) ``SMC(Bootstrap(...))`` advanced
  one step at a time with ``next(alg)``; FilterPy has no particle filter.

pursuit's rows call ``state, info = filt.step(state, z)`` once per step,
from Python, with batch ``()`` (one run, no batch axis) and ``(1,)``.
``ratio`` is the peer's µs per step divided by the row's: above 1 the row
is faster than the peer.  Each pursuit pass takes turns with its peer's
pass (:func:`interleaved_us`), so a drifting load on a shared machine hits
both.  Where numba is installed the same passes run again with
``backend="numba"`` (the compiled one-run lane); the compiled step's floor,
piece by piece, is ``benchmarks/_online_compiled.py``.

Run::

    PYTHONPATH=src taskset -c 1 .bench-venv/bin/python benchmarks/bench_online.py
    PYTHONPATH=src taskset -c 1 .bench-venv/bin/python benchmarks/bench_online.py --ab   # one-run path vs general step
    PYTHONPATH=src taskset -c 1 .bench-venv/bin/python benchmarks/bench_online.py --kinds kf,ekf --no-numba
    .bench-venv/bin/python benchmarks/run.py --only online
"""

from __future__ import annotations

import _one_core  # first: NumPy's BLAS on one thread (benchmarks/ is on sys.path when a benchmark runs)

_one_core.pin()

import argparse  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

import pursuit as pu  # noqa: E402
from pursuit.compute import numba_available  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing  # noqa: E402

STEPS = 2000
REPEATS = 7
SENSOR = (0.0, -50.0)
SIG_R, SIG_B = 1.0, 0.02
ANCHORS = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
SIG_ANCHOR = 2.0
PARTICLES = 1000

Row = tuple[str, str, float, float | None]  # (name, backend, µs per step, peer µs / row µs)
Maker = Callable[[], Callable[[], object]]  # builds a fresh pass (not timed); the pass is timed


CLOCK: Callable[[], float] = time.perf_counter
"""The clock of every pass: wall clock, or ``time.process_time`` (CPU time of this process) with ``--cpu``."""


def interleaved_us(passes: dict[str, tuple[Maker, int]], repeats: int = REPEATS) -> dict[str, float]:
    """Median µs per step of each pass, the passes taking turns in every round.

    Taking turns keeps a ratio fair on a shared machine whose load drifts
    during the run.  ``passes`` maps a name to ``(make, steps of one pass)``.
    The clock is :data:`CLOCK`: CPU time leaves out the time other
    processes held the core (a pass of 2000 steps spans many scheduler slices).
    """
    times: dict[str, list[float]] = {name: [] for name in passes}
    for _ in range(repeats):
        for name, (make, steps) in passes.items():
            go = make()
            t0 = CLOCK()
            go()
            times[name].append((CLOCK() - t0) / steps * 1e6)
    return {name: statistics.median(ts) for name, ts in times.items()}


# -- work ---------------------------------------------------------------------
def motion() -> ConstantVelocity:
    return ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")


def truth(steps: int, seed: int = 0) -> np.ndarray:
    """(steps, 4) one CV trajectory."""
    rng = np.random.default_rng(seed)
    mot, x = motion(), np.array([0.0, 1.0, 0.0, 0.5])
    out = np.empty((steps, 4))
    for k in range(steps):
        x = mot.sample(x, k + 1, rng)
        out[k] = x
    return out


def kf_work(steps: int):
    mot = motion()
    meas = LinearGaussian.position(4, mot.position_indices, 1.0)
    zs = meas.sample(truth(steps), 1, np.random.default_rng(1))
    return mot, meas, zs


def rb_work(steps: int):
    mot = motion()
    meas = RangeBearing(np.array(SENSOR), SIG_R, SIG_B)
    zs = meas.sample(truth(steps), 1, np.random.default_rng(1))
    return mot, meas, zs


def pf_steps(steps: int) -> int:
    """Steps of a PF pass: N = 1000 particles cost a few hundred µs a step, so a tenth of the steps."""
    return max(steps // 10, 50)


def pf_work(steps: int):
    from pursuit.models import RangeSensors

    mot = ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="discrete")
    meas = RangeSensors(ANCHORS, SIG_ANCHOR)
    x = truth(steps) + np.array([30.0, 0.0, 30.0, 0.0])
    zs = meas.sample(x, 1, np.random.default_rng(1))
    return mot, meas, zs, np.array([30.0, 1.0, 30.0, 0.5])


PRIOR_COV = np.diag([25.0, 1.0, 25.0, 1.0])
KINDS = ("kf", "ekf", "ukf", "pf")


# -- pursuit ---------------------------------------------------------------------
def _pursuit_pass(filt, zs, prior, batch, rng=None) -> Maker:
    def make():
        state = filt.init(prior, batch=batch, rng=rng)
        z_steps = [np.broadcast_to(z, (*batch, z.shape[-1])) for z in zs]

        def go():
            s = state
            for z in z_steps:
                s, _ = filt.step(s, z)

        return go

    return make


def pursuit_passes(kind: str, backend: str, steps: int = STEPS) -> dict[str, tuple[Maker, int]]:
    """Passes of pursuit's filter of ``kind`` (``"kf"``, ``"ekf"``, ``"ukf"``, ``"pf"``) computing with ``backend``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a fallback warning: the backend column says what ran
        if kind == "pf":
            mot, meas, zs, x0 = pf_work(steps)
            pf = pu.BootstrapParticleFilter(mot, meas, particles=PARTICLES, backend=backend)
            n = pf_steps(steps)
            make = _pursuit_pass(pf, zs[:n], pu.Gaussian(x0, PRIOR_COV), (1,), np.random.default_rng(0))
            return {f"pursuit PF N={PARTICLES}, batch (1,)": (make, n)}
        if kind == "kf":
            mot, meas, zs = kf_work(steps)
            prior = pu.Gaussian(np.zeros(4), np.eye(4))
            filt, label = pu.KalmanFilter(mot, meas, backend=backend), "KF"
        else:
            mot, meas, zs = rb_work(steps)
            prior = pu.Gaussian(np.array([0.0, 1.0, 0.0, 0.5]), np.eye(4))
            cls = pu.ExtendedKalmanFilter if kind == "ekf" else pu.UnscentedKalmanFilter
            filt, label = cls(mot, meas, backend=backend), f"{kind.upper()} range-bearing"
    return {f"pursuit {label}, batch {batch}": (_pursuit_pass(filt, zs, prior, batch), steps) for batch in ((), (1,))}


# -- peers ------------------------------------------------------------------------
PEER_LABELS = {
    "kf": "FilterPy KalmanFilter",
    "ekf": "FilterPy ExtendedKalmanFilter",
    "ukf": "FilterPy UnscentedKalmanFilter (Merwe points)",
    "pf": "particles SMC(Bootstrap), next(alg)",
}


def peer_pass(kind: str, steps: int = STEPS) -> tuple[Maker, int] | None:
    """The peer's pass on the same work, or None if not installed.

    FilterPy ``predict(); update(z)``, or ``particles`` advanced with ``next(alg)``.
    """
    if kind == "pf":
        return _particles_pass(steps)
    try:
        from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
    except ImportError:
        return None
    if kind == "kf":
        mot, meas, zs = kf_work(steps)
        zcol = [z.reshape(2, 1) for z in zs]

        def make():
            kf = KalmanFilter(dim_x=4, dim_z=2)
            kf.F = np.array(mot.transition_matrix())
            kf.Q = np.array(mot.cov())
            kf.H = np.array(meas.matrix())
            kf.R = np.array(meas.cov())
            kf.x = np.zeros((4, 1))
            kf.P = np.eye(4)

            def go():
                for z in zcol:
                    kf.predict()
                    kf.update(z)

            return go

        return make, steps
    mot, meas, zs = rb_work(steps)
    F = np.array(mot.transition_matrix())
    x0 = np.array([0.0, 1.0, 0.0, 0.5])
    if kind == "ekf":
        zcol = [z.reshape(2, 1) for z in zs]

        def hj(x):
            return meas.jacobian(x[:, 0])

        def hx(x):
            return meas.h(x[:, 0]).reshape(2, 1)

        def res(a, b):
            return meas.residual(a[:, 0], b[:, 0]).reshape(2, 1)

        def make():
            ekf = ExtendedKalmanFilter(dim_x=4, dim_z=2)
            ekf.F = F.copy()
            ekf.Q = np.array(mot.cov())
            ekf.R = np.array(meas.cov())
            ekf.x = x0.reshape(4, 1).copy()
            ekf.P = np.eye(4)

            def go():
                for z in zcol:
                    ekf.predict()
                    ekf.update(z, hj, hx, residual=res)

            return go

        return make, steps

    def fx(x, dt):
        return F @ x

    def make():
        pts = MerweScaledSigmaPoints(4, alpha=1.0, beta=2.0, kappa=0.0)
        ukf = UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=1.0, fx=fx, hx=meas.h, points=pts, residual_z=meas.residual)
        ukf.Q = np.array(mot.cov())
        ukf.R = np.array(meas.cov())
        ukf.x = x0.copy()
        ukf.P = np.eye(4)

        def go():
            for z in zs:
                ukf.predict()
                ukf.update(z)

        return go

    return make, steps


def _particles_pass(steps: int) -> tuple[Maker, int] | None:
    try:
        import particles
        from particles import distributions as dists
        from particles import state_space_models as ssm
    except ImportError:
        return None
    mot, meas, zs, x0 = pf_work(steps)
    n = pf_steps(steps)
    F = np.asarray(mot.transition_matrix())
    G = np.asarray(mot.noise_factor())  # Q = G Gᵀ is singular (discrete white-noise acceleration)
    R = SIG_ANCHOR**2 * np.eye(len(ANCHORS))

    class LinearGaussianMove(dists.ProbDist):
        dim = 4

        def __init__(self, loc):
            self.loc = loc

        def rvs(self, size=None):
            return self.loc + np.random.standard_normal((self.loc.shape[0], G.shape[1])) @ G.T

    class RangeCV(ssm.StateSpaceModel):
        def PX0(self):
            return dists.MvNormal(loc=x0, cov=PRIOR_COV)

        def PX(self, t, xp):
            return LinearGaussianMove(xp @ F.T)

        def PY(self, t, xp, x):
            pos = x[:, [0, 2]]
            ranges = np.sqrt(((pos[:, None, :] - ANCHORS[None, :, :]) ** 2).sum(-1))
            return dists.MvNormal(loc=ranges, cov=R)

    data = list(zs[:n])

    def make():
        fk = ssm.Bootstrap(ssm=RangeCV(), data=data)
        alg = particles.SMC(fk=fk, N=PARTICLES, resampling="systematic", ESSrmin=1.0, store_history=False, collect=None)

        def go():
            for _ in range(n):
                next(alg)

        return go

    return make, n


# -- the table ----------------------------------------------------------------------
def rows(
    backend: str = "numpy", steps: int = STEPS, repeats: int = REPEATS, peers: dict[str, float | None] | None = None,
    kinds: tuple[str, ...] = KINDS,
) -> list[Row]:
    """``(name, backend, µs per step, peer µs / row µs)`` of pursuit computing with ``backend``, every kind.

    Each kind's pursuit passes take turns with the peer's pass
    (:func:`interleaved_us`); the peer's µs per step are written into
    ``peers`` (kind → µs, None when not installed) when a dict is given.
    """
    out: list[Row] = []
    for kind in kinds:
        passes = pursuit_passes(kind, backend, steps)
        peer = peer_pass(kind, steps)
        if peer is not None:
            passes["peer"] = peer
        us = interleaved_us(passes, repeats)
        ref = us.pop("peer", None)
        if peers is not None:
            peers[kind] = ref
        out += [(name, backend, v, ref / v if ref else None) for name, v in us.items()]
    return out


def table(all_rows: list[Row]) -> str:
    lines = ["| implementation | backend | µs per step | ratio (peer µs / µs) |", "|---|---|---|---|"]
    for name, backend, us, ratio in all_rows:
        lines.append(f"| {name} | {backend} | {us:.1f} | {'' if ratio is None else f'{ratio:.2f}'} |")
    return "\n".join(lines)


def ab_rows(steps: int = 500, repeats: int = 5, kinds: tuple[str, ...] = ("kf", "ekf", "ukf")) -> list[Row]:
    """The one-run path of the Gaussian filters against their general step, with the same filters (``--ab``).

    The general-step rows switch the one-run path off (the private
    ``pursuit.filters.gaussian._ONE_RUN_TYPES`` emptied for the pass); all
    passes of a kind, FilterPy's included, take turns.
    """
    from pursuit.filters import gaussian

    def general(make: Maker) -> Maker:
        def make_general():
            go = make()

            def run():
                saved = gaussian._ONE_RUN_TYPES
                gaussian._ONE_RUN_TYPES = frozenset()
                try:
                    go()
                finally:
                    gaussian._ONE_RUN_TYPES = saved

            return run

        return make_general

    out: list[Row] = []
    for kind in kinds:
        passes: dict[str, tuple[Maker, int]] = {}
        for name, (make, n) in pursuit_passes(kind, "numpy", steps).items():
            passes[f"{name}, one-run path"] = (make, n)
            passes[f"{name}, general step"] = (general(make), n)
        peer = peer_pass(kind, steps)
        if peer is not None:
            passes[PEER_LABELS[kind]] = peer
        us = interleaved_us(passes, repeats)
        ref = us.get(PEER_LABELS[kind])
        out += [(name, "numpy" if name.startswith("pursuit") else "peer", v, ref / v if ref else None) for name, v in us.items()]
    return out


def main(quick: bool = False, kinds: tuple[str, ...] = KINDS, numba: bool = True, repeats: int | None = None) -> list[Row]:
    steps, repeats = (200, 3) if quick else (STEPS, repeats or REPEATS)
    peers: dict[str, float | None] = {}
    mine = rows("numpy", steps, repeats, peers, kinds)
    all_rows: list[Row] = [
        (PEER_LABELS[kind], "peer", us, 1.0) if us is not None else (PEER_LABELS[kind], "not installed", float("nan"), None)
        for kind, us in peers.items()
    ]
    all_rows += mine
    if numba and numba_available():
        # the compiled step, timed against the same peers in turn (its floor: benchmarks/_online_compiled.py)
        all_rows += [r for r in rows("numba", steps, repeats, kinds=kinds) if r[1] != "peer"]
    clock = "CPU time" if CLOCK is time.process_time else "wall clock"
    print(
        f"One run, {steps} steps (PF: {pf_steps(steps)}), N = {PARTICLES} particles; median of {repeats} passes ({clock}), "
        "each pursuit pass taking turns with its peer's; one core.\n"
    )
    print(table(all_rows))
    return all_rows


def _parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description="One run at a time: pursuit's step against FilterPy and particles.")
    p.add_argument("--ab", action="store_true", help="the one-run path against the general step (NumPy)")
    p.add_argument("--quick", action="store_true", help="200 steps, 3 passes")
    p.add_argument("--kinds", default=None, help=f"comma-separated subset of {','.join(KINDS)} (default: all; --ab: kf,ekf,ukf)")
    p.add_argument("--no-numba", action="store_true", help="NumPy rows only")
    p.add_argument("--cpu", action="store_true", help="time by CPU time (time.process_time), not wall clock")
    p.add_argument("--repeats", type=int, default=None, help=f"passes per row (default {REPEATS}; --ab: 5); the median is reported")
    return p.parse_args(argv)


if __name__ == "__main__":
    args = _parse(sys.argv[1:])
    if args.cpu:
        CLOCK = time.process_time
    chosen = None if args.kinds is None else tuple(k.strip() for k in args.kinds.split(","))
    if chosen is not None and not set(chosen) <= set(KINDS):
        raise SystemExit(f"--kinds: expected a subset of {', '.join(KINDS)}, got {args.kinds!r}")
    if args.ab:
        print(table(ab_rows(repeats=args.repeats or 5, kinds=tuple(k for k in (chosen or ("kf", "ekf", "ukf")) if k != "pf"))))
    else:
        main(quick=args.quick, kinds=chosen or KINDS, numba=not args.no_numba, repeats=args.repeats)
