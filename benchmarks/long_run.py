"""One single run of 10^6 steps per Gaussian filter on the hard long scenario.

    python benchmarks/long_run.py [NAME ...] [--steps N]    (from the repository root)

NAME is a filter (kf, ekf, ukf, ckf), a filter with a fading strategy
(ekf+stf, ukf+ifmkf, ...: strategies ewfmkf, stf, ifmkf with their defaults),
a maneuvering-target filter (cs, apcs, ms, kf-singer, imm-singer: the long
maneuvering scenario of tests/filters/test_robustness.py, a 3-D maneuvering
path at 200 km sampled every second, 1 mm fixes, 20 % missing components and
100 s outages), or a group: plain (the four filters; the default), fading (the
twelve fading variants), maneuver (the five maneuvering filters) or all.

The test suite checks 10^6 filter steps per filter as 200 runs x 5000 steps
(tests/filters/test_robustness.py), which costs seconds; this script runs the
same scenario as ONE run of 10^6 steps, which costs minutes, and prints for each
filter the wall time, the number of covariance repairs, the number of
covariances that failed a Cholesky factorisation, whether any value was
non-finite, and the smallest ratio of smallest to largest eigenvalue met (how
close to singular the covariance came; an eigenvalue below about 1e-16 of the
largest is beneath the accuracy of eigvalsh itself, so the Cholesky test is
the one that counts).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pursuit as pu  # noqa: E402
from tests.filters.test_robustness import MANEUVER_FILTERS, long_maneuver_scenario, long_scenario  # noqa: E402

FILTERS = {
    "kf": (pu.KalmanFilter, "position"),
    "ekf": (pu.ExtendedKalmanFilter, "range"),
    "ukf": (pu.UnscentedKalmanFilter, "range"),
    "ckf": (pu.CubatureKalmanFilter, "toa"),
}
FADING = {"ewfmkf": pu.ExponentiallyWeighted, "stf": pu.StrongTracking, "ifmkf": pu.Improved}
GROUPS = {
    "plain": list(FILTERS),
    "fading": [f"{f}+{s}" for f in FILTERS for s in FADING],
}
GROUPS["maneuver"] = list(MANEUVER_FILTERS)
GROUPS["all"] = GROUPS["plain"] + GROUPS["fading"] + GROUPS["maneuver"]


def _expand(names: list[str]) -> list[str]:
    out = []
    for name in names or ["plain"]:
        for n in GROUPS.get(name, [name]):
            f, _, s = n.partition("+")
            if n not in MANEUVER_FILTERS and (f not in FILTERS or (s and s not in FADING)):
                raise SystemExit(
                    f"unknown name {n!r}: use {', '.join(FILTERS)}, FILTER+{{{','.join(FADING)}}}, "
                    f"{', '.join(MANEUVER_FILTERS)} or {', '.join(GROUPS)}"
                )
            out.append(n)
    return out


def _factors(c: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(c)
        return True
    except np.linalg.LinAlgError:
        return False


def _single_run(label: str, filt, z: np.ndarray, dts: np.ndarray, prior, fading: bool) -> None:
    """Step ``filt`` through one long run, checking every covariance; print one summary line."""
    state = filt.init(prior, (1,))
    n = prior.dim
    covs = np.empty((1000, 1, n, n))
    repaired = not_pd = 0
    finite = True
    worst = np.inf
    lam_max = 1.0
    faded = 0
    t0 = time.perf_counter()
    error = ""
    for i in range(z.shape[0]):
        try:
            state, info = filt.step(state, z[i], dt=float(dts[i]))
        except (np.linalg.LinAlgError, ValueError) as e:
            error = f", FAILED at step {i + 1}: {type(e).__name__}: {e}"
            break
        repaired += int(np.count_nonzero(info["repaired"]))
        if fading:
            lam = float(np.max(info["fading"]))
            lam_max = max(lam_max, lam)
            faded += lam > 1.0
        covs[i % 1000] = state.cov
        if i % 1000 == 999 or i == z.shape[0] - 1:
            chunk = covs[: i % 1000 + 1]
            finite &= bool(np.all(np.isfinite(chunk)) and np.all(np.isfinite(state.mean)))
            w = np.linalg.eigvalsh(chunk)
            worst = min(worst, float(np.min(w[..., 0] / w[..., -1])))
            try:
                np.linalg.cholesky(chunk)
            except np.linalg.LinAlgError:
                not_pd += sum(1 for c in chunk.reshape(-1, n, n) if not _factors(c))
    wall = time.perf_counter() - t0
    extra = f", faded_steps={faded}, max_lambda={lam_max:.3g}" if fading else ""
    print(
        f"{label}: {z.shape[0]} steps in one run, {wall:.0f} s, repaired={repaired}, "
        f"cholesky_failures={not_pd}, all_finite={finite}, min_eig_ratio={worst:.3g}{extra}{error}",
        flush=True,
    )


def main(argv: list[str]) -> int:
    steps = 10**6
    if "--steps" in argv:
        i = argv.index("--steps")
        steps = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2 :]
    for name in _expand(argv):
        if name in MANEUVER_FILTERS:  # the long maneuvering scenario
            meas, z, dts, prior = long_maneuver_scenario(runs=1, steps=steps)
            _single_run(f"{name} (maneuver)", MANEUVER_FILTERS[name](meas), z, dts, prior, fading=False)
            continue
        f, _, strategy = name.partition("+")
        cls, sensor = FILTERS[f]
        motion, meas, z, dts, prior = long_scenario(sensor, runs=1, steps=steps)
        filt = cls(motion, meas, fading=FADING[strategy]()) if strategy else cls(motion, meas)
        _single_run(f"{name} ({sensor})", filt, z, dts, prior, fading=bool(strategy))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
