"""One single run of 10^6 steps per Gaussian filter on the hard long scenario.

    python benchmarks/long_run.py [FILTER ...]     (from the repository root; default: all four)

The test suite checks 10^6 filter steps per filter as 200 runs x 5000 steps
(tests/filters/test_robustness.py), which costs seconds; this script runs the
same scenario as ONE run of 10^6 steps, which costs minutes, and prints for each
filter the wall time, the number of covariance repairs, the number of
covariances that failed a Cholesky check, and whether any value was non-finite.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pursuit as pu  # noqa: E402
from tests.filters.test_robustness import long_scenario  # noqa: E402

FILTERS = {
    "kf": (pu.KalmanFilter, "position"),
    "ekf": (pu.ExtendedKalmanFilter, "range"),
    "ukf": (pu.UnscentedKalmanFilter, "range"),
    "ckf": (pu.CubatureKalmanFilter, "toa"),
}


def main(names: list[str]) -> int:
    for name in names or list(FILTERS):
        cls, sensor = FILTERS[name]
        motion, meas, z, dts, prior = long_scenario(sensor, runs=1, steps=10**6)
        filt = cls(motion, meas)
        state = filt.init(prior, (1,))
        covs = np.empty((1000, 1, 4, 4))
        repaired = not_pd = 0
        finite = True
        t0 = time.perf_counter()
        for i in range(z.shape[0]):
            state, info = filt.step(state, z[i], dt=float(dts[i]))
            repaired += int(np.count_nonzero(info["repaired"]))
            covs[i % 1000] = state.cov
            if i % 1000 == 999:
                finite &= bool(np.all(np.isfinite(covs)) and np.all(np.isfinite(state.mean)))
                w = np.linalg.eigvalsh(covs)[..., 0]
                not_pd += int(np.count_nonzero(w <= 0))
        wall = time.perf_counter() - t0
        print(f"{name} ({sensor}): {z.shape[0]} steps in one run, {wall:.0f} s, repaired={repaired}, not_positive_definite={not_pd}, all_finite={finite}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
