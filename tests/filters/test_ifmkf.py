"""IFMKF: the divergence test, the outlier gate and the λ search (paper P2, spec 03 §4.4)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit.filters.fading import FadingContext
from pursuit.models import LinearGaussian
from pursuit.rng import run_streams
from pursuit.scenarios import UnderwaterTOA

Q, R, PBAR = 1.0e-4, 4.0e-6, 2.0e-4  # τ = 3 (0.01 + 0.002) = 0.036 with β = 3
TAU = 3.0 * (np.sqrt(Q) + np.sqrt(R))


def _scalar_context(k: int, z: np.ndarray, pbar: float = PBAR) -> FadingContext:
    """A 1-D Kalman step with prediction 0: the innovation is z itself."""
    z = np.asarray(z, dtype=float)[..., None]
    batch = z.shape[:-1]

    def trial(lam):
        P = np.asarray(lam) * pbar + Q
        gain = P / (P + R)
        mean = np.where(np.isnan(z[..., 0]), 0.0, gain * z[..., 0])[..., None]
        return mean, ((1 - gain) * P)[..., None, None]

    return FadingContext(
        k=k,
        pred_mean=np.zeros((*batch, 1)),
        propagated_cov=np.full((1, 1), pbar),
        process_cov=np.array([[Q]]),
        z=z,
        measurement=LinearGaussian([[1.0]], [[R]]),
        trial_update=trial,
    )


def _drive(strategy, residuals):
    """Feed a sequence of innovations (one column per run); returns per-step λ, diverging, gated."""
    residuals = np.asarray(residuals, dtype=float)
    if residuals.ndim == 1:
        residuals = residuals[:, None]
    memory = strategy.init(residuals.shape[1:])
    out = {"lam": [], "diverging": [], "gated": []}
    for k, z in enumerate(residuals, start=1):
        fade, memory = strategy.factor(memory, _scalar_context(k, z))
        out["lam"].append(np.broadcast_to(fade.lam, z.shape))
        out["diverging"].append(fade.info["diverging"])
        out["gated"].append(fade.info["gated"])
        if fade.skip is not None:
            assert np.array_equal(fade.skip, fade.info["gated"])
    return {key: np.array(v) for key, v in out.items()}


QUIET = [0.01, -0.012, 0.008, 0.011, -0.009, 0.01, 0.012, -0.01, 0.009, 0.011]


def test_threshold_is_reserve_times_model_plus_observation_std():
    fade, _ = pu.Improved().factor(pu.Improved().init(()), _scalar_context(1, 0.5))
    assert fade.info["divergence_threshold"] == pytest.approx(TAU)
    assert fade.info["divergence_residual"] == pytest.approx(0.5)


def test_decaying_start_up_transient_is_normal():
    transient = [5.0, 2.0, 1.0, 0.6, 0.4, 0.25, 0.15, 0.1, 0.07, 0.05, 0.04] + QUIET
    out = _drive(pu.Improved(), transient)
    assert not out["diverging"].any()
    assert np.all(out["lam"] == 1.0)


def test_isolated_outlier_is_gated_and_not_faded():
    seq = QUIET + [1.0] + QUIET
    out = _drive(pu.Improved(), seq)
    gated = out["gated"][:, 0]
    assert gated[len(QUIET)] and gated.sum() == 1
    assert not out["diverging"].any()
    assert np.all(out["lam"] == 1.0)


def test_isolated_outlier_without_gate_is_still_not_divergence():
    out = _drive(pu.Improved(gate=False), QUIET + [1.0] + QUIET)
    assert not out["gated"].any()
    assert not out["diverging"].any()
    assert np.all(out["lam"] == 1.0)


def test_instantaneous_test_fades_on_the_outlier_the_window_test_ignores():
    out = _drive(pu.Improved(gate=False, test="instant"), QUIET + [1.0] + QUIET)
    assert out["diverging"][len(QUIET), 0]
    assert out["lam"][len(QUIET), 0] > 1.0


def test_persistent_jump_is_gated_at_most_gate_max_steps_then_faded():
    seq = QUIET + [1.0] * 8
    out = _drive(pu.Improved(gate_max=2), seq)
    n = len(QUIET)
    assert out["gated"][n : n + 2, 0].all()
    assert not out["gated"][n + 2 :, 0].any()
    assert out["diverging"][n + 2 :, 0].all()
    assert np.all(out["lam"][n + 2 :, 0] > 1.0)


def test_growing_residual_is_abnormal_divergence():
    growth = 0.05 * 1.5 ** np.arange(10)  # 0.05 ... 1.9: never a jump big enough to gate
    out = _drive(pu.Improved(), QUIET + list(growth))
    n = len(QUIET)
    assert not out["diverging"][: n + 2].any()  # median not yet above τ
    assert out["diverging"][n + 2 :, 0].all()
    assert not out["gated"].any()
    # fading starts once λ = 1 no longer brings the post-fit residual |z| R / (P̄ + Q + R) to 3 sqrt(R)
    needs_fading = growth * R / (PBAR + Q + R) > 3 * np.sqrt(R)
    assert needs_fading.sum() >= 4
    assert np.array_equal(out["lam"][n:, 0] > 1.0, needs_fading)


def test_hysteresis_keeps_diverging_while_the_median_is_high():
    seq = QUIET + [0.1, 0.2, 0.3, 0.3, 0.25, 0.2, 0.15, 0.12, 0.1, 0.08, 0.07, 0.06, 0.05] + QUIET
    with_h = _drive(pu.Improved(), seq)["diverging"][:, 0]
    without = _drive(pu.Improved(hysteresis=False), seq)["diverging"][:, 0]
    n = len(QUIET)
    falling = slice(n + 6, n + 13)  # slope of the window negative, median still above τ
    assert with_h[falling].all()
    assert not without[falling].all()
    assert not with_h[-3:].any()  # leaves once the median is back under τ


def test_never_diverging_during_the_first_window():
    out = _drive(pu.Improved(window=5), [1.0] * 12)
    assert not out["diverging"][:5].any()
    assert out["diverging"][5:].all()
    assert not out["gated"].any()  # no gate before a full window


def test_missing_measurement_leaves_the_state_unchanged():
    seq = QUIET + [np.nan] + [1.0] + QUIET
    out = _drive(pu.Improved(), seq)
    n = len(QUIET)
    assert not out["diverging"][n, 0] and not out["gated"][n, 0] and out["lam"][n, 0] == 1.0
    assert out["gated"][n + 1, 0]  # the window survived the gap


def test_consistent_search_finds_the_smallest_lambda_that_fits():
    # Scalar KF: post-fit residual |z| R / (λ P̄ + Q + R) falls with λ, so the
    # smallest λ reaching β v = 3 sqrt(R) is known in closed form.
    strategy = pu.Improved(gate=False)
    seq = np.array([QUIET + [0.2, 0.3, 0.4, 0.5, 0.6, 0.8]] * 3).T * np.array([1.0, -1.0, 2.0])
    out = _drive(strategy, seq)
    target = strategy.beta * np.sqrt(R)
    lam_exact = np.maximum((np.abs(seq) * R / target - Q - R) / PBAR, 1.0)
    active = out["diverging"]
    assert active[-3:].all()
    np.testing.assert_allclose(out["lam"][active], lam_exact[active], rtol=2e-5)


@pytest.mark.parametrize("unreachable", ["lam_max", "innovation"])
def test_unreachable_level_gives_lam_max(unreachable):
    # Scalar KF: λ_max = 10 leaves the post-fit residual above the level; the
    # innovation factor (25 − Q − R)/P̄ ≈ 1.2e5 is capped at λ_max too.
    strategy = pu.Improved(gate=False, lam_max=10.0, unreachable=unreachable)
    out = _drive(strategy, QUIET + [5.0] * 6)
    assert np.all(out["lam"][-3:] == 10.0)


def test_unreachable_level_gives_the_innovation_factor_by_default():
    # A trial update that never moves the estimate: no λ reaches the level, so
    # the default takes λ_ν = (ν² − Q − R)/P̄ from this step's innovation alone.
    def never_fits(k, z):
        ctx = _scalar_context(k, z)
        ctx._trial_update = lambda lam: (np.zeros((*np.shape(lam), 1)), None)
        return ctx

    seq = QUIET + [0.2, 0.3, 0.4, 0.5, 0.6, 0.8]
    strategy = pu.Improved(gate=False)
    memory, lams, diverging = strategy.init(()), [], []
    for k, z in enumerate(seq, start=1):
        fade, memory = strategy.factor(memory, never_fits(k, z))
        lams.append(float(fade.lam))
        diverging.append(bool(fade.info["diverging"]))
    lams, diverging, z = np.array(lams), np.array(diverging), np.array(seq)
    assert diverging[-3:].all()
    expected = np.clip((z**2 - Q - R) / PBAR, 1.0, strategy.lam_max)
    np.testing.assert_allclose(lams[diverging], expected[diverging], rtol=1e-12)
    assert np.all(lams[diverging] < strategy.lam_max)  # not the spec's λ_max
    assert np.all(lams[~diverging] == 1.0)


@pytest.mark.parametrize("search", ["minimise", "stf"])
def test_other_searches_fade_on_divergence_only(search):
    out = _drive(pu.Improved(search=search, gate=False), QUIET + [0.2, 0.3, 0.4, 0.5, 0.6, 0.8])
    n = len(QUIET)
    assert np.all(out["lam"][:n] == 1.0)
    assert np.all(out["lam"][-3:] > 1.0)


def test_batch_runs_are_independent():
    seqs = np.array([QUIET + [1.0] * 6, QUIET + list(np.linspace(0.05, 0.3, 6)), QUIET + [0.01] * 6]).T
    batch = _drive(pu.Improved(), seqs)
    for i in range(3):
        alone = _drive(pu.Improved(), seqs[:, i])
        for key in batch:
            assert np.array_equal(batch[key][:, i], alone[key][:, 0]), key


# --------------------------------------------------------------------------
# on paper P2's scenario
# --------------------------------------------------------------------------
def _ifmkf_track(condition, runs=100, seed=4, **kw):
    sc = UnderwaterTOA(condition=condition)
    sim = sc.simulate(run_streams(seed, range(runs), 0), runs)
    track = pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=pu.Improved(**kw)), sim.measurements, sim.prior)
    return sc, sim, track


def test_ifmkf_does_not_fade_in_the_ideal_condition():
    _, _, track = _ifmkf_track("ideal")
    assert not track.info["faded"].any()
    assert not track.info["gated"].any()


def test_outlier_alone_does_not_make_ifmkf_fade():
    sc, _, track = _ifmkf_track("abnormal")
    k = sc.outlier_step - 1
    assert track.info["gated"][k].all()  # every run rejects the outlier ...
    assert track.info["gated"].sum() == track.info["gated"][k].sum()  # ... and nothing else
    assert not track.info["faded"].any()  # and no run fades, before, at or after it


def test_post_fit_residual_meets_the_level_where_ifmkf_fades():
    """Audit the λ search on the 'actual' condition from outside the strategy."""
    inner = pu.Improved()
    checks = {"faded": 0, "unreachable": 0}

    class Audit:
        data_independent = False

        def init(self, batch):
            return inner.init(batch)

        def factor(self, memory, ctx):
            fade, memory = inner.factor(memory, ctx)
            lam = np.broadcast_to(fade.lam, ctx.z.shape[:-1])
            faded = lam > 1.0
            if faded.any():
                level = inner.beta * np.sqrt(np.max(np.diagonal(ctx.measurement_cov)))
                post = lambda lam_: np.abs(ctx.z - ctx.measurement.h(ctx.trial_update(lam_)[0], ctx.k)).max(axis=-1)  # noqa: E731
                reachable = post(np.full(lam.shape, inner.lam_max)) <= level
                reached = faded & reachable
                assert np.all(post(lam)[reached] <= level * (1 + 1e-9))
                # a slightly smaller λ no longer fits: λ is (close to) the smallest
                assert np.all(post(np.where(reached, lam * (1 - 1e-3), 1.0))[reached & (lam > 1.01)] > level)
                # out of reach: the one-step innovation-matching factor, from full matrices
                H, nu = ctx.jacobian, ctx.innovation
                HPH = H @ ctx.propagated_cov @ np.swapaxes(H, -1, -2)
                N = nu[..., :, None] * nu[..., None, :] - H @ ctx.process_cov @ np.swapaxes(H, -1, -2) - ctx.measurement_cov
                lam_nu = np.clip(np.trace(N, axis1=-2, axis2=-1) / np.trace(HPH, axis1=-2, axis2=-1), 1.0, inner.lam_max)
                out = faded & ~reachable
                np.testing.assert_allclose(lam[out], lam_nu[out], rtol=1e-9)
                checks["faded"] += int(faded.sum())
                checks["unreachable"] += int(out.sum())
            return fade, memory

    sc = UnderwaterTOA(condition="actual", steps=40)
    sim = sc.simulate(run_streams(5, range(20), 0), 20)
    pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=Audit()), sim.measurements, sim.prior)
    assert checks["faded"] > 50
    assert checks["unreachable"] > 0  # both branches are exercised


def test_unreachable_minimise_keeps_sigma_point_filters_stable():
    sc = UnderwaterTOA(condition="actual", steps=20)
    sim = sc.simulate(run_streams(6, range(6), 0), 6)
    for cls in (pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter):
        plain = pu.run(cls(sc.motion, sc.measurement), sim.measurements, sim.prior)
        strategy = pu.Improved(unreachable="minimise", grid=40)
        track = pu.run(cls(sc.motion, sc.measurement, fading=strategy), sim.measurements, sim.prior)
        rmse = lambda t: np.sqrt(np.mean(np.sum((t.mean[..., :2] - sim.truth[..., :2]) ** 2, axis=-1)))  # noqa: E731
        assert track.info["faded"].any()
        assert np.isfinite(rmse(track)) and rmse(track) < rmse(plain)


FULL_LENGTH = [
    pytest.param("kf", "position", "actual", id="kf-position-actual"),
    pytest.param("ekf", "ranges", "actual", id="ekf-actual"),
    pytest.param("ukf", "ranges", "actual", id="ukf-actual"),
    pytest.param("ckf", "ranges", "actual", id="ckf-actual"),
    pytest.param("ekf", "ranges", "abnormal", id="ekf-abnormal"),
    pytest.param("ukf", "ranges", "abnormal", id="ukf-abnormal"),
    pytest.param("ckf", "ranges", "abnormal", id="ckf-abnormal"),
]
GAUSSIAN = {"kf": pu.KalmanFilter, "ekf": pu.ExtendedKalmanFilter, "ukf": pu.UnscentedKalmanFilter, "ckf": pu.CubatureKalmanFilter}


@pytest.mark.parametrize("kind,mode,condition", FULL_LENGTH)
def test_default_ifmkf_is_stable_and_not_worse_than_the_plain_filter_over_the_full_horizon(kind, mode, condition):
    # With spec 03's unreachable = "lam_max" the UKF and CKF blew up here
    # (position RMSE ~1e79 m, a third of the runs, between steps 9 and 45).
    sc = UnderwaterTOA(condition=condition, mode=mode)  # the full 60 steps
    runs = 40
    sim = sc.simulate(run_streams(7, range(runs), 0), runs)
    cls = GAUSSIAN[kind]
    plain = pu.run(cls(sc.motion, sc.measurement), sim.measurements, sim.prior)
    track = pu.run(cls(sc.motion, sc.measurement, fading=pu.Improved()), sim.measurements, sim.prior)
    assert sc.steps == 60 and track.mean.shape[0] == 60
    assert np.all(np.isfinite(track.mean)) and np.all(np.isfinite(track.cov))
    if condition == "actual":
        assert track.info["faded"].any()  # the comparison covers real fading

    def per_run_rmse(t):
        return np.sqrt(np.mean(np.sum((t.mean[..., :2] - sim.truth[..., :2]) ** 2, axis=-1), axis=0))

    # Paired over runs (same truth and measurements): the one-sided 99.9 %
    # upper confidence bound of the mean RMSE difference must be below zero.
    d = per_run_rmse(track) - per_run_rmse(plain)
    upper = d.mean() + stats.t.ppf(0.999, runs - 1) * d.std(ddof=1) / np.sqrt(runs)
    assert upper < 0.0, (d.mean(), upper)


def test_gated_step_info_describes_the_rejected_measurement():
    # The contract of the Gaussian filters' step info (filters/gaussian.py): on a
    # gated step the estimate is the prediction, while innovation, S, NIS, dof
    # and loglik describe the measurement that was rejected, as for `gate=p`.
    sc = UnderwaterTOA(condition="abnormal")
    runs = 20
    sim = sc.simulate(run_streams(4, range(runs), 0), runs)
    filt = pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=pu.Improved())
    track = pu.run(filt, sim.measurements, sim.prior, store_predictions=True)
    k = sc.outlier_step - 1
    gated = track.info["gated"][k]
    assert gated.all()
    info = {key: track.info[key][k] for key in ("innovation", "S", "nis", "dof", "loglik", "pred_mean", "pred_cov")}
    z, meas = sim.measurements[k], sc.measurement
    nu = z - meas.h(info["pred_mean"], k + 1)
    H = meas.jacobian(info["pred_mean"], k + 1)
    S = H @ info["pred_cov"] @ np.swapaxes(H, -1, -2) + meas.cov(k + 1)
    nis = np.einsum("...i,...ij,...j->...", nu, np.linalg.inv(S), nu)
    np.testing.assert_allclose(info["innovation"], nu, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(info["S"], S, rtol=1e-10)
    np.testing.assert_allclose(info["nis"], nis, rtol=1e-8)
    assert np.all(info["dof"] == 3)
    _, logdet = np.linalg.slogdet(S)
    np.testing.assert_allclose(info["loglik"], -0.5 * (nis + logdet + 3 * np.log(2 * np.pi)), rtol=1e-8)
    assert np.all(info["nis"] > 1e3)  # the +1 m outlier, now visible to NIS/ANIS
    # ... and the estimate is the prediction (covariance symmetrised), with λ = 1
    np.testing.assert_array_equal(track.mean[k], info["pred_mean"])
    P = info["pred_cov"]
    np.testing.assert_array_equal(track.cov[k], 0.5 * (P + np.swapaxes(P, -1, -2)))
    assert np.array_equal(track.cov[k], np.swapaxes(track.cov[k], -1, -2))
    assert np.all(track.info["fading"][k] == 1.0)


def test_gated_step_info_equals_the_chi_square_gate_on_the_same_step():
    # Both gates keep the prediction and report the rejected measurement: from
    # the same state, on the outlier step, an EKF with a χ² gate reports the
    # same numbers as IFMKF.
    sc = UnderwaterTOA(condition="abnormal", steps=16)
    sim = sc.simulate(run_streams(4, range(10), 0), 10)
    ifm = pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=pu.Improved())
    chi = pu.ExtendedKalmanFilter(sc.motion, sc.measurement, gate=0.999)
    state = ifm.init(sim.prior, batch=(10,))
    k = sc.outlier_step
    for i in range(k - 1):
        state, _ = ifm.step(state, sim.measurements[i])
    after_ifm, info_ifm = ifm.step(state, sim.measurements[k - 1])
    after_chi, info_chi = chi.step(pu.filters.GaussianState(state.mean, state.cov, state.k), sim.measurements[k - 1])
    assert info_ifm["gated"].all() and info_chi["gated"].all()
    for key in ("innovation", "S", "nis", "dof", "loglik"):
        np.testing.assert_array_equal(info_ifm[key], info_chi[key], err_msg=key)
    np.testing.assert_array_equal(after_ifm.mean, after_chi.mean)
    np.testing.assert_array_equal(after_ifm.cov, after_chi.cov)
