"""The filters every conformance test runs on.

Add a :class:`Case` here when you add a filter: the conformance suite
(`test_conformance.py`) then checks its output shapes, batch-versus-single
equality, NaN handling, determinism and the meaning of its NIS.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import pursuit as pu
from pursuit.scenarios import LinearCV, WSNRange


@dataclass(frozen=True)
class Case:
    """A filter built against a scenario.

    Attributes
    ----------
    id
        Test id.
    build
        ``build(scenario) -> filter``.
    exact_on_linear
        The filter is exact (a Kalman filter in disguise) on linear-Gaussian
        models, so its NIS must be χ² with the measurement dimension.
    nis_tolerance
        For approximate filters (particle filters), the allowed relative
        deviation of the mean NIS from the measurement dimension on the
        linear model.
    """

    id: str
    build: Callable[[Any], Any]
    exact_on_linear: bool = True
    nis_tolerance: float = 0.0


LINEAR = LinearCV(ndim=2, steps=25, q=0.05, sigma=1.0)
NONLINEAR = WSNRange(steps=25)

CASES = [
    Case("kf", lambda s: pu.KalmanFilter(s.motion, s.measurement)),
    Case("ekf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement)),
    Case("ukf", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement)),
    Case("ukf-alpha", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, alpha=0.5, beta=2.0, kappa=1.0)),
    Case("ckf", lambda s: pu.CubatureKalmanFilter(s.motion, s.measurement)),
    Case("ekf-fading", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.Constant(1.05)), exact_on_linear=False),
    # adaptive fading strategies (paper P2 and the strong tracking filter): λ can exceed 1
    Case("kf-ewfmkf", lambda s: pu.KalmanFilter(s.motion, s.measurement, fading=pu.ExponentiallyWeighted()), exact_on_linear=False),
    Case("ekf-ewfmkf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.ExponentiallyWeighted(b=0.9)), exact_on_linear=False),
    Case("ekf-stf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.StrongTracking()), exact_on_linear=False),
    Case("ukf-stf", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, fading=pu.StrongTracking(rho=0.8, beta=1.5)), exact_on_linear=False),
    Case("kf-ifmkf", lambda s: pu.KalmanFilter(s.motion, s.measurement, fading=pu.Improved()), exact_on_linear=False),
    Case("ekf-ifmkf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.Improved()), exact_on_linear=False),
    Case("ckf-ifmkf", lambda s: pu.CubatureKalmanFilter(s.motion, s.measurement, fading=pu.Improved(beta=1.0, search="minimise", grid=24)), exact_on_linear=False),
    Case("ukf-ifmkf-instant", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, fading=pu.Improved(beta=1.0, test="instant", search="stf")), exact_on_linear=False),
]

# The plain Kalman filter needs linear models.
NONLINEAR_CASES = [c for c in CASES if c.id != "kf" and not c.id.startswith("kf-")]
