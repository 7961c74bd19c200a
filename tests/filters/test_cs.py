"""CS, APCS and MS filters: hand re-implementation, reductions to the Kalman filter, detector statistics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.special import gammaln

import pursuit as pu
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, ModifiedSingerFilter
from pursuit.filters.cs import chi2_threshold
from pursuit.models import LinearGaussian, Singer
from pursuit.models.maneuver import cs_variance, exp_correlated_input, exp_correlated_noise, exp_correlated_transition
from pursuit.rng import run_streams
from pursuit.scenarios import ManeuveringTarget

SCENARIO = ManeuveringTarget()
QUIET = ManeuveringTarget(maneuvers=[], init="sampled")


def _sim(scenario, runs, seed=5):
    return scenario.simulate(run_streams(seed, range(runs), 0), runs)


def _run(filt, sim, **kw):
    return pu.run(filt, sim.measurements, sim.prior, **kw)


# --------------------------------------------------------------------------
# standard CS
# --------------------------------------------------------------------------
def test_cs_filter_matches_a_plain_reimplementation_of_the_recursion():
    sim = _sim(SCENARIO, 3)
    alpha, a_max, T, r = 0.02, 80.0, 1.0, 20.0
    track = _run(CurrentStatisticalFilter(SCENARIO.measurement, alpha=alpha, a_max=a_max), sim)
    F = exp_correlated_transition(3, alpha, T)
    U = exp_correlated_input(3, alpha, T)
    q = exp_correlated_noise(3, alpha, T)
    H = np.array([1.0, 0.0, 0.0])
    for run in range(3):
        for axis in range(3):
            sl = slice(3 * axis, 3 * axis + 3)
            x = sim.prior.mean[run, sl].copy()
            P = sim.prior.cov[sl, sl].copy()
            for k in range(SCENARIO.steps):
                a_bar = x[2]
                s2 = cs_variance(a_bar, a_max)
                x = F @ x + U * a_bar
                P = F @ P @ F.T + 2 * alpha * s2 * q
                S = H @ P @ H + r
                K = P @ H / S
                x = x + K * (sim.measurements[k, run, axis] - H @ x)
                A = np.eye(3) - np.outer(K, H)
                P = A @ P @ A.T + r * np.outer(K, K)
            np.testing.assert_allclose(track.mean[-1, run, sl], x, rtol=1e-10)
            np.testing.assert_allclose(track.cov[-1, run, sl, sl], P, rtol=1e-8)


def test_axes_are_filtered_independently_and_the_info_combines_them():
    sim = _sim(SCENARIO, 4)
    three = _run(CurrentStatisticalFilter(SCENARIO.measurement), sim)
    total_nis = np.zeros(three.info["nis"].shape)
    for axis in range(3):
        sl = slice(3 * axis, 3 * axis + 3)
        meas = LinearGaussian([[1.0, 0.0, 0.0]], [[SCENARIO.R]])
        prior = pu.Gaussian(sim.prior.mean[:, sl], sim.prior.cov[sl, sl])
        one = pu.run(CurrentStatisticalFilter(meas), sim.measurements[..., axis : axis + 1], prior)
        np.testing.assert_allclose(three.mean[..., sl], one.mean, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(three.info["S"][..., axis, axis], one.info["S"][..., 0, 0], rtol=1e-11)
        total_nis += one.info["nis"]
    np.testing.assert_allclose(three.info["nis"], total_nis, rtol=1e-8)  # ν = z − ẑ cancels ~2e5 m
    off = three.cov.copy()
    for axis in range(3):
        off[..., 3 * axis : 3 * axis + 3, 3 * axis : 3 * axis + 3] = 0.0
    assert not off.any()


@pytest.mark.parametrize(
    "H,R,match",
    [
        ([[1.0, 0.0, 0.0, 0.0]], [[1.0]], "per measured axis"),
        ([[0.5, 0.0, 0.0]], [[1.0]], "coefficient 1"),
        ([[1.0, 0, 0, 0, 0, 0], [0, 0, 0, 1.0, 0, 0]], [[1.0, 0.2], [0.2, 1.0]], "diagonal"),
    ],
)
def test_measurements_the_cs_filters_cannot_use_are_refused(H, R, match):
    with pytest.raises(ValueError, match=match):
        CurrentStatisticalFilter(LinearGaussian(H, R))


def test_nonlinear_measurements_are_refused():
    with pytest.raises(TypeError, match="linear position measurement"):
        AdaptiveCSFilter(pu.scenarios.WSNRange().measurement)


@pytest.mark.parametrize(
    "cls,kwargs,field",
    [
        (CurrentStatisticalFilter, {"alpha": 0.0}, "alpha"),
        (CurrentStatisticalFilter, {"mean": "median"}, "mean"),
        (AdaptiveCSFilter, {"variance": "cubic"}, "variance"),
        (AdaptiveCSFilter, {"fading": "always"}, "fading"),
        (AdaptiveCSFilter, {"alpha_cap": 1e-4}, "alpha_cap"),
        (AdaptiveCSFilter, {"false_alarm": 1.5}, "false_alarm"),
        (AdaptiveCSFilter, {"beta_s": 0.5}, "beta_s"),
        (AdaptiveCSFilter, {"sigma_min": 2.0, "sigma_max": 1.0}, "sigma_max"),
        (ModifiedSingerFilter, {"warmup": -1}, "warmup"),
        (ModifiedSingerFilter, {"forgetting": 1.0}, "forgetting"),
    ],
)
def test_bad_parameters_name_the_field(cls, kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        cls(SCENARIO.measurement, **kwargs)


# --------------------------------------------------------------------------
# APCS
# --------------------------------------------------------------------------
def _detector_only(**kw):
    """APCS whose detections change nothing, on a nominal Singer model: a Kalman filter plus the χ² test."""
    base = dict(variance="fixed", sigma_min=0.0, mean="zero", fading="none", alpha_rule="none")
    base.update(kw)
    return AdaptiveCSFilter(SCENARIO.measurement, **base)


def test_apcs_without_adaptation_is_the_singer_kalman_filter():
    sim = _sim(SCENARIO, 6)
    apcs = _run(_detector_only(alpha0=0.05, sigma_a=7.0), sim)
    kf = _run(pu.KalmanFilter(Singer(alpha=0.05, sigma=7.0, ndim=3), SCENARIO.measurement), sim)
    np.testing.assert_allclose(apcs.mean, kf.mean, rtol=1e-11, atol=1e-9)
    np.testing.assert_allclose(apcs.cov, kf.cov, rtol=1e-9, atol=1e-10)
    for key in ("nis", "loglik"):
        np.testing.assert_allclose(apcs.info[key], kf.info[key], rtol=1e-9)
    # with nothing adapted, D is the per-axis NIS of the filter itself
    per_axis = apcs.info["innovation"] ** 2 / np.diagonal(apcs.info["S"], axis1=-2, axis2=-1)
    np.testing.assert_allclose(apcs.info["maneuver_stat"], per_axis, rtol=1e-12)


@pytest.mark.parametrize("config", [{"false_alarm": 0.1}, {"threshold": 3.0}], ids=["p=0.1", "M=3"])
def test_detector_fires_at_its_chi_square_false_alarm_rate_on_a_non_maneuvering_target(config):
    # A constant-velocity target (no maneuver, no process noise) and a filter whose nominal model is
    # exactly matched to it (σ_a = 0, prior drawn from the filter's own prior): D ~ χ²(1) independently
    # at every step, axis and run, so the number of detections is Binomial(n, p).
    runs = 200
    sim = _sim(QUIET, runs, seed=17)
    filt = _detector_only(alpha0=0.001, sigma_a=0.0, **config)
    p = config.get("false_alarm") or stats.chi2.sf(config["threshold"], 1)
    if "false_alarm" in config:
        assert filt.threshold == pytest.approx(2.705543, abs=1e-6)
    det = _run(filt, sim).info["maneuver"]
    n = det.size
    lo, hi = stats.binom.ppf([0.0005, 0.9995], n, p)
    assert lo <= det.sum() <= hi


def test_default_apcs_adapts_within_its_limits():
    sim = _sim(SCENARIO, 20)
    filt = AdaptiveCSFilter(SCENARIO.measurement, sigma_max=40.0)
    track = _run(filt, sim, store_predictions=True)
    info = track.info
    assert np.all(info["axis_fading"] >= 1.0)
    assert np.all((info["alpha"] >= filt.alpha0) & (info["alpha"] <= filt.alpha_cap))
    assert np.all((info["sigma_a2"] >= filt.sigma_min**2 - 1e-15) & (info["sigma_a2"] <= 40.0**2 + 1e-9))
    # no detection: λ = 1 and α = α0 exactly
    quiet = ~info["maneuver"]
    assert np.all(info["axis_fading"][quiet] == 1.0) and np.all(info["alpha"][quiet] == filt.alpha0)
    # σ_a² of step k+1 is the displacement law applied to the correction of step k
    dx = track.mean[:-1][..., [0, 3, 6]] - info["pred_mean"][:-1][..., [0, 3, 6]]
    law = np.clip((4 - np.pi) / np.pi * (2 * dx) ** 2, filt.sigma_min**2, 40.0**2)
    np.testing.assert_allclose(info["sigma_a2"][1:], law, rtol=1e-12)


def test_apcs_detects_the_onset_of_strong_maneuvers():
    runs = 100
    sim = _sim(SCENARIO, runs)
    filt = AdaptiveCSFilter(SCENARIO.measurement)
    det = _run(filt, sim).info["maneuver"][..., 1]  # y axis
    p = stats.chi2.sf(filt.threshold, 1)
    for onset in (21, 51, 67):
        k = int(np.searchsorted(SCENARIO.times, onset))
        hits = det[k : k + 2].sum()
        # far above what false alarms at the configured rate could give
        assert hits > stats.binom.ppf(1 - 1e-9, 2 * runs, 3 * p)


def _apcs_reference(sim, run, axis, *, alpha0, a_max, M, rho, beta_s, alpha_cap, sigma_min, sigma_max, T=1.0, r=20.0):
    """Spec 04 §2.5 for one axis, written out with scalars: per-step mean, cov, λ, α, σ_a², D."""
    H = np.array([1.0, 0.0, 0.0])
    c = (4 - np.pi) / np.pi
    clip = lambda v: min(max(v, sigma_min**2), np.inf if sigma_max is None else sigma_max**2)  # noqa: E731
    sl = slice(3 * axis, 3 * axis + 3)
    x = sim.prior.mean[run, sl].copy()
    P = sim.prior.cov[sl, sl].copy()
    s2 = clip(cs_variance(x[2], a_max))  # start-up: eq. (14) at â(0|0)
    V = None
    F0, q0 = exp_correlated_transition(3, alpha0, T), exp_correlated_noise(3, alpha0, T)
    out = {key: [] for key in ("mean", "cov", "lam", "alpha", "sigma2", "D", "nu", "S0", "V", "FPF0")}
    for k in range(sim.measurements.shape[0]):
        z = sim.measurements[k, run, axis]
        # ① ā = â(k|k): the prediction is the constant-acceleration extrapolation for every α
        x_pred = np.array([x[0] + x[1] * T + x[2] * T * T / 2, x[1] + x[2] * T, x[2]])
        # ② nominal prediction (α0, λ = 1) and the detection statistic
        FPF0 = F0 @ P @ F0.T
        Q0 = 2 * alpha0 * s2 * q0
        nu = z - x_pred[0]
        D = nu * nu / ((FPF0 + Q0)[0, 0] + r)
        V = nu * nu if V is None else (rho * V + nu * nu) / (1 + rho)  # STF memory, every step
        # ③ decide: strong-tracking λ and raised α only when D > M
        if D > M:
            lam = max(1.0, (V - Q0[0, 0] - beta_s * r) / FPF0[0, 0])
            alpha = min(alpha0 * D / M, alpha_cap)
        else:
            lam, alpha = 1.0, alpha0
        F = exp_correlated_transition(3, alpha, T)
        P_pred = lam * F @ P @ F.T + 2 * alpha * s2 * exp_correlated_noise(3, alpha, T)
        S = H @ P_pred @ H + r
        K = P_pred @ H / S
        x = x_pred + K * nu
        A = np.eye(3) - np.outer(K, H)
        P = A @ P_pred @ A.T + r * np.outer(K, K)
        for key, v in zip(out, (x, P, lam, alpha, s2, D, nu, (FPF0 + Q0)[0, 0] + r, V, FPF0[0, 0])):
            out[key].append(v)
        # ④ σ_a² for the next step from the displacement correction
        s2 = clip(c * (2 * (x[0] - x_pred[0]) / T**2) ** 2)
    return {key: np.array(v) for key, v in out.items()}


def _assert_within(actual, desired, bound):
    err = np.abs(actual - desired)
    assert np.all(err <= bound), f"largest error {np.max(err):.3g} at {np.argmax(err - bound)}, bound there {bound.flat[np.argmax(err - bound)]:.3g}"


@pytest.mark.parametrize(
    "config",
    [
        dict(),  # paper P4's filter: α0 = 0.001, M = 3, ρ = 0.95, β_s = 1, α_cap = 1, σ_min = 0.1
        # a low threshold and a large β_s reach λ's floor of 1 on a detection; α's cap and σ_max bind
        dict(alpha0=0.05, threshold=1.5, rho=0.9, beta_s=2.0, alpha_cap=0.2, sigma_min=0.5, sigma_max=25.0),
    ],
    ids=["p4", "floor-cap-clip"],
)
def test_apcs_matches_a_plain_reimplementation_of_the_detection_branch(config):
    sim = _sim(SCENARIO, 3, seed=11)
    filt = AdaptiveCSFilter(SCENARIO.measurement, **config)
    track = _run(filt, sim)
    info = track.info
    params = dict(
        alpha0=filt.alpha0, a_max=filt.a_max, M=filt.threshold, rho=filt.rho, beta_s=filt.beta_s,
        alpha_cap=filt.alpha_cap, sigma_min=filt.sigma_min, sigma_max=filt.sigma_max,
    )
    # The two compute the same formulas in different orders.  The one ill-conditioned operation is
    # ν = z − x⁻, which cancels positions of 2e5 m: every quantity inherits an absolute error of a few
    # ulps of 2e5 m in ν (dnu below, 2.9e-10 m), propagated to first order; the rest is relative
    # round-off (rel).
    dnu, rel, c = 10 * np.spacing(2e5), 1e-9, (4 - np.pi) / np.pi
    branches = dict(faded=0, clipped=0, capped=0)
    for run in range(3):
        for axis in range(3):
            sl = slice(3 * axis, 3 * axis + 3)
            ref = _apcs_reference(sim, run, axis, **params)
            D, lam, s2 = (info[key][:, run, axis] for key in ("maneuver_stat", "axis_fading", "sigma_a2"))
            dD = 2 * np.abs(ref["nu"]) * dnu / ref["S0"]  # D = ν²/S0
            _assert_within(D, ref["D"], rel * ref["D"] + dD)
            np.testing.assert_array_equal(info["maneuver"][:, run, axis], ref["D"] > filt.threshold)
            # λ = (V − Q0 − β_s r)/(F P Fᵀ)_pp, V a weighted mean of ν² (weights summing to 1): dV ≤ 2√V dν
            _assert_within(lam, ref["lam"], rel * ref["lam"] + 2 * np.sqrt(ref["V"]) * dnu / ref["FPF0"])
            _assert_within(info["alpha"][:, run, axis], ref["alpha"], rel * ref["alpha"] + filt.alpha0 / filt.threshold * dD)
            # σ_a² = c (2Δx/T²)², Δx = K ν, K_p ≤ 1: dσ_a² ≤ 2 √(c σ_a²) (2/T²) dν
            _assert_within(s2, ref["sigma2"], rel * ref["sigma2"] + 2 * np.sqrt(c * ref["sigma2"]) * 2 / SCENARIO.dt**2 * dnu)
            np.testing.assert_allclose(track.mean[:, run, sl], ref["mean"], rtol=1e-10, atol=dnu)
            np.testing.assert_allclose(track.cov[:, run, sl, sl], ref["cov"], rtol=1e-8)
            detect = ref["D"] > filt.threshold
            branches["faded"] += int(np.sum(detect & (ref["lam"] > 1)))
            branches["clipped"] += int(np.sum(detect & (ref["lam"] == 1)))
            branches["capped"] += int(np.sum(ref["alpha"] == filt.alpha_cap))
    # The detection branch is exercised.  With P4's values λ's floor is out of reach: D > M gives
    # V ≥ ν²/(1 + ρ) > M/(1 + ρ) (F P Fᵀ + Q0 + r)_pp, so with M ≥ 1 + ρ and β_s = 1, N > (F P Fᵀ)_pp.
    assert branches["faded"] > 0, branches
    if config:
        assert branches["clipped"] > 0 and branches["capped"] > 0, branches
        assert np.any(info["sigma_a2"] == filt.sigma_max**2) and np.any(info["sigma_a2"] == filt.sigma_min**2)


def test_a_missing_axis_keeps_its_adaptive_memory():
    sim = _sim(SCENARIO, 3)
    zs = sim.measurements.copy()
    zs[40, :, 1] = np.nan
    track = pu.run(AdaptiveCSFilter(SCENARIO.measurement), zs, sim.prior)
    assert np.all(track.info["sigma_a2"][41, :, 1] == track.info["sigma_a2"][40, :, 1])
    assert not track.info["maneuver"][40, :, 1].any()
    assert np.all(np.isnan(track.info["maneuver_stat"][40, :, 1]))


def test_apcs_beats_cs_on_the_maneuvering_axis():
    # Ordering measured with confidence: per-run time-averaged y RMSE, paired over runs.
    runs = 100
    sim = _sim(SCENARIO, runs, seed=2024)
    rms = {}
    for filt in (CurrentStatisticalFilter(SCENARIO.measurement), AdaptiveCSFilter(SCENARIO.measurement)):
        e = _run(filt, sim).mean - sim.truth
        rms[filt.name] = np.sqrt(np.mean(e[..., 3:5] ** 2, axis=0))  # (runs, 2): y position, y velocity
    d = rms["CS"] - rms["APCS"]
    z = d.mean(axis=0) / (d.std(axis=0, ddof=1) / np.sqrt(runs))
    assert np.all(z > 5), z


def test_apcs_and_cs_agree_before_the_first_maneuver_within_the_band_of_filters_that_track_well():
    # Spec 04 §3: "on maneuver-free segments the two are within a tolerance".  Before the first
    # maneuver (t < 21 s) the truth is a straight line on every axis.  A filter tracks well there when
    # its position error is below the raw measurements' (σ_z: no filtering at all), and no unbiased
    # filter can beat the best linear unbiased estimator, least squares through every measurement so
    # far (Gauss-Markov): with n measurements its error variance at the last one is
    # σ_z² (4n − 2)/(n(n + 1)).  Two filters that track well differ by less than the width of that
    # band, which is the tolerance.  Per-run RMSE over the segment's steps and axes, paired over runs.
    runs = 100
    sim = _sim(SCENARIO, runs, seed=4321)
    before = SCENARIO.times < min(m.start for m in SCENARIO.maneuvers)
    assert not SCENARIO.maneuvering()[before].any()
    sigma = np.sqrt(SCENARIO.R)
    n = SCENARIO.times[before] / SCENARIO.dt  # measurements so far (t = T, 2T, ..., t_k)
    blue = sigma * np.sqrt(np.mean((4 * n - 2) / (n * (n + 1))))  # pooled RMSE of the BLUE
    cells = before.sum() * 3
    raw = sigma * np.sqrt(2 / cells) * np.exp(gammaln((cells + 1) / 2) - gammaln(cells / 2))  # E per-run RMSE of z
    tolerance = raw - blue  # 4.45 − 2.72 = 1.73 m
    rms = {}
    for filt in (CurrentStatisticalFilter(SCENARIO.measurement), AdaptiveCSFilter(SCENARIO.measurement)):
        e = (_run(filt, sim).mean - sim.truth)[before][..., [0, 3, 6]]
        rms[filt.name] = np.sqrt(np.mean(e**2, axis=(0, 2)))  # (runs,)
    se = lambda v: v.std(ddof=1) / np.sqrt(runs)  # noqa: E731
    for name, r in rms.items():  # both track well: better than the raw measurements
        assert r.mean() + 3 * se(r) < raw, (name, r.mean(), raw)
    d = rms["CS"] - rms["APCS"]
    assert abs(d.mean()) + 3 * se(d) < tolerance, (d.mean(), se(d), tolerance)


def test_chi2_threshold():
    assert chi2_threshold(0.1) == pytest.approx(2.705543454, rel=1e-9)
    assert chi2_threshold(0.05, 2) == pytest.approx(5.991464547, rel=1e-9)


# --------------------------------------------------------------------------
# MS
# --------------------------------------------------------------------------
def test_ms_before_its_warmup_ends_is_the_singer_kalman_filter():
    sim = _sim(SCENARIO, 4)
    ms = _run(ModifiedSingerFilter(SCENARIO.measurement, alpha_init=0.04, sigma_init=12.0, warmup=1000), sim)
    kf = _run(pu.KalmanFilter(Singer(alpha=0.04, sigma=12.0, ndim=3), SCENARIO.measurement), sim)
    np.testing.assert_allclose(ms.mean, kf.mean, rtol=1e-11, atol=1e-9)
    np.testing.assert_allclose(ms.cov, kf.cov, rtol=1e-9, atol=1e-10)


def _feed_ms(filt, accels):
    """Run MS's estimator on given acceleration sequences ``(N, batch)``."""
    batch = accels.shape[1]
    x0 = np.zeros((batch, 1, 3))
    memory = filt._init_memory(x0, None)
    measured = np.ones((batch, 1), dtype=bool)
    for a in accels:
        x = np.zeros((batch, 1, 3))
        x[..., 0, 2] = a
        memory = filt._learn(memory, None, None, x, measured, 1.0)
    return filt._estimates(memory, 1.0), memory


def test_ms_estimator_recovers_the_ar1_parameters(rng):
    alpha, sigma, N, B = 0.1, 5.0, 4000, 40
    beta = np.exp(-alpha)
    a = np.empty((N, B))
    a[0] = sigma * rng.standard_normal(B)
    for i in range(1, N):
        a[i] = beta * a[i - 1] + sigma * np.sqrt(1 - beta**2) * rng.standard_normal(B)
    filt = ModifiedSingerFilter(LinearGaussian([[1.0, 0.0, 0.0]], [[1.0]]), warmup=0, tau_min=0.5)
    (alpha_hat, s2_hat), memory = _feed_ms(filt, a)
    beta_hat = memory["r1"] / memory["r0"]
    # large-sample standard errors of an AR(1) lag-1 autocorrelation and of a variance estimate
    se_beta = np.sqrt((1 - beta**2) / (N * B))
    se_var = sigma**2 * np.sqrt(2 * (1 + beta**2) / (1 - beta**2) / (N * B))
    assert abs(beta_hat.mean() - beta) < 5 * se_beta
    assert abs(s2_hat.mean() - sigma**2) < 5 * se_var
    np.testing.assert_allclose(alpha_hat, -np.log(beta_hat), rtol=1e-12)


def test_ms_clips_beta_to_the_shortest_time_constant(rng):
    filt = ModifiedSingerFilter(LinearGaussian([[1.0, 0.0, 0.0]], [[1.0]]), warmup=0, tau_min=2.0)
    (alpha_hat, _), _ = _feed_ms(filt, rng.standard_normal((500, 3)) * np.array([1, -1] * 250)[:, None])
    np.testing.assert_allclose(alpha_hat, 0.5, rtol=1e-12)


def test_apcs_gains_more_on_the_stronger_maneuver():
    # P4: the stronger the maneuver, the larger the gap.  +60 m/s² (67-80 s) against +40 m/s² (21-35 s) on y,
    # per-run relative reduction of the position RMSE, paired over runs.
    runs = 100
    sim = _sim(SCENARIO, runs, seed=77)
    t = SCENARIO.times
    err = {}
    for filt in (CurrentStatisticalFilter(SCENARIO.measurement), AdaptiveCSFilter(SCENARIO.measurement)):
        err[filt.name] = (_run(filt, sim).mean - sim.truth)[..., 3]
    gain = []
    for start, stop in ((21, 35), (67, 80)):
        steps = (t >= start) & (t <= stop)
        cs, apcs = (np.sqrt(np.mean(err[n][steps] ** 2, axis=0)) for n in ("CS", "APCS"))
        gain.append(1.0 - apcs / cs)
    d = gain[1] - gain[0]
    assert d.mean() / (d.std(ddof=1) / np.sqrt(runs)) > 5
