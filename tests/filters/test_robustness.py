"""Numerical robustness of the Gaussian filters: long runs, ill-conditioned updates.

The long-run test gives every Gaussian filter 10^6 steps (a batch of 200
runs of 5000 steps each, so that the per-step Python overhead is paid 5000
times, not 10^6 times) on a deliberately hard scenario: irregular steps from
0.01 s to 10 s with rare 500 s gaps, precise sensors, 20 % of the components
missing at random.  Before the sigma-point filters used the Joseph form
(``filters/gaussian.py``) the UKF and the CKF lost positive definiteness
here (the ukf-range and ckf-toa cases failed), and before the 3x3 inverse
had its fallback for nearly singular S the TOA runs went to NaN.

The fading variants (EWFMKF, STF, IFMKF on every filter) run the same
scenario as 20 runs of 5000 steps.  Before the strategies kept λ under
:attr:`pursuit.filters.FadingContext.lam_ceiling` they failed within 50
steps: an innovation-driven λ reached 1e10 to 1e28 once a filter had lost
the target after a long gap, the predicted covariance swamped R and S was
singular (EKF+STF, EKF+IFMKF, UKF+STF: LinAlgError) or the covariances lost
positive definiteness (CKF+EWFMKF: 66 repairs).  With the ceiling alone one
EKF+EWFMKF run still died at step 1953: fading at a 0.01 s step had inflated
the unmeasured velocity covariance, a 500 s gap turned it into 3e11 m² of
position variance, and the 4x4 S was singular in floating point; since then
``inv_spd`` pseudo-inverts such a matrix as its 3x3 closed forms always did.

The maneuvering-target filters (CS, APCS, MS, the Singer-model KF and
IMM-Singer) get 10^6 steps of their own long scenario: a 3-D maneuvering path
at 200 km sampled every second, 1 mm position fixes, 20 % missing components
and 100 s outages.  APCS is not given the irregular steps above: its
strong-tracking memory V averages ν² over steps of any length, so after a
500 s gap it remembers a huge innovation and, at the next detection on a
0.04 s step, λ = (V − Q − r)/(F P Fᵀ)_pp reached 3e15; the covariance then has
a condition number beyond 1/ε and loses positive definiteness (the
displacement law 2Δx/T² likewise turns a post-gap correction at a short step
into σ_a ≈ 1e7 m/s²).  CS, MS, the Singer KF and IMM-Singer passed that
irregular scenario too (200 runs x 5000 steps, checked once, not a test).
"""

from __future__ import annotations

import numpy as np
import pytest

import pursuit as pu
from pursuit._linalg import inv_spd, symmetrize
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, InteractingMultipleModel, ModifiedSingerFilter
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors, Singer, TimeOfArrival

RUNS, STEPS = 200, 5000  # 10^6 filter steps per filter
ANCHORS = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
ARRAY = np.array([[0.0, 0.0], [0.0, 50.0], [50.0, 0.0]])
BEARING_SENSOR = np.array([-20.0, -30.0])


def _orbit(t):
    """A bounded Lissajous path inside the 100 m square (vectorised over any shape of t)."""
    return np.stack([50 + 40 * np.cos(2 * np.pi * t / 700.0), 50 + 40 * np.sin(2 * np.pi * t / 450.0)], axis=-1)


def long_scenario(sensor: str, runs: int = RUNS, steps: int = STEPS, seed: int = 1, gap_rate: float = 1e-3):
    """Models, measurements ``(K, M, m)``, time steps ``(K,)`` and prior of the hard scenario."""
    return scenario_with_truth(sensor, runs, steps, seed, gap_rate)[:5]


def scenario_with_truth(sensor: str, runs: int = RUNS, steps: int = STEPS, seed: int = 1, gap_rate: float = 1e-3):
    """:func:`long_scenario` and the true positions ``(K, M, 2)``; ``sensor`` also ``"range-bearing"`` (from BEARING_SENSOR)."""
    rng = np.random.default_rng(seed)
    # 64 distinct irregular steps (so the motion model's matrix cache works) plus rare long gaps
    levels = np.exp(np.linspace(np.log(0.01), np.log(10.0), 64))
    dts = levels[rng.integers(0, 64, steps)]
    dts[rng.random(steps) < gap_rate] = 500.0
    t = np.cumsum(dts)
    pos = _orbit(t[:, None] + rng.uniform(0, 1000, runs)[None, :])  # (K, M, 2)
    if sensor == "position":
        meas = LinearGaussian.position(4, (0, 2), 1e-3)
        z = pos + 1e-3 * rng.standard_normal(pos.shape)
    elif sensor == "range":
        meas = RangeSensors(ANCHORS, 1e-3)
        z = np.linalg.norm(pos[..., None, :] - ANCHORS, axis=-1) + 1e-3 * rng.standard_normal((steps, runs, 4))
    elif sensor == "toa":
        meas = TimeOfArrival(ARRAY, 1e-6)
        z = np.linalg.norm(pos[..., None, :] - ARRAY, axis=-1) / 1500.0 + 1e-6 * rng.standard_normal((steps, runs, 3))
    else:
        meas = RangeBearing(BEARING_SENSOR, 1e-3, 1e-4)
        d = pos - BEARING_SENSOR
        z = np.stack([np.hypot(d[..., 0], d[..., 1]), np.arctan2(d[..., 1], d[..., 0])], axis=-1)
        z = z + rng.standard_normal((steps, runs, 2)) * [1e-3, 1e-4]
    z[rng.random(z.shape) < 0.2] = np.nan
    x0 = np.zeros((runs, 4))
    x0[:, 0], x0[:, 2] = pos[0, :, 0], pos[0, :, 1]
    prior = pu.Gaussian(x0, np.diag([100.0, 1.0, 100.0, 1.0]))
    return ConstantVelocity(ndim=2, q=1e-4), meas, z, dts, prior, pos


def _run_and_check(filt, z, dts, prior):
    """Step through, checking every covariance (batched Cholesky every 500 steps)."""
    state = filt.init(prior, (z.shape[1],))
    chunk, repaired = [], 0
    for i in range(z.shape[0]):
        state, info = filt.step(state, z[i], dt=float(dts[i]))
        repaired += int(np.count_nonzero(info["repaired"]))
        chunk.append(np.asarray(state.cov))
        if len(chunk) == 500 or i == z.shape[0] - 1:
            C = np.stack(chunk)
            chunk = []
            assert np.all(np.isfinite(C)), f"non-finite covariance before step {i + 1}"
            assert np.array_equal(C, np.swapaxes(C, -1, -2))
            np.linalg.cholesky(C)  # raises LinAlgError if any covariance is not positive definite
        assert np.all(np.isfinite(state.mean)), f"non-finite estimate at step {i + 1}"
    assert repaired == 0, f"{repaired} covariances needed repair"
    return state


LONG = [
    pytest.param(pu.KalmanFilter, "position", id="kf-position"),
    pytest.param(pu.ExtendedKalmanFilter, "range", id="ekf-range"),
    pytest.param(pu.UnscentedKalmanFilter, "range", id="ukf-range"),
    pytest.param(pu.CubatureKalmanFilter, "toa", id="ckf-toa"),
]


@pytest.mark.slow
@pytest.mark.parametrize("cls,sensor", LONG)
def test_a_million_steps_without_nan_or_loss_of_positive_definiteness(cls, sensor):
    motion, meas, z, dts, prior = long_scenario(sensor)
    assert z.shape[0] * z.shape[1] == 10**6
    _run_and_check(cls(motion, meas), z, dts, prior)


FADING = {
    "ewfmkf": pu.ExponentiallyWeighted,
    "stf": pu.StrongTracking,
    "ifmkf": pu.Improved,
}


@pytest.mark.slow
@pytest.mark.parametrize("strategy", list(FADING))
@pytest.mark.parametrize("cls,sensor", LONG)
def test_fading_variants_run_long_without_nan_or_loss_of_positive_definiteness(cls, sensor, strategy):
    # 10^5 filter steps per variant (the existing 200 x 5000 would cost minutes
    # each for IFMKF); the default parameters of every strategy.
    motion, meas, z, dts, prior = long_scenario(sensor, runs=20, steps=STEPS)
    _run_and_check(cls(motion, meas, fading=FADING[strategy]()), z, dts, prior)


@pytest.mark.parametrize("cls", [pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter], ids=lambda c: c.__name__)
@pytest.mark.parametrize("sensor", ["range", "toa"])
def test_short_hard_runs_for_every_filter_and_sensor(cls, sensor):
    # The long test above covers one sensor per filter; this covers the rest, briefly.
    motion, meas, z, dts, prior = long_scenario(sensor, runs=20, steps=1000, seed=2, gap_rate=5e-3)
    _run_and_check(cls(motion, meas), z, dts, prior)


@pytest.mark.parametrize("strategy", list(FADING))
@pytest.mark.parametrize(
    "cls,sensor",
    [
        pytest.param(pu.ExtendedKalmanFilter, "toa", id="ekf-toa"),
        pytest.param(pu.UnscentedKalmanFilter, "toa", id="ukf-toa"),
        pytest.param(pu.CubatureKalmanFilter, "range", id="ckf-range"),
    ],
)
def test_short_hard_runs_for_the_fading_variants_on_the_other_sensors(cls, sensor, strategy):
    # The long fading test covers one sensor per filter; this covers the rest, briefly.
    motion, meas, z, dts, prior = long_scenario(sensor, runs=20, steps=1000, seed=2, gap_rate=5e-3)
    _run_and_check(cls(motion, meas, fading=FADING[strategy]()), z, dts, prior)


# --------------------------------------------------------------------------
# the maneuvering-target filters (CS family, Singer KF, IMM-Singer)
# --------------------------------------------------------------------------
_PERIODS = np.array([[700.0, 450.0, 300.0], [520.0, 330.0, 260.0], [610.0, 390.0, 280.0]])  # (axis, term) s


def _maneuver_path(t):
    """A bounded 3-D maneuvering path about 200 km on every axis: position ``(*t.shape, 3)``.

    Each axis is 200 km plus three sinusoids of 20, 10 and 5 km amplitude with periods of 4-12
    minutes, so the acceleration wanders smoothly up to about 7 m/s² and changes sign every
    couple of minutes: the target never stops maneuvering, never leaves a 70 km box and never
    matches any filter's model exactly.
    """
    amp = np.array([20e3, 10e3, 5e3])
    w = 2 * np.pi / _PERIODS  # (3, 3)
    return 200e3 + np.einsum("j,...ij->...i", amp, np.sin(t[..., None, None] * w))


def long_maneuver_scenario(
    runs: int = RUNS, steps: int = STEPS, seed: int = 1, dt: float = 1.0, outage_rate: float = 1e-3, outage: int = 100
):
    """Measurement model, measurements ``(K, M, 3)``, time steps ``(K,)`` and prior for the maneuvering filters.

    A long run of :func:`_maneuver_path` sampled every ``dt`` (P4's period: APCS's displacement law
    and strong-tracking memory, and MS's AR(1) estimator, are defined for a fixed period), measured
    in position on every axis with 1 mm noise at 200 km, 20 % of the components missing at random
    and, at a rate ``outage_rate`` per step, outages of ``outage`` steps with nothing measured (the
    filters extrapolate a maneuvering target for 100 s and must take precise fixes again after
    it).  The state is ``[x, vx, ax, y, vy, ay, z, vz, az]``.
    """
    rng = np.random.default_rng(seed)
    dts = np.full(steps, float(dt))
    t = np.cumsum(dts)
    offset = rng.uniform(0, 5000, runs)
    pos = _maneuver_path(t[:, None] + offset[None, :])  # (K, M, 3)
    sigma = 1e-3
    meas = LinearGaussian.position(9, (0, 3, 6), sigma)
    z = pos + sigma * rng.standard_normal(pos.shape)
    z[rng.random(z.shape) < 0.2] = np.nan
    for k in np.flatnonzero(rng.random(steps) < outage_rate):
        z[k : k + outage] = np.nan
    x0 = np.zeros((runs, 9))
    x0[:, 0::3] = _maneuver_path(offset)
    prior = pu.Gaussian(x0, np.diag(np.tile([100.0, 100.0, 10.0], 3)))
    return meas, z, dts, prior


def _singer_kf(meas, alpha, sigma):
    return pu.KalmanFilter(Singer(alpha=alpha, sigma=sigma, ndim=3), meas)


MANEUVER_FILTERS = {
    "cs": lambda meas: CurrentStatisticalFilter(meas),
    "apcs": lambda meas: AdaptiveCSFilter(meas),
    "ms": lambda meas: ModifiedSingerFilter(meas),
    "kf-singer": lambda meas: _singer_kf(meas, 0.05, 20.0),
    "imm-singer": lambda meas: InteractingMultipleModel(
        [_singer_kf(meas, a, s) for a, s in ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))], 0.95
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MANEUVER_FILTERS))
def test_a_million_steps_of_the_maneuvering_filters_without_nan_or_loss_of_positive_definiteness(name):
    meas, z, dts, prior = long_maneuver_scenario()
    assert z.shape[0] * z.shape[1] == 10**6
    assert np.all(np.isnan(z), axis=(1, 2)).sum() >= 100  # the outages are there
    _run_and_check(MANEUVER_FILTERS[name](meas), z, dts, prior)


def _one_step(cls, P_scale, sigma):
    """The textbook posterior covariance P⁻ − K S Kᵀ and the filter's, from the same predicted moments."""
    meas = RangeSensors(ANCHORS, sigma)
    filt = cls(ConstantVelocity(ndim=2, q=1e-4), meas)
    rng = np.random.default_rng(0)
    M = 2000
    x = np.array([50.0, 0.0, 50.0, 0.0]) + rng.standard_normal((M, 4)) * np.sqrt(np.array([P_scale, 1e-2, P_scale, 1e-2]))
    P = np.broadcast_to(np.diag([P_scale, 1e-2, P_scale, 1e-2]), (M, 4, 4)).copy()
    z = meas.h(x + rng.standard_normal((M, 4)) * np.sqrt(np.array([P_scale, 1e-2, P_scale, 1e-2])))
    m = filt._measure(x, P, 1)
    S = symmetrize(m.Pzz + meas.R)
    K = m.Pxz @ inv_spd(S)
    textbook = symmetrize(P - K @ S @ np.swapaxes(K, -1, -2))
    from pursuit.filters.gaussian import _update  # the filter's own update on the same moments

    _, cov, _ = _update(x, P, z, ~np.isnan(z), m, meas, 1)
    return textbook, cov


@pytest.mark.parametrize("cls", [pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter], ids=lambda c: c.__name__)
def test_sigma_point_joseph_form_equals_the_textbook_update(cls):
    # Well conditioned (2 m prior spread, 1 m ranges): the two forms agree to round-off.
    textbook, joseph = _one_step(cls, P_scale=4.0, sigma=1.0)
    scale = np.max(np.abs(textbook), axis=(-2, -1), keepdims=True)
    assert np.max(np.abs(joseph - textbook) / scale) < 1e-12


@pytest.mark.parametrize("cls", [pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter], ids=lambda c: c.__name__)
def test_sigma_point_joseph_form_stays_positive_definite_where_the_textbook_form_does_not(cls):
    # A 300 m prior spread against 1 mm ranges: P⁻ − K S Kᵀ cancels to below round-off.
    textbook, joseph = _one_step(cls, P_scale=1e5, sigma=1e-3)
    assert np.any(np.linalg.eigvalsh(textbook)[..., 0] <= 0)  # the hazard is real
    np.linalg.cholesky(joseph)  # and the filter's form is immune to it
