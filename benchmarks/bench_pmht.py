"""PMHT: pursuit's PMHTTracker (all runs in one batch) against Stone Soup's (one run at a time).

Three pieces of work, the same detections for both libraries, scored by pursuit's GOSPA (p = 2,
α = 2; mean over scans and runs with the 95 % interval over runs):

* **Stone Soup's own PMHT example** (``docs/examples/dataassociation/Pmht_Example.py``) rebuilt in
  pursuit terms: two CV targets from (−20, 5, 0, 10) and (20, −5, 0, 10) (state x, vx, y, vy),
  q = 1, R = I, P_D = 0.5, 10⁻³ false alarms per scan over 2 km × 2 km, 50 scans; batches of
  10 scans, 10 EM iterations, re-estimated priors (``update_log_pi``); both trackers start from the
  example's priors (the true start states, covariance I; here one scan before the first scan)
  and hold a fixed set of tracks.  GOSPA c = 10.
* **Williams 2015** (``mt-williams``: four CV targets, 10 false alarms per scan over
  300 m × 300 m, P_D = 0.9, 81 scans, GOSPA c = 10), windows of 5 scans sliding by one scan (Stone
  Soup: ``batch_len`` 5, ``overlap_len`` 4), fixed priors, at most 10 EM iterations.  Stone Soup's
  PMHT holds a fixed set of tracks, so it starts from the four true states one scan before scan 1
  (covariance I); pursuit runs twice: from the same priors with no initiation or deletion (the
  same tracker), and with its own two-point initiation, 2-of-3 confirmation and W-hysteresis
  termination (the ``mt-williams`` configuration).
* **The clutter-prior case**: Stone Soup 1.9.1 gives the clutter hypothesis of every scan of a
  batch the prior of the batch's *first* scan (``_compute_log_weights`` reads
  ``self._log_pi[start_logpi_index][0]``, the targets ``[start_logpi_index + k]``).  With
  re-estimated priors and a first scan without detections that prior is −∞ for the whole batch:
  every clutter point is then forced onto a track.  One target, one false alarm 6 m from it in
  scans 2-5, scan 1 empty; the error of the track with Stone Soup as it is, with the one index
  corrected (``_stonesoup_mt.corrected_pmht``, labelled), and with pursuit.
* **The smoother case**: one target, no clutter, P_D ≈ 1, one batch of 10 scans: PMHT must then
  equal the RTS smoother (spec 05 §7; pursuit's ``tests/multitarget/test_pmht.py`` checks 1e-9).
  Stone Soup's ``_iterate`` starts every EM iteration from the previous iteration's smoothed state
  at the batch's first scan (``track[k0]``, overwritten by the last M-step), so that scan's data
  enter again at each iteration; the table gives its distance from Stone Soup's own
  ``KalmanSmoother`` after 1 and after 10 iterations.

A *scan* is one run's scan; rates are runs × scans / wall time on one core (BLAS on one thread),
pursuit's the median of 3 repetitions, Stone Soup's one pass (it takes minutes per run).  Stone
Soup's estimate of a scan is its track state in the batch that first brings the scan in.

``--growth`` measures instead how pursuit's PMHT and GM-PHD time per scan grows with the number of
targets, of false alarms per scan and with the window length, and draws ``docs/img/pmht_cost_growth.png``.

Run::

    .bench-venv/bin/python benchmarks/bench_pmht.py            # needs stonesoup (make bench installs it)
    .venv/bin/python benchmarks/bench_pmht.py --growth         # the cost-growth figure
    .venv/bin/python benchmarks/run.py --quick --only pmht      # smoke run
"""

from __future__ import annotations

import _one_core  # first: NumPy on one core (benchmarks/ is on sys.path when a benchmark runs)

_one_core.pin()

import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _timing import median_time  # noqa: E402
from pursuit.filters import KalmanFilter  # noqa: E402
from pursuit.gaussian import Gaussian  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian  # noqa: E402
from pursuit.multitarget import GMPHDTracker, PMHTTracker, gospa, gospa_summary  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.multitarget import MultiTargetScenario, Target, williams15  # noqa: E402

SS_ITER = 10  # Stone Soup's example runs 10 EM iterations per batch; pursuit stops earlier once converged
NEVER = 10**6  # max_misses that never ends a track: the fixed track set of Stone Soup's PMHT
FIGURE = Path(__file__).resolve().parents[1] / "docs" / "img" / "pmht_cost_growth.png"


def stonesoup_example() -> MultiTargetScenario:
    """Stone Soup's PMHT example (two CV targets, P_D = 0.5, 10⁻³ false alarms per scan) in pursuit terms."""
    motion = ConstantVelocity(ndim=2, dt=1.0, q=1.0, noise="continuous")
    sensor = LinearGaussian.position(4, (0, 2), 1.0)
    targets = (Target([-20.0, 5.0, 0.0, 10.0]), Target([20.0, -5.0, 0.0, 10.0]))
    return MultiTargetScenario(targets, motion, sensor, [[-1000.0, 1000.0], [-1000.0, 1000.0]], 1e-3, 0.5, 50, 1.0, "stonesoup-pmht-example")


def _true_priors(sc: MultiTargetScenario, truth) -> np.ndarray:
    """``(M, N, n)``: each target's true state at scan 1 taken one scan back (F⁻¹ x₁), the fixed trackers' priors."""
    F = np.asarray(sc.motion.transition_matrix(None), dtype=float)
    return np.einsum("ij,mnj->mni", np.linalg.inv(F), truth.states[0])


def _score(sc, truth, est, mask, c: float) -> tuple[float, float]:
    pos = list(sc.motion.position_indices)
    s = gospa_summary(gospa(truth.positions(pos), truth.exists, est, mask, c, 2.0, 2.0))["total"]
    return s.mean, s.half_width


def pursuit_pmht_row(label, sc, truth, scans, *, c, batch, estimate_priors, priors=None, repeats=3) -> dict:
    """pursuit's PMHT on all runs at once: from ``priors`` with a fixed track set, or with its own initiation."""
    kf = KalmanFilter(sc.motion, sc.measurement)
    runs = scans.z.shape[1]
    kw = dict(batch=batch, max_iter=SS_ITER, estimate_priors=estimate_priors, volume=sc.clutter_volume)
    if priors is None:
        tracker = PMHTTracker(kf, sc.p_detect, sc.clutter_density, max_speed=sc.max_speed, **kw)
        initial = None
    else:
        tracker = PMHTTracker(kf, sc.p_detect, sc.clutter_density, max_misses=NEVER, **kw)
        initial = Gaussian(priors, np.broadcast_to(np.eye(priors.shape[-1]), (*priors.shape, priors.shape[-1])))
    out = {}

    def go():
        out["res"] = tracker.track(scans.z, times=scans.times, initial=initial)

    wall = median_time(go, repeats)
    res = out["res"]
    est, mask = res.positions(list(sc.motion.position_indices))
    mean, half = _score(sc, truth, est, mask, c)
    used = res.iterations[res.iterations > 0]
    return {"implementation": label, "runs": runs, "rate": runs * sc.steps / wall, "gospa": mean, "ci": half, "iterations": used.mean()}


def stonesoup_pmht_row(label, sc, truth, scans, priors, *, c, batch_len, overlap_len, update_log_pi, corrected=False, steps=None) -> dict | None:
    """Stone Soup's PMHT, one run at a time (None without stonesoup)."""
    try:
        import stonesoup  # noqa: F401

        from _stonesoup_mt import pmht_one_run
    except ImportError:  # pragma: no cover - depends on the environment
        return None
    K = sc.steps if steps is None else steps
    runs = scans.z.shape[1]
    L = priors.shape[1]
    est = np.full((K, runs, L, 2), np.nan)
    mask = np.zeros((K, runs, L), dtype=bool)
    t0 = time.perf_counter()
    for r in range(runs):
        per_scan = [zk[np.isfinite(zk).all(axis=-1)] for zk in scans.z[:K, r]]
        out = pmht_one_run(
            per_scan, prior_means=priors[r], prior_cov=np.eye(4), q=float(sc.motion.q), R=np.asarray(sc.measurement.cov(1)),
            dt=sc.dt, p_detect=sc.p_detect, clutter_rate=sc.clutter_rate, meas_range=sc.clutter_region, batch_len=batch_len,
            overlap_len=overlap_len, max_iter=SS_ITER, update_log_pi=update_log_pi, corrected=corrected,
        )  # fmt: skip
        for k, pos in enumerate(out):
            est[k, r, : len(pos)] = pos
            mask[k, r, : len(pos)] = True
    wall = time.perf_counter() - t0
    keep = truth if steps is None else type(truth)(truth.states[:K], truth.exists[:K], truth.labels)
    mean, half = _score(sc, keep, est, mask, c)
    return {"implementation": label, "runs": runs, "rate": runs * K / wall, "gospa": mean, "ci": half, "iterations": float(SS_ITER)}


def _table(title: str, rows: list[dict], ref: dict | None, peer: dict | None) -> None:
    print(f"**{title}**\n")
    print("| implementation | runs | scans/s (one core) | GOSPA mean ± 95 % | EM iterations per window | pursuit / Stone Soup speed |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        if r is None:
            continue
        ratio = f"{ref['rate'] / peer['rate']:.0f}x" if (peer is not None and r is ref) else ""
        print(f"| {r['implementation']} | {r['runs']} | {r['rate']:.1f} | {r['gospa']:.3f} ± {r['ci']:.3f} | {r['iterations']:.1f} | {ratio} |")
    print()


def example_table(quick: bool) -> None:
    sc = stonesoup_example()
    runs, peer_runs = (3, 1) if quick else (100, 10)
    truth, scans = sc.simulate(run_streams(1000, range(runs), 0), runs)
    priors = _true_priors(sc, truth)
    kw = dict(c=10.0, batch=10, estimate_priors=True)
    ours = pursuit_pmht_row("pursuit PMHT", sc, truth, scans, priors=priors, **kw)
    sel = range(peer_runs)
    t_p, s_p, pr_p = truth.select_runs(sel), scans.select_runs(sel), priors[:peer_runs]
    same = pursuit_pmht_row(f"pursuit PMHT (the peer's {peer_runs} runs)", sc, t_p, s_p, priors=pr_p, **kw)
    ss_kw = dict(c=10.0, batch_len=10, overlap_len=5, update_log_pi=True, steps=20 if quick else None)
    peer = stonesoup_pmht_row("Stone Soup PMHTTracker (one run at a time)", sc, t_p, s_p, pr_p, **ss_kw)
    fixed = stonesoup_pmht_row("Stone Soup PMHTTracker, clutter prior per scan (corrected variant)", sc, t_p, s_p, pr_p, corrected=True, **ss_kw)
    _table("Stone Soup's PMHT example (2 targets, P_D = 0.5, 10⁻³ false alarms per scan, batches of 10 scans)", [ours, same, peer, fixed], ours, peer)


def williams_table(quick: bool) -> None:
    sc = williams15()
    runs, peer_runs = (3, 1) if quick else (100, 2)
    truth, scans = sc.simulate(run_streams(0, range(runs), 0), runs)
    priors = _true_priors(sc, truth)
    sel = range(peer_runs)
    t_p, s_p, pr_p = truth.select_runs(sel), scans.select_runs(sel), priors[:peer_runs]
    kw = dict(c=10.0, batch=5, estimate_priors=False)
    ours = pursuit_pmht_row("pursuit PMHT, from the true priors, fixed track set", sc, truth, scans, priors=priors, **kw)
    same = pursuit_pmht_row(f"pursuit PMHT, from the true priors (the peer's {peer_runs} runs)", sc, t_p, s_p, priors=pr_p, **kw)
    own = pursuit_pmht_row("pursuit PMHT, own initiation and termination", sc, truth, scans, **kw)
    own_same = pursuit_pmht_row(f"pursuit PMHT, own initiation (the peer's {peer_runs} runs)", sc, t_p, s_p, **kw)
    ss_kw = dict(c=10.0, batch_len=5, overlap_len=4, update_log_pi=False, steps=10 if quick else None)
    peer = stonesoup_pmht_row("Stone Soup PMHTTracker, from the true priors (one run at a time)", sc, t_p, s_p, pr_p, **ss_kw)
    fixed = stonesoup_pmht_row("Stone Soup PMHTTracker, clutter prior per scan (corrected variant)", sc, t_p, s_p, pr_p, corrected=True, **ss_kw)
    _table("Williams 2015 (4 targets, P_D = 0.9, 10 false alarms per scan, windows of 5 scans sliding by one)", [ours, same, own, own_same, peer, fixed], ours, peer)


def clutter_prior_case() -> list[dict]:
    """One target, scan 1 empty, a false alarm 6 m from the target in scans 2-5: mean position error over scans 2-5."""
    sc_kw = dict(q=1.0, R=np.eye(2), dt=1.0, p_detect=0.9, clutter_rate=1.0, meas_range=[[-10.0, 10.0], [-10.0, 10.0]])
    truth = np.array([[float(k), 0.0] for k in range(1, 6)])  # x = k, y = 0, speed (1, 0)
    scans = [np.zeros((0, 2))] + [np.array([truth[k], truth[k] + [0.0, 6.0]]) for k in range(1, 5)]
    prior = np.array([[0.0, 1.0, 0.0, 0.0]])
    rows = []
    try:
        import stonesoup  # noqa: F401

        from _stonesoup_mt import pmht_one_run
    except ImportError:  # pragma: no cover - depends on the environment
        pmht_one_run = None
    if pmht_one_run is not None:
        for label, corrected in (("Stone Soup PMHTTracker", False), ("Stone Soup PMHTTracker, clutter prior per scan (corrected variant)", True)):
            out = pmht_one_run(scans, prior_means=prior, prior_cov=np.eye(4), batch_len=5, overlap_len=0, max_iter=SS_ITER, update_log_pi=True, corrected=corrected, **sc_kw)
            rows.append({"implementation": label, "error": np.mean([np.linalg.norm(out[k][0] - truth[k]) for k in range(1, 5)])})
    motion = ConstantVelocity(ndim=2, dt=1.0, q=1.0, noise="continuous")
    kf = KalmanFilter(motion, LinearGaussian.position(4, (0, 2), 1.0))
    z = np.full((5, 1, 2, 2), np.nan)
    for k, s in enumerate(scans):
        z[k, 0, : len(s)] = s
    tracker = PMHTTracker(kf, 0.9, 1.0 / 400.0, batch=5, max_iter=SS_ITER, estimate_priors=True, volume=400.0, max_misses=NEVER)
    res = tracker.track(z, initial=Gaussian(prior, np.eye(4)[None]))
    # pursuit reports the filtered estimate at the end of the window ending at each scan
    est = res.mean[:, 0, 0][:, [0, 2]]
    rows.append({"implementation": "pursuit PMHT (estimate_priors)", "error": np.mean(np.linalg.norm(est[1:] - truth[1:], axis=-1))})
    return rows


def smoother_case() -> list[dict]:
    """Stone Soup's PMHT on one target without clutter against its own KF + RTS smoother: largest position difference."""
    try:
        import datetime

        from stonesoup.smoother.kalman import KalmanSmoother
        from stonesoup.types.hypothesis import SingleHypothesis
        from stonesoup.types.state import GaussianState
        from stonesoup.types.track import Track

        from _stonesoup_mt import _components, _feed, pmht_one_run
    except ImportError:  # pragma: no cover - depends on the environment
        return []
    rng = np.random.default_rng(1)
    F = np.asarray(ConstantVelocity(ndim=2, dt=1.0, q=1.0, noise="continuous").transition_matrix(None))
    x, scans = np.array([0.0, 1.0, 0.0, 0.0]), []
    for _ in range(10):
        x = F @ x
        scans.append(x[[0, 2]][None] + rng.normal(size=(1, 2)))
    transition, measurement, predictor, updater, _ = _components(1.0, np.eye(2), 1.0, 1.0, 1.0)
    start = datetime.datetime(2000, 1, 1)
    state = GaussianState(np.array([[0.0], [1.0], [0.0], [0.0]]), np.eye(4), timestamp=start)
    track = Track()
    for t, dets in _feed(scans, measurement, 1.0, start):
        state = updater.update(SingleHypothesis(predictor.predict(state, timestamp=t), next(iter(dets))))
        track.append(state)
    rts = np.array([np.asarray(s.state_vector, dtype=float).ravel()[[0, 2]] for s in KalmanSmoother(transition).smooth(track)])
    rows = []
    for it in (1, SS_ITER):
        out = pmht_one_run(
            scans, prior_means=np.array([[0.0, 1.0, 0.0, 0.0]]), prior_cov=np.eye(4), q=1.0, R=np.eye(2), dt=1.0, p_detect=0.999,
            clutter_rate=1e-6, meas_range=[[-1e3, 1e3], [-1e3, 1e3]], batch_len=10, overlap_len=0, max_iter=it, update_log_pi=False,
        )  # fmt: skip
        diff = np.max(np.linalg.norm(np.array([o[0] for o in out]) - rts, axis=-1))
        rows.append({"implementation": f"Stone Soup PMHTTracker, {it} EM iteration{'s' if it > 1 else ''}", "diff": diff})
    return rows


def main(quick: bool = False) -> None:
    """Measure and print the markdown tables."""
    example_table(quick)
    williams_table(quick)
    print("**The clutter-prior case (one target; scan 1 empty; a false alarm 6 m off the target in scans 2-5; re-estimated priors)**\n")
    print("| implementation | mean position error, scans 2-5 (m) |")
    print("|---|---|")
    for r in clutter_prior_case():
        print(f"| {r['implementation']} | {r['error']:.2f} |")
    rows = smoother_case()
    if rows:
        print("\n**The smoother case (one target, no clutter, P_D ≈ 1, one batch of 10 scans)**\n")
        print("| implementation | largest distance from the RTS smoother's positions (m) |")
        print("|---|---|")
        for r in rows:
            print(f"| {r['implementation']} | {r['diff']:.2e} |")


if __name__ == "__main__":
    import sys

    if "--growth" in sys.argv:
        from _pmht_growth import growth

        growth(quick="--quick" in sys.argv)
    else:
        main(quick="--quick" in sys.argv)
