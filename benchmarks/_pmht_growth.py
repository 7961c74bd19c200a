"""How pursuit's PMHT and GM-PHD time per scan grows with targets, false alarms and window length.

``python benchmarks/bench_pmht.py --growth`` runs :func:`growth`: a small grid, each point the fastest
of 5 timings of all runs in one batch, taken round-robin over the grid (the least disturbed by other
jobs on a shared machine), on one core, printed as a markdown table with the fitted
growth exponents and drawn to ``docs/img/pmht_cost_growth.png``.

Work: N constant-velocity targets (q = 0.02, speed 1 m/s in random directions) spread over a
1 km × 1 km region, R = I, P_D = 0.9, λ false alarms per scan uniform over the region, 20 scans,
20 runs.  PMHT starts from the true priors with a fixed track set (no initiation), so it holds
exactly N tracks; GM-PHD runs with its default adaptive two-point births, so its component count
is its own.  Grid: N ∈ {1, 2, 4, 8, 16} (λ = 10, B = 5); λ ∈ {2.5, 5, 10, 20, 40, 80} (N = 4,
B = 5); B ∈ {1, 2, 3, 5, 8, 12} (N = 4, λ = 10; PMHT only).  The exponent is the least-squares
slope of log(time per scan) against log(variable) over the upper half of each sweep.
"""

from __future__ import annotations

import numpy as np

import time
from pursuit.filters import KalmanFilter
from pursuit.gaussian import Gaussian
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.multitarget import GMPHDTracker, PMHTTracker
from pursuit.rng import run_streams
from pursuit.scenarios.multitarget import MultiTargetScenario, Target

SIDE = 1000.0
STEPS = 20
RUNS = 20
TARGETS = (1, 2, 4, 8, 16)
CLUTTER = (2.5, 5.0, 10.0, 20.0, 40.0, 80.0)
BATCHES = (1, 2, 3, 5, 8, 12)


def scene(n_targets: int, clutter_rate: float) -> MultiTargetScenario:
    """N CV targets on a jittered grid over the region, heading in fixed pseudo-random directions."""
    rng = np.random.default_rng(n_targets)
    side = int(np.ceil(np.sqrt(n_targets)))
    cells = (np.arange(n_targets)[:, None] // [side, 1]) % side
    pos = (cells + 0.5) / side * SIDE + rng.uniform(-20.0, 20.0, (n_targets, 2))
    heading = rng.uniform(0.0, 2.0 * np.pi, n_targets)
    targets = tuple(Target([p[0], np.cos(h), p[1], np.sin(h)]) for p, h in zip(pos, heading))
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.02, noise="continuous")
    sensor = LinearGaussian.position(4, (0, 2), 1.0)
    return MultiTargetScenario(targets, motion, sensor, [[0.0, SIDE], [0.0, SIDE]], clutter_rate, 0.9, STEPS, 1.0, "growth", max_speed=5.0)


def _job(n_targets: int, clutter_rate: float, batch: int | None):
    """A call that tracks all runs once with PMHT (``batch`` given) or GM-PHD (``batch`` None)."""
    sc = scene(n_targets, clutter_rate)
    truth, scans = sc.simulate(run_streams(7, range(RUNS), 0), RUNS)
    kf = KalmanFilter(sc.motion, sc.measurement)
    if batch is None:
        tracker = GMPHDTracker(kf, sc.p_detect, sc.clutter_density, max_speed=sc.max_speed)
        return lambda: tracker.track(scans.z, times=scans.times)
    F = np.asarray(sc.motion.transition_matrix(None))
    prior = np.einsum("ij,mnj->mni", np.linalg.inv(F), truth.states[0])
    initial = Gaussian(prior, np.broadcast_to(np.eye(4), (*prior.shape, 4)))
    tracker = PMHTTracker(kf, sc.p_detect, sc.clutter_density, batch=batch, max_iter=10, max_misses=10**6)
    return lambda: tracker.track(scans.z, times=scans.times, initial=initial)


def _fastest(jobs: list, rounds: int) -> np.ndarray:
    """Seconds per run-scan of each job: the fastest of ``rounds`` rounds over all jobs in turn.

    Round-robin, so that a burst of load from other jobs on a shared machine slows one timing of
    many points rather than every timing of a few neighbouring points.
    """
    best = np.full(len(jobs), np.inf)
    for _ in range(rounds):
        for i, job in enumerate(jobs):
            t0 = time.perf_counter()
            job()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best / (RUNS * STEPS)


def _slope(x, y) -> float:
    x, y = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    h = len(x) // 2
    return float(np.polyfit(x[h:], y[h:], 1)[0])


def growth(quick: bool = False, figure=None) -> dict:
    """Measure the grid, print the table, draw the figure (``figure`` path; default docs/img/pmht_cost_growth.png)."""
    global RUNS
    if quick:
        RUNS = 2
    sweeps = {
        "targets": (TARGETS[:3] if quick else TARGETS, lambda v, b: (v, 10.0, b)),
        "false alarms per scan": (CLUTTER[:3] if quick else CLUTTER, lambda v, b: (4, v, b)),
        "window length B (scans)": (BATCHES[:3] if quick else BATCHES, None),
    }
    points = []  # (sweep, value, batch or None)
    for name, (values, args) in sweeps.items():
        for v in values:
            if args is None:
                points.append((name, v, (4, 10.0, int(v))))
            else:
                points.append((name, v, args(v, 5)))
                points.append((name, v, args(v, None)))
    times = _fastest([_job(*p[2]) for p in points], 2 if quick else 5)
    out: dict = {}
    print("| sweep | value | PMHT ms per run-scan | GM-PHD ms per run-scan |")
    print("|---|---|---|---|")
    for name, (values, _) in sweeps.items():
        pm = np.array([t for p, t in zip(points, times) if p[0] == name and p[2][2] is not None])
        gm = np.array([t for p, t in zip(points, times) if p[0] == name and p[2][2] is None])
        gm = gm if gm.size else np.full(len(values), np.nan)
        for v, a, b in zip(values, pm, gm):
            g = f"{1e3 * b:.2f}" if np.isfinite(b) else "–"
            print(f"| {name} | {v:g} | {1e3 * a:.2f} | {g} |")
        out[name] = (np.asarray(values, float), pm, gm)
    print()
    for name, (x, pm, gm) in out.items():
        g = f", GM-PHD ~ x^{_slope(x, gm):.2f}" if np.isfinite(gm).all() else ""
        print(f"* {name}: PMHT ~ x^{_slope(x, pm):.2f}{g}")
    _draw(out, figure)
    return out


def _draw(out: dict, figure) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench_pmht import FIGURE

    path = FIGURE if figure is None else figure
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.8), constrained_layout=True)
    for ax, (name, (x, pm, gm)) in zip(axes, out.items()):
        ax.loglog(x, 1e3 * pm, "o-", color="C0", label=f"PMHT (slope {_slope(x, pm):.2f})")
        if np.isfinite(gm).all():
            ax.loglog(x, 1e3 * gm, "s--", color="C1", label=f"GM-PHD (slope {_slope(x, gm):.2f})")
        ax.set_xlabel(name)
        ax.set_ylabel("ms per run-scan (one core)")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{v:g}" for v in x])
        ys = 1e3 * np.concatenate([pm, gm[np.isfinite(gm)]])
        ticks = [t for t in (0.5, 1, 2, 5, 10, 20, 50, 100) if ys.min() / 1.5 <= t <= ys.max() * 1.5]
        ax.set_yticks(ticks)
        ax.set_yticklabels([f"{t:g}" for t in ticks])
        ax.minorticks_off()
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
    axes[0].set_title("targets (10 false alarms, B = 5)", fontsize=9)
    axes[1].set_title("false alarms per scan (4 targets, B = 5)", fontsize=9)
    axes[2].set_title("PMHT window length (4 targets, 10 false alarms)", fontsize=9)
    fig.suptitle(f"pursuit PMHT and GM-PHD: time per run-scan, {RUNS} runs in one batch, {STEPS} scans, P_D = 0.9 (fastest of 5)", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"\nwrote {path}")
