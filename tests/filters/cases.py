"""The filters every conformance test runs on.

Add a :class:`Case` here when you add a filter: the conformance suite
(`test_conformance.py`) then checks its output shapes, batch-versus-single
equality, NaN handling, determinism and the meaning of its NIS.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import Any, Callable

import pursuit as pu
from pursuit.filters import (
    AdaptiveCSFilter,
    CurrentStatisticalFilter,
    InteractingMultipleModel,
    ModifiedSingerFilter,
    NonlinearCSFilter,
    kinematic_map,
)
from pursuit.filters.cuckoo import CSPF, ICSPF, CuckooSearch
from pursuit.filters.particle import BootstrapParticleFilter
from pursuit.filters.upf import PartialUPF
from pursuit.models import ConstantVelocity, Singer
from pursuit.scenarios import LinearCV, ManeuveringTarget, WSNRange
from pursuit.scenarios.bearings import BearingsOnlyTarget


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
        linear model (0: not checked).
    scenario
        A scenario of its own for filters that need a particular state
        layout (the CS-model filters need ``[p, v, a]`` per axis); the
        shared linear and nonlinear scenarios are then skipped.
    gaussian_loglik
        The filter's ``loglik`` is log N(ν; 0, S) (Gaussian filters).  A
        particle filter reports the particle estimate of the marginal
        likelihood increment instead (see ``pursuit.filters.particle``).
    """

    id: str
    build: Callable[[Any], Any]
    exact_on_linear: bool = True
    nis_tolerance: float = 0.0
    scenario: Any = None
    gaussian_loglik: bool = True


LINEAR = LinearCV(ndim=2, steps=25, q=0.05, sigma=1.0)
NONLINEAR = WSNRange(steps=25)
MANEUVER = ManeuveringTarget(horizon=27, maneuvers=[{"axis": "y", "start": 10, "stop": 18, "accel": 40.0}])
BEARINGS = BearingsOnlyTarget(dims=3, horizon=27, maneuvers=[{"axis": "y", "start": 10, "stop": 18, "accel": 10.0}])


def _singer_kf(s, alpha, sigma):
    return pu.KalmanFilter(Singer(alpha=alpha, sigma=sigma, ndim=3, dt=s.dt), s.measurement)


def _imm_cv_singer(s):
    cv = ConstantVelocity(ndim=3, dt=s.dt, q=0.5)
    meas_cv = pu.models.LinearGaussian.position(cv.dim, cv.position_indices, s.R**0.5)
    singer = Singer(alpha=0.1, sigma=30.0, ndim=3, dt=s.dt)
    modes = [pu.KalmanFilter(cv, meas_cv), pu.KalmanFilter(singer, s.measurement)]
    return InteractingMultipleModel(modes, 0.9, maps=[kinematic_map(cv, singer, fill_var=1.0), None], name="IMM-CV-Singer")

CASES = [
    Case("kf", lambda s: pu.KalmanFilter(s.motion, s.measurement)),
    Case("ekf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement)),
    Case("ukf", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement)),
    Case("ukf-alpha", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, alpha=0.5, beta=2.0, kappa=1.0)),
    Case("ckf", lambda s: pu.CubatureKalmanFilter(s.motion, s.measurement)),
    Case("ekf-fading", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.Constant(1.05)), exact_on_linear=False),
    Case(
        "imm-ekf",
        lambda s: InteractingMultipleModel(
            [pu.ExtendedKalmanFilter(s.motion, s.measurement), pu.ExtendedKalmanFilter(type(s.motion)(ndim=2, q=1.0), s.measurement)],
            0.95,
        ),
        exact_on_linear=False,
    ),
    Case("cs", lambda s: CurrentStatisticalFilter(s.measurement, dt=s.dt), exact_on_linear=False, scenario=MANEUVER),
    Case("apcs", lambda s: AdaptiveCSFilter(s.measurement, dt=s.dt), exact_on_linear=False, scenario=MANEUVER),
    Case("ms", lambda s: ModifiedSingerFilter(s.measurement, dt=s.dt, warmup=3), exact_on_linear=False, scenario=MANEUVER),
    Case("kf-singer", lambda s: _singer_kf(s, 0.05, 20.0), exact_on_linear=False, scenario=MANEUVER),
    Case(
        "imm-singer",
        lambda s: InteractingMultipleModel([_singer_kf(s, a, q) for a, q in ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))], 0.95),
        exact_on_linear=False,
        scenario=MANEUVER,
    ),
    Case("imm-cv-singer", _imm_cv_singer, exact_on_linear=False, scenario=MANEUVER),
    # the joint CS-model filter on the per-axis scenario and on azimuth + elevation
    Case("cs-nonlinear-apcs", lambda s: NonlinearCSFilter(s.measurement, dt=s.dt, adaptation="apcs"), exact_on_linear=False, scenario=MANEUVER),
    Case("cs-nonlinear-ekf", lambda s: NonlinearCSFilter(s.measurement, dt=s.dt, alpha0=0.05, a_max=2.0, fading="stf"), exact_on_linear=False, scenario=BEARINGS),
    Case("cs-nonlinear-ukf", lambda s: NonlinearCSFilter(s.measurement, dt=s.dt, update="ukf", alpha0=0.05, a_max=2.0, gate=0.99), exact_on_linear=False, scenario=BEARINGS),
    # χ² gates on the per-axis filters and on the IMM (a step with a rejected run re-runs the IMM's
    # modes for the whole batch: the other runs must not notice).  APCS and IMM-Singer adapt to
    # this scenario's maneuver, so only a tight gate (0.7) rejects some of their steps here.
    Case("cs-gated", lambda s: CurrentStatisticalFilter(s.measurement, dt=s.dt, gate=0.9), exact_on_linear=False, scenario=MANEUVER),
    Case("apcs-gated", lambda s: AdaptiveCSFilter(s.measurement, dt=s.dt, gate=0.7), exact_on_linear=False, scenario=MANEUVER),
    Case(
        "imm-singer-gated",
        lambda s: InteractingMultipleModel([_singer_kf(s, a, q) for a, q in ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))], 0.95, gate=0.7),
        exact_on_linear=False,
        scenario=MANEUVER,
    ),
    # adaptive fading strategies (paper P2 and the strong tracking filter): λ can exceed 1
    Case("kf-ewfmkf", lambda s: pu.KalmanFilter(s.motion, s.measurement, fading=pu.ExponentiallyWeighted()), exact_on_linear=False),
    Case("ekf-ewfmkf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.ExponentiallyWeighted(b=0.9)), exact_on_linear=False),
    Case("ekf-stf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.StrongTracking()), exact_on_linear=False),
    Case("ukf-stf", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, fading=pu.StrongTracking(rho=0.8, beta=1.5)), exact_on_linear=False),
    Case("kf-ifmkf", lambda s: pu.KalmanFilter(s.motion, s.measurement, fading=pu.Improved()), exact_on_linear=False),
    Case("ekf-ifmkf", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, fading=pu.Improved()), exact_on_linear=False),
    Case("ckf-ifmkf", lambda s: pu.CubatureKalmanFilter(s.motion, s.measurement, fading=pu.Improved(beta=1.0, search="minimise", grid=24)), exact_on_linear=False),
    Case("ukf-ifmkf-instant", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, fading=pu.Improved(beta=1.0, test="instant", search="stf")), exact_on_linear=False),
    # A tight chi-square gate rejects a few per cent of the measurements, so the runs of a
    # batch stop sharing one covariance: the batched path must still equal the
    # one-run-at-a-time path.
    Case("kf-gated", lambda s: pu.KalmanFilter(s.motion, s.measurement, gate=0.9), exact_on_linear=False),
    Case("ukf-gated", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, gate=0.9), exact_on_linear=False),
]

# Particle filters.  With N particles the predictive mean and covariance of z carry a
# Monte Carlo error that inflates the mean NIS by O(1/N) (measured on LINEAR against the
# KF: +12 % at N = 400, +2 % at N = 2000, +0.4 % at N = 10 000); the statistical error of
# the mean of 200 x 25 NIS values is about 2 %.  Hence N = 2000 and a 10 % tolerance.
_PF = dict(exact_on_linear=False, gaussian_loglik=False)
CASES += [
    Case("pf-systematic", lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=2000), nis_tolerance=0.1, **_PF),
    Case(
        "pf-stratified-ess",
        lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=2000, resampler="stratified", ess_threshold=0.5),
        nis_tolerance=0.1,
        **_PF,
    ),
    Case("pf-multinomial", lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=200, resampler="multinomial"), **_PF),
    Case(
        "pf-residual-ess",
        lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=200, resampler="residual", ess_threshold=0.7),
        **_PF,
    ),
    Case("upf-l0", lambda s: PartialUPF(s.motion, s.measurement, particles=100, fraction=0.0), **_PF),
    Case("upf-l0.5", lambda s: PartialUPF(s.motion, s.measurement, particles=100, fraction=0.5), **_PF),
    Case("upf-l1", lambda s: PartialUPF(s.motion, s.measurement, particles=50, fraction=1.0), **_PF),
    Case("cs-pf", lambda s: CSPF(s.motion, s.measurement, particles=100, search=CuckooSearch(n_iter=3, alpha_max=0.01, alpha_min=0.01, pa_max=0.25, pa_min=0.25, pa_schedule="constant", trend="off")), **_PF),
    Case("ics-pf", lambda s: ICSPF(s.motion, s.measurement, particles=100, search=CuckooSearch(n_iter=3)), **_PF),
    Case(
        "ics-pf-sequential-stop",
        lambda s: ICSPF(
            s.motion, s.measurement, particles=100, acceptance="greedy", weight_mode="sequential", search=CuckooSearch(n_iter=4, f_stop=0.9)
        ),
        **_PF,
    ),
    Case("ics-pf-greedy", lambda s: ICSPF(s.motion, s.measurement, particles=100, acceptance="greedy", search=CuckooSearch(n_iter=3)), **_PF),
    Case("ics-pf-weighted", lambda s: ICSPF(s.motion, s.measurement, particles=100, estimate="weighted", search=CuckooSearch(n_iter=3)), **_PF),
]


# Cases run on the nonlinear scenario too, except those that need linear models (the plain KF) or a
# scenario of their own.
NONLINEAR_CASES = [c for c in CASES if c.id != "kf" and not c.id.startswith("kf-") and c.scenario is None]

# The compiled backend (numba, pursuit[fast]) runs the whole conformance suite too: shapes, batch
# equals loop (bit for bit), missing data, determinism, NIS meaning.
if importlib.util.find_spec("numba") is not None:
    _NB = dict(backend="numba")
    CASES += [
        Case("kf-numba", lambda s: pu.KalmanFilter(s.motion, s.measurement, **_NB)),
        Case("ekf-numba", lambda s: pu.ExtendedKalmanFilter(s.motion, s.measurement, **_NB)),
        Case("ukf-numba", lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement, **_NB)),
        Case("ckf-fading-numba", lambda s: pu.CubatureKalmanFilter(s.motion, s.measurement, fading=1.05, **_NB), exact_on_linear=False),
        Case("pf-numba", lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=2000, **_NB), nis_tolerance=0.1, **_PF),
        Case(
            "pf-residual-ess-numba",
            lambda s: BootstrapParticleFilter(s.motion, s.measurement, particles=200, resampler="residual", ess_threshold=0.7, **_NB),
            **_PF,
        ),
        Case("ics-pf-numba", lambda s: ICSPF(s.motion, s.measurement, particles=100, search=CuckooSearch(n_iter=3), **_NB), **_PF),
        Case(
            "ics-pf-sequential-stop-numba",
            lambda s: ICSPF(
                s.motion, s.measurement, particles=100, acceptance="greedy", weight_mode="sequential",
                search=CuckooSearch(n_iter=4, f_stop=0.9), **_NB
            ),
            **_PF,
        ),
        Case("cs-pf-numba", lambda s: CSPF(s.motion, s.measurement, particles=100, search=CuckooSearch(n_iter=3, trend="off"), **_NB), **_PF),
        Case("upf-l0.5-numba", lambda s: PartialUPF(s.motion, s.measurement, particles=100, fraction=0.5, **_NB), **_PF),
        Case("upf-l1-numba", lambda s: PartialUPF(s.motion, s.measurement, particles=50, fraction=1.0, **_NB), **_PF),
        # the CS-model filter's compiled updates, with the moving observer's angles (azimuth + elevation)
        Case(
            "cs-nonlinear-ekf-numba",
            lambda s: NonlinearCSFilter(s.measurement, dt=s.dt, alpha0=0.05, a_max=2.0, **_NB),
            exact_on_linear=False,
            scenario=BEARINGS,
        ),
        Case(
            "cs-nonlinear-ukf-numba",
            lambda s: NonlinearCSFilter(s.measurement, dt=s.dt, update="ukf", alpha0=0.05, a_max=2.0, gate=0.99, **_NB),
            exact_on_linear=False,
            scenario=BEARINGS,
        ),
    ]
    NONLINEAR_CASES = [c for c in CASES if c.id != "kf" and not c.id.startswith("kf-") and c.scenario is None]
