"""Compiled filters stepped one run at a time from Python (``filt.step(state, z)``, one call per step), against FilterPy.

Work: the 2-D constant-velocity target of ``bench_kf.py`` (4 states,
continuous white-noise acceleration q = 0.01, dt = 1); the KF measures the
position (unit variance), the EKF, UKF and bootstrap PF (N = 1000) a
range-bearing sensor at (0, -50) (σ = 1 m, 0.02 rad).  One run of ``steps``
steps, batch ``()``; the time per step is the median over ``repeat`` passes
(after a warm-up pass that compiles or loads the kernels).  FilterPy's KF and
UKF (``predict(); update(z)``) are timed on the same measurements in the same
process, so the ratio is what to compare across machines.

``rows()`` is what ``bench_online.py`` imports.  Run::

    PYTHONPATH=src taskset -c 1 .bench-venv/bin/python benchmarks/_online_compiled.py
    PYTHONPATH=src taskset -c 1 .bench-venv/bin/python benchmarks/_online_compiled.py --cpu   # CPU time, on a loaded machine
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _one_core  # noqa: E402  (first: one BLAS thread, before NumPy loads)

_one_core.pin()

import numpy as np  # noqa: E402

import pursuit as pu  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing  # noqa: E402

# wall time; with --cpu the process's CPU time, which leaves out the time other jobs hold the core
# (on a loaded machine the wall time of a pinned process counts their slices too)
_clock = time.perf_counter
SENSOR = (0.0, -50.0)
SIG_R, SIG_B = 1.0, 0.02
PF_PARTICLES = 1000


def _motion():
    return ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")


def _work(meas, steps: int, seed: int = 0) -> np.ndarray:
    """Measurements ``(steps, m)`` of one simulated run."""
    motion = _motion()
    rng = np.random.default_rng(seed)
    x = np.array([0.0, 1.0, 0.0, 0.5])
    zs = np.empty((steps, meas.dim))
    for k in range(steps):
        x = motion.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    return zs


def _per_step(fn, steps: int, repeat: int) -> float:
    """Median µs per step of ``fn()`` (one pass of ``steps`` steps) over ``repeat`` passes, after one warm-up pass."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = _clock()
        fn()
        times.append(_clock() - t0)
    return statistics.median(times) / steps * 1e6


def _pursuit_pass(filt, prior, zs, rng=None, batch=()):
    if batch:
        zs = zs[:, None, :]  # (steps, 1, m): one run with a batch axis

    def go():
        s = filt.init(prior, batch=batch, rng=rng) if rng is not None else filt.init(prior, batch=batch)
        step = filt.step
        for z in zs:
            s, _ = step(s, z)
    return go


def rows(steps: int = 2000, repeat: int = 5) -> list[tuple[str, str, float]]:
    """``(name, "numba", µs per step)`` for the KF, EKF, UKF (batch ``()``, then ``(1,)``) and bootstrap PF (N = 1000), one run stepped from Python."""
    motion = _motion()
    lin = LinearGaussian.position(4, motion.position_indices, 1.0)
    rb = RangeBearing(np.array(SENSOR), SIG_R, SIG_B)
    prior = pu.Gaussian(np.array([0.0, 1.0, 0.0, 0.5]), np.diag([10.0, 1.0, 10.0, 1.0]))
    zl, zr = _work(lin, steps), _work(rb, steps, seed=1)
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a filter that would not compile fails the benchmark, not a silent NumPy row
        for name, filt, zs in [
            ("KF", pu.KalmanFilter(motion, lin, backend="numba"), zl),
            ("EKF (range-bearing)", pu.ExtendedKalmanFilter(motion, rb, backend="numba"), zr),
            ("UKF (range-bearing)", pu.UnscentedKalmanFilter(motion, rb, backend="numba"), zr),
        ]:
            out.append((name, "numba", _per_step(_pursuit_pass(filt, prior, zs), steps, repeat)))
            out.append((f"{name}, batch (1,)", "numba", _per_step(_pursuit_pass(filt, prior, zs, batch=(1,)), steps, repeat)))
        pf = pu.BootstrapParticleFilter(motion, rb, particles=PF_PARTICLES, backend="numba")
        pf_steps = max(steps // 10, 10)  # a PF step costs a hundred KF steps
        rng = np.random.default_rng(5)
        out.append((f"bootstrap PF N={PF_PARTICLES} (range-bearing)", "numba",
                    _per_step(_pursuit_pass(pf, prior, zr[:pf_steps], rng), pf_steps, repeat)))
    return out


def filterpy_rows(steps: int = 2000, repeat: int = 5) -> list[tuple[str, str, float]]:
    """``(name, "FilterPy", µs per step)`` for FilterPy's KF and UKF on the same work, or ``[]`` without FilterPy."""
    try:
        from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter
    except ImportError:
        return []
    motion = _motion()
    lin = LinearGaussian.position(4, motion.position_indices, 1.0)
    rb = RangeBearing(np.array(SENSOR), SIG_R, SIG_B)
    zl, zr = _work(lin, steps), _work(rb, steps, seed=1)
    F, Q = np.array(motion.transition_matrix()), np.array(motion.cov())

    def kf():
        f = KalmanFilter(dim_x=4, dim_z=2)
        f.F, f.Q, f.H, f.R = F, Q, np.array(lin.matrix()), np.array(lin.cov())
        f.x, f.P = np.array([[0.0], [1.0], [0.0], [0.5]]), np.diag([10.0, 1.0, 10.0, 1.0])
        for z in zl:
            f.predict()
            f.update(z.reshape(2, 1))

    def ukf():
        pts = MerweScaledSigmaPoints(4, alpha=1.0, beta=2.0, kappa=0.0)
        f = UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=1.0, fx=lambda x, dt: F @ x, hx=rb.h, points=pts,
                                  residual_z=rb.residual)
        f.Q, f.R = Q, np.array(rb.cov())
        f.x, f.P = np.array([0.0, 1.0, 0.0, 0.5]), np.diag([10.0, 1.0, 10.0, 1.0])
        for z in zr:
            f.predict()
            f.update(z)

    return [("KF", "FilterPy", _per_step(kf, steps, repeat)), ("UKF (range-bearing)", "FilterPy", _per_step(ukf, steps, repeat))]


def floor_rows(steps: int = 20000, repeat: int = 5) -> list[tuple[str, float]]:
    """``(piece, µs)``: where one compiled KF step's time goes (the lane's own pieces, timed alone in this process),
    then the EKF/UKF kernels: the serial block kernel on one lane against the scalar one-run kernel the lane calls."""
    from pursuit._compiled import gauss_kernels as GK
    from pursuit._compiled import one_run_kernels as OS
    from pursuit._compiled.online import StepInfo, _new_state

    motion = _motion()
    lin = LinearGaussian.position(4, motion.position_indices, 1.0)
    filt = pu.KalmanFilter(motion, lin, backend="numba")
    prior = pu.Gaussian(np.array([0.0, 1.0, 0.0, 0.5]), np.diag([10.0, 1.0, 10.0, 1.0]))
    s0 = filt.init(prior)
    z = np.array([1.0, 0.5])
    s1, _ = filt.step(s0, z)
    lane = vars(filt)["_online_lane"]
    x, P = s1.mean, s1.cov
    (c,) = lane.model(None)
    out = np.empty(lane.size)
    grid = np.empty(lane.grid)
    call, kernel = lane.call, lane.kernel
    a = np.zeros(4)

    def loop(fn):
        def go():
            for _ in range(steps):
                fn()
        return go

    chain = [s1]
    z_ro = np.broadcast_to(z, z.shape)  # read-only, as bench_online.py passes z

    def full():  # chained, as a tracking loop steps: the lane recognises its own last state
        chain[0] = filt.step(chain[0], z)[0]

    def full_ro():
        chain[0] = filt.step(chain[0], z_ro)[0]

    def general():  # k given: the lane's general path (z re-checked, the model looked up)
        chain[0] = filt.step(chain[0], z, k=chain[0].k + 1)[0]

    pieces = [
        ("whole step: state = filt.step(state, z)[0]", full),
        ("whole step, z read-only (np.broadcast_to, as bench_online.py)", full_ro),
        ("whole step through the lane's general path (k given)", general),
        ("kernel through numba's dispatcher (5 arguments)", lambda: kernel(x, P, z, c, out)),
        ("kernel through its entry point (what the lane calls)", lambda: call(x, P, z, c, out)),
        ("np.empty of the output rows and their flat view", lambda: np.empty(lane.grid).ravel()),
        ("state: an index and a slice of the output rows, and the GaussianState",
         lambda: _new_state(grid[0], grid[lane.prow], 1)),
        ("info: StepInfo (lazy; nothing sliced)", lambda: StepInfo(lane, out, (), False)),
        ("reference: a + a on a 4-vector (NumPy ufunc call)", lambda: a + a),
    ]
    rb = RangeBearing(np.array(SENSOR), SIG_R, SIG_B)
    zr = np.array([60.0, 0.1])
    for label, cls, block, scalar in [("EKF", pu.ExtendedKalmanFilter, GK.ekf_one, OS.ekf_one_scalar),
                                      ("UKF", pu.UnscentedKalmanFilter, GK.sigma_one, OS.sigma_one_scalar)]:
        f = cls(motion, rb, backend="numba")
        t1, _ = f.step(f.init(prior), zr)
        ln = vars(f)["_online_lane"]
        args = (t1.mean, t1.cov, zr, *ln.model(None))
        o = np.empty(ln.size)
        block(*args, o)  # compiles or loads
        types = tuple(block.typeof_pyval(v) for v in (*args, o))
        b_call, s_call = block.overloads[types].entry_point, scalar.overloads[types].entry_point
        ch = [t1]

        def whole(f=f, ch=ch):
            ch[0] = f.step(ch[0], zr)[0]

        pieces += [
            (f"{label} (range-bearing) whole step", whole),
            (f"{label} kernel: serial block kernel on one lane (before)", lambda c=b_call, a=args, o=o: c(*a, o)),
            (f"{label} kernel: scalar one-run kernel (what the lane calls)", lambda c=s_call, a=args, o=o: c(*a, o)),
        ]
    return [(name, _per_step(loop(fn), steps, repeat)) for name, fn in pieces]


def main() -> None:
    global _clock
    if "--cpu" in sys.argv:
        _clock = time.process_time
        print("(CPU time of this process: time.process_time)\n")
    print("| piece of one compiled KF step | µs |")
    print("|---|---|")
    for name, t in floor_rows():
        print(f"| {name} | {t:.3f} |")
    print()
    ours = rows()
    peer = {name: t for name, _, t in filterpy_rows()}
    print("| filter | backend | µs per step | FilterPy µs per step | vs FilterPy |")
    print("|---|---|---|---|---|")
    for name, backend, t in ours:
        p = peer.get(name)
        ratio = f"{p / t:.1f}x faster" if p is not None else "n/a"
        print(f"| {name} | {backend} | {t:.2f} | {'' if p is None else f'{p:.1f}'} | {ratio} |")


if __name__ == "__main__":
    main()
