"""Where the compiled backend's time goes: cost floors of one particle step and one Kalman step.

Not a comparison with peers: this measures, in the same run, the pieces the
compiled filters cannot avoid, to explain the distance to the speed targets
of issue 8 (PF >= 60 M particle-steps/s per core, KF >= 10 M steps/s per
core).

* **Particle step floor.** Every particle of a bootstrap PF needs one
  standard normal from its run's NumPy stream (pursuit keeps NumPy's
  streams so that both backends give the same estimates) and one ``exp``
  for its weight.  Measured one million at a time inside numba (one
  thread): through numba's ``Generator`` and libm's ``exp``, and as the
  compiled filters do it (the PCG64 state advanced in place, a vectorised
  ``exp``), beside NumPy's own vectorised draw; the UNGM propagation
  arithmetic for scale.  The sum of draw and ``exp`` bounds the compiled
  bootstrap PF's rate from above.
* **Particle run split.** The compiled bootstrap PF on UNGM (100 runs,
  100 steps, N = 1000, one thread) through ``pursuit.run`` stepping from
  Python (``sequence=False``) and as it runs by default, every run's whole
  sequence in one compiled call.
* **Kalman step split.** The compiled KF (4-state CV, position measured,
  1000 runs, 1 thread): the block step kernel (what a nonlinear EKF and
  the UKF/CKF use) and the step kernel generated for the linear model
  (``pursuit._compiled.kf_codegen``), each called directly on lane-major
  arrays; ``pursuit.run`` stepping from Python
  (``sequence=False``: the per-step call, the step info arrays and copying
  every step's results into the track); and ``pursuit.run`` as it runs by
  default, all steps in one compiled call.

Run::

    .bench-venv/bin/python benchmarks/run.py --only floor
"""

from __future__ import annotations

import math

import numpy as np
from _timing import median_time  # benchmarks/ is on sys.path when a benchmark runs as a script

import pursuit as pu

REPEATS = 5


def _median_time(fn, repeats: int = REPEATS) -> float:
    return median_time(fn, repeats)


def particle_floor(n: int) -> list[tuple[str, float]]:
    """Nanoseconds per element for the unavoidable pieces of a particle step (numba, one thread)."""
    import numba

    @numba.njit
    def draw(g, out):
        for i in range(out.shape[0]):
            out[i] = g.standard_normal()

    @numba.njit
    def expo(a, out):
        s = 0.0
        for i in range(a.shape[0]):
            v = math.exp(a[i])
            out[i] = v
            s += v
        return s

    @numba.njit
    def ungm(x, noise, out):
        for i in range(x.shape[0]):
            xi = x[i]
            out[i] = noise[i] * 3.1622776601683795 + (xi * (0.5 + 25.0 / (xi * xi + 1.0)) + 8.0)

    from pursuit._compiled.common import exp_weight
    from pursuit._compiled.streams import fill_normal, stream_addresses

    @numba.njit(error_model="numpy")
    def expo_vec(a, out):  # the filters' exp: vectorised, the sum in a separate pass
        for i in range(a.shape[0]):
            out[i] = exp_weight(a[i])

    g = np.random.default_rng(0)
    out = np.empty(n)
    a = -5.0 * g.random(n)
    addrs = stream_addresses([g])
    draw(g, out), expo(a, out), expo_vec(a, out), ungm(a, a, out)  # compile
    rows = [
        ("Generator.standard_normal() in numba, per draw", _median_time(lambda: draw(g, out))),
        ("NumPy Generator.standard_normal(out=...), per draw", _median_time(lambda: g.standard_normal(out=out))),
        ("math.exp in numba, per value", _median_time(lambda: expo(a, out))),
        ("UNGM propagation arithmetic in numba, per particle", _median_time(lambda: ungm(a, a, out))),
    ]
    if addrs is not None:
        fill_normal(addrs[0], out[:10])  # compile
        rows.append(("PCG64 stream drawn in place (pursuit._compiled.streams), per normal",
                     _median_time(lambda: fill_normal(addrs[0], out))))
    rows.append(("exp_weight (vectorised exp of the compiled filters), per value", _median_time(lambda: expo_vec(a, out))))
    return [(label, t / n * 1e9) for label, t in rows]


def particle_split(runs: int, steps: int, particles: int) -> tuple[float, float]:
    """Particle-steps per second of the compiled bootstrap PF on UNGM, one thread.

    Returns (run step by step, run in one call): ``pursuit.run(...,
    sequence=False)`` returns to Python after every step (the step's glue,
    its info arrays and the copy into the track); by default the whole
    sequence of every run is one compiled call.  Same draws, same bits.
    """
    import numba

    from pursuit.rng import run_streams
    from pursuit.scenarios.ungm import UNGM

    numba.set_num_threads(1)
    sc = UNGM(steps=steps)
    sim = sc.simulate(run_streams(1, range(runs), 0), runs)
    filt = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=particles, backend="numba")

    def go(sequence):
        pu.run(filt, sim.measurements, sim.prior, rng=run_streams(2, range(runs), 1), sequence=sequence)

    go(True), go(False)  # compile
    work = runs * steps * particles
    stepped = work / _median_time(lambda: go(False))
    whole = work / _median_time(lambda: go(True))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return stepped, whole


def _block_inputs(filt, zs: np.ndarray, runs: int, n: int = 4, m: int = 2) -> tuple:
    """What a serial block kernel takes for ``filt``'s compiled models and ``zs (T, runs, m)``, lane-major.

    ``(n, m, F, Q, zl, valid, outs, sensor, x0, P0)``: the motion matrices at
    the model's ``dt``, the measurements ``(T, m, runs)`` and their mask, the
    output buffers, the packed sensor, and a prior (zero mean, identity).
    """
    from pursuit._compiled.kernel_args import GaussOutputs
    from pursuit._compiled.particle import measurement_args

    ms, hs = filt._specs  # noqa: SLF001 (measurement of the internals)
    F, _, _ = ms.arrays(1, None)
    Q = np.ascontiguousarray(ms.cov(1, None))
    zl = np.ascontiguousarray(np.moveaxis(zs, 2, 1))
    valid = ~np.isnan(zl)
    outs = GaussOutputs(np.empty((n, runs)), np.empty((n, n, runs)), np.empty((n, runs)), np.empty((n, n, runs)),
                        np.empty((n, n, runs)), np.empty((m, runs)), np.empty((m, m, runs)), np.empty(runs),
                        np.empty(runs, dtype=np.int64), np.empty(runs), np.ones(runs, dtype=np.bool_))
    x0 = np.zeros((n, runs))
    P0 = np.ascontiguousarray(np.broadcast_to(np.eye(n)[..., None], (n, n, runs)))
    return n, m, F, Q, zl, valid, outs, measurement_args(hs), x0, P0


def kalman_split(runs: int, steps: int) -> tuple[float, float, float, float]:
    """Filter-steps per second of the compiled KF, one thread.

    Returns (block kernel alone, generated step kernel alone, run step by
    step, run in one call): the block kernel is what the EKF with a
    nonlinear measurement and the UKF/CKF use; a linear measurement runs the
    kernels generated for the model's structure (``pursuit._compiled.kf_codegen``).
    """
    import numba

    from pursuit._compiled import gauss_kernels as GK
    from pursuit._compiled import generated, kf_codegen
    from pursuit._compiled.kernel_args import Prediction
    from pursuit.models import ConstantVelocity, LinearGaussian

    numba.set_num_threads(1)
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")
    meas = LinearGaussian.position(4, motion.position_indices, 1.0)
    zs = np.random.default_rng(0).standard_normal((steps, runs, 2)) * 3.0
    filt = pu.KalmanFilter(motion, meas, backend="numba")
    prior = pu.Gaussian(np.zeros(4), np.eye(4))
    pu.run(filt, zs[:2], prior, keep_cov=False)  # compile
    pu.run(filt, zs[:2], prior, keep_cov=False, sequence=False)
    whole = runs * steps / _median_time(lambda: pu.run(filt, zs, prior, keep_cov=False), 3)
    stepped = runs * steps / _median_time(lambda: pu.run(filt, zs, prior, keep_cov=False, sequence=False), 3)

    n, m, F, Q, zl, valid, outs, sensor, x0, P0 = _block_inputs(filt, zs, runs)
    hs = filt._specs[1]  # noqa: SLF001 (measurement of the internals)

    def block_only():
        x, P = x0, P0
        for k in range(steps):
            GK.ekf_step_serial((x, P), (zl[k], valid[k]), Prediction(F, Q, 1.0), sensor, outs)
            x, P = outs.x.copy(), outs.P.copy()

    gen = generated.linear_kf_kernels(F, Q, hs.A, hs.R)
    rows = kf_codegen.step_rows(n, m)
    out = np.empty((sum(c for _, c in rows.values()), runs))
    nblocks = -(-runs // gen.STEP_BLOCK)

    def generated_only():
        x, P = x0, P0
        for k in range(steps):
            gen.step(x, P, zl[k], valid[k], F, Q, 1.0, hs.A, hs.R, out, 0, nblocks)
            x = out[rows["x"][0]:rows["x"][0] + n].copy()
            P = out[rows["P"][0]:rows["P"][0] + n * n].reshape(n, n, runs).copy()

    generated_only()  # compile
    block = runs * steps / _median_time(block_only, 3)
    unrolled = runs * steps / _median_time(generated_only, 3)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return block, unrolled, stepped, whole


def ukf_split(runs: int, steps: int) -> dict[str, float]:
    """Where the compiled UKF's time goes on bench_kf's work (4-state CV, range-bearing sensor), one thread.

    Returns ns per filter-step (one run, one step) of: the range-bearing
    measurement of the 9 sigma points alone, through libm's ``hypot`` and
    ``atan2`` one run at a time (as ``model_math.h_range_bearing``, which the
    EKF and the particle filters use) and as the UKF/CKF kernels compute it
    (``gauss_kernels._h_sigma_block``: ``atan2_lanes`` and ``hypot_lanes``
    in one vectorised loop over the runs); the sigma step
    kernel alone (lane-major arrays, no Python between steps); the
    whole-sequence kernel alone (every step of every run in one call, the
    outputs already allocated); ``pursuit.run`` stepping from Python
    (``sequence=False``: the step kernel, the per-step glue, the step info)
    and ``pursuit.run`` as it runs by default (the whole-sequence kernel,
    the info arrays and the divergence checks).
    """
    import numba
    from bench_kf import ukf_work

    from pursuit._compiled import gauss_kernels as GK
    from pursuit._compiled.kernel_args import GaussSequenceOutputs, Prediction, SigmaPoints

    @numba.njit(error_model="numpy")
    def h_points_lanes(sensor, X, out):  # the same, as the UKF/CKF kernels do it
        acc = 0.0
        for s in range(X.shape[0]):
            GK._h_sigma_block(sensor, X[s], out)
            acc += out[0, 0]
        return acc

    @numba.njit(error_model="numpy")
    def h_points(X, out):  # 9 points (n, B) per run: range and bearing, libm, as model_math.h_range_bearing
        acc = 0.0
        for s in range(X.shape[0]):
            for c in range(X.shape[2]):
                dx = X[s, 0, c]
                dy = X[s, 2, c] + 50.0
                out[0, c] = math.hypot(dx, dy)
                out[1, c] = math.atan2(dy, dx)
            acc += out[0, 0]
        return acc

    numba.set_num_threads(1)
    motion, meas, zs = ukf_work(runs, steps)
    filt = pu.UnscentedKalmanFilter(motion, meas, backend="numba")
    prior = pu.Gaussian(np.zeros(4), np.eye(4))
    pu.run(filt, zs[:2], prior, keep_cov=False)  # compile
    pu.run(filt, zs[:2], prior, keep_cov=False, sequence=False)
    whole = _median_time(lambda: pu.run(filt, zs, prior, keep_cov=False), 3) / (runs * steps)
    stepped = _median_time(lambda: pu.run(filt, zs, prior, keep_cov=False, sequence=False), 3) / (runs * steps)

    n, m, F, Q, zl, valid, outs, sensor, x0, P0 = _block_inputs(filt, zs, runs)
    cscale, wm, wc = filt.sigma_weights(n)
    sigma = SigmaPoints(float(cscale), np.ascontiguousarray(wm), np.ascontiguousarray(wc), wm.shape[0] % 2 == 1)

    def kernel_only():
        x, P = x0, P0
        for k in range(steps):
            GK.sigma_step_serial((x, P), (zl[k], valid[k]), Prediction(F, Q, 1.0), sensor, sigma, outs)
            x, P = outs.x.copy(), outs.P.copy()

    kernel_only()
    kernel = _median_time(kernel_only, 3) / (runs * steps)
    seq_outs = GaussSequenceOutputs(np.empty((steps, runs, n)), np.empty((1, 1, 1, 1)), np.empty((steps, runs, m)),
                                    np.empty((steps, runs, m, m)), np.empty((steps, runs)), np.empty((steps, runs), dtype=np.int64),
                                    np.empty((steps, runs)), np.ones(runs, dtype=np.bool_))

    def sequence_only():
        GK.sigma_sequence_serial((x0, P0), (zl, valid), Prediction(F, Q, 1.0), sensor, sigma, False, seq_outs)

    sequence_only()
    sequence = _median_time(sequence_only, 3) / (runs * steps)
    pts = np.random.default_rng(0).standard_normal((wm.shape[0], n, runs)) * 30.0
    hout = np.empty((m, runs))
    h_points(pts, hout)
    h = _median_time(lambda: h_points(pts, hout), 5) / runs
    h_points_lanes(sensor, pts, hout)
    h_lanes = _median_time(lambda: h_points_lanes(sensor, pts, hout), 5) / runs
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return {"h": h * 1e9, "h_lanes": h_lanes * 1e9, "kernel": kernel * 1e9, "sequence": sequence * 1e9, "stepped": stepped * 1e9, "run": whole * 1e9}


def print_ukf_split(quick: bool = False) -> dict[str, float]:
    """Print the UKF split as a markdown table; returns it."""
    runs, steps = (200, 50) if quick else (1000, 200)
    t = ukf_split(runs, steps)
    print(f"**Compiled UKF, 4-state CV, range-bearing sensor (bench_kf's work), {runs} runs x {steps} steps, one thread**\n")
    print("| measured | ns per filter-step | M filter-steps/s |")
    print("|---|---|---|")
    print(f"| range and bearing of the 9 sigma points alone, libm hypot and atan2 (the EKF's and PFs' h) | {t['h']:.0f} | {1e3 / t['h']:.2f} |")
    print(f"| the same as the UKF/CKF kernels compute it (`atan2_lanes`, `hypot_lanes`, one vectorised loop) | {t['h_lanes']:.0f} | {1e3 / t['h_lanes']:.2f} |")
    print(f"| sigma step kernel alone (lane-major arrays, no Python between steps) | {t['kernel']:.0f} | {1e3 / t['kernel']:.2f} |")
    print(f"| whole-sequence kernel alone (`gauss_kernels.sigma_sequence_serial`, outputs allocated) | {t['sequence']:.0f} | {1e3 / t['sequence']:.2f} |")
    print(f"| `pursuit.run(..., sequence=False)` (step kernel, per-step glue, step info, divergence checks) | {t['stepped']:.0f} | {1e3 / t['stepped']:.2f} |")
    print(f"| `pursuit.run` (whole-sequence kernel, info arrays, divergence checks; the default) | {t['run']:.0f} | {1e3 / t['run']:.2f} |")
    print()
    return t


def main(quick: bool = False) -> dict:
    """Print two markdown tables; returns the numbers."""
    try:
        import numba  # noqa: F401
    except ImportError:
        print("numba is not installed: nothing to measure.\n")
        return {}
    floor = particle_floor(100_000 if quick else 1_000_000)
    print("**Per-particle pieces (numba, one thread)**\n")
    print("| piece | ns per element |")
    print("|---|---|")
    for label, ns in floor:
        print(f"| {label} | {ns:.2f} |")
    ns = dict(floor)
    old = ns["Generator.standard_normal() in numba, per draw"] + ns["math.exp in numba, per value"]
    print(f"\nThrough numba's Generator and libm's exp, one draw and one exp cost {old:.1f} ns per particle: at most "
          f"{1e3 / old:.0f} M particle-steps/s per core before propagation, likelihood, moments and resampling.")
    fast = ns.get("PCG64 stream drawn in place (pursuit._compiled.streams), per normal")
    if fast is not None:
        new = fast + ns["exp_weight (vectorised exp of the compiled filters), per value"]
        print(f"With the in-place PCG64 stream (the same numbers) and the vectorised exp the compiled filters use: "
              f"{new:.1f} ns, at most {1e3 / new:.0f} M particle-steps/s per core.")
    print()
    pruns, psteps, pn = (20, 50, 1000) if quick else (100, 100, 1000)
    pf_stepped, pf_whole = particle_split(pruns, psteps, pn)
    print(f"**Compiled bootstrap PF, UNGM, {pruns} runs x {psteps} steps, N = {pn}, one thread**\n")
    print("| measured | M particle-steps/s |")
    print("|---|---|")
    print(f"| `pursuit.run(..., sequence=False)` (back to Python after every step) | {pf_stepped / 1e6:.1f} |")
    print(f"| `pursuit.run` (every run's whole sequence in one compiled call, the default) | {pf_whole / 1e6:.1f} |")
    print()
    runs, steps = (200, 50) if quick else (1000, 300)
    block, kernel, stepped, whole = kalman_split(runs, steps)
    print(f"**Compiled KF, 4-state CV, position measured, {runs} runs x {steps} steps, one thread**\n")
    print("| measured | M filter-steps/s |")
    print("|---|---|")
    print(f"| block step kernel alone (nonlinear EKF and UKF/CKF path; lane-major arrays, no Python between steps) | {block / 1e6:.2f} |")
    print(f"| generated step kernel alone (the linear KF's, unrolled for the model's structure) | {kernel / 1e6:.2f} |")
    print(f"| `pursuit.run(..., sequence=False)` (per-step call, step info, results copied into the track) | {stepped / 1e6:.2f} |")
    print(f"| `pursuit.run` (all steps in one compiled call, the default) | {whole / 1e6:.2f} |")
    print()
    ukf = print_ukf_split(quick)
    return {"ukf_split_ns": ukf, "particle_floor_ns": floor, "pf_run_stepped": pf_stepped, "pf_run": pf_whole, "kf_block_kernel": block, "kf_kernel": kernel, "kf_run_stepped": stepped, "kf_run": whole}


if __name__ == "__main__":
    import sys

    if "--ukf" in sys.argv:  # the UKF split alone
        print_ukf_split(quick="--quick" in sys.argv)
    else:
        main(quick="--quick" in sys.argv)
