"""Chi-square gating of outliers in the Gaussian filters."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit.experiment import ConfigError, load_experiment
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, InteractingMultipleModel, ModifiedSingerFilter
from pursuit.models import ConstantVelocity, Singer
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, ManeuveringTarget, WSNRange

CLASSES = [pu.KalmanFilter, pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter]


def _data(runs=200, steps=40, seed=5, outlier_rate=0.05, size=30.0):
    sc = LinearCV(ndim=2, steps=steps, q=0.05, sigma=1.0)
    sim = sc.simulate(run_streams(seed, range(runs), 0), runs)
    rng = np.random.default_rng(seed)
    outlier = rng.random((steps, runs)) < outlier_rate
    outlier[0] = False  # keep the start clean so the prior is not in question
    zs = sim.measurements.copy()
    zs[..., 0] += np.where(outlier, size * sc.sigma, 0.0)
    return sc, sim, zs, outlier


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_without_a_gate_nothing_is_gated(cls):
    sc, sim, zs, _ = _data(runs=5, steps=10)
    track = pu.run(cls(sc.motion, sc.measurement), zs, sim.prior)
    assert track.info["gated"].dtype == bool
    assert not track.info["gated"].any()


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_gross_outliers_are_rejected_and_the_step_only_predicts(cls):
    sc, sim, zs, outlier = _data()
    gate = 0.99
    track = pu.run(cls(sc.motion, sc.measurement, gate=gate), zs, sim.prior, store_predictions=True)
    gated = track.info["gated"]
    # every 30-sigma outlier is caught
    assert gated[outlier].all()
    # a gated step keeps the prediction, and reports the rejected measurement's NIS
    np.testing.assert_array_equal(track.mean[gated], track.info["pred_mean"][gated])
    np.testing.assert_array_equal(track.cov[gated], track.info["pred_cov"][gated])
    thresholds = stats.chi2.ppf(gate, track.info["dof"])
    np.testing.assert_array_equal(gated, track.info["nis"] > thresholds)
    # clean measurements are gated at about the gate's false-alarm rate 1 - gate (loose: the
    # steps after a rejection are not independent of it)
    clean = ~outlier
    assert gated[clean].mean() < 3 * (1 - gate)


def test_a_gated_run_equals_a_run_told_which_measurements_to_ignore():
    sc, sim, zs, outlier = _data()
    kf = pu.KalmanFilter(sc.motion, sc.measurement, gate=0.99)
    track = pu.run(kf, zs, sim.prior)
    gated = track.info["gated"]
    masked = zs.copy()
    masked[gated] = np.nan  # the same steps, missing instead of gated
    reference = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), masked, sim.prior)
    np.testing.assert_allclose(track.mean, reference.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(track.cov, reference.cov, rtol=1e-12, atol=1e-12)


def test_the_gate_helps_on_contaminated_data():
    sc, sim, zs, outlier = _data(runs=300)
    plain = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), zs, sim.prior)
    gated = pu.run(pu.KalmanFilter(sc.motion, sc.measurement, gate=0.99), zs, sim.prior)
    err_plain = np.sqrt(np.mean((plain.mean - sim.truth)[..., 0] ** 2))
    err_gated = np.sqrt(np.mean((gated.mean - sim.truth)[..., 0] ** 2))
    assert err_gated < 0.5 * err_plain


def test_the_gate_uses_the_measured_components_only():
    sc = WSNRange(steps=20)
    sim = sc.simulate(run_streams(3, range(4), 0), 4)
    zs = sim.measurements.copy()
    zs[5, 0, :2] = np.nan  # two of four ranges missing: the gate uses chi2(2)
    zs[5, 0, 3] += 40.0  # and one of the two left is an outlier
    track = pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement, gate=0.999), zs, sim.prior)
    assert track.info["dof"][5, 0] == 2
    assert track.info["gated"][5, 0]
    assert track.info["nis"][5, 0] > stats.chi2.ppf(0.999, 2)


@pytest.mark.parametrize("bad", [0.0, 1.0, 1.5, -0.1, float("nan")])
def test_impossible_gate_probabilities_are_refused(bad):
    sc = LinearCV(ndim=1)
    with pytest.raises(ValueError, match="gate"):
        pu.KalmanFilter(sc.motion, sc.measurement, gate=bad)


_GATE_CONFIGS = {
    "wsn": """
[experiment]
runs = 2
[scenario]
type = "wsn-range"
steps = 5
[[filters]]
type = "ekf"
gate = 0.99
[[filters]]
type = "ukf"
gate = 0.999
[[filters]]
type = "ckf"
gate = 0.9
""",
    "maneuver": """
[experiment]
kind = "maneuver"
runs = 2
[scenario]
type = "maneuver-3d"
horizon = 8
[[filters]]
type = "cs"
gate = 0.99
[[filters]]
type = "apcs"
gate = 0.95
[[filters]]
type = "ms"
gate = 0.999
[[filters]]
type = "singer"
gate = 0.98
[[filters]]
type = "imm-singer"
gate = 0.97
[[filters]]
type = "imm"
models = [{type = "singer", alpha = 0.05}, {type = "cs"}]
gate = 0.9
""",
}


@pytest.mark.parametrize("config", list(_GATE_CONFIGS))
def test_gate_is_a_config_parameter_of_every_gaussian_filter(tmp_path, config):
    text = _GATE_CONFIGS[config]
    last_line = text[: text.index("gate = 0.9\n")].count("\n") + 1
    path = tmp_path / "exp.toml"
    path.write_text(text)
    exp = load_experiment(path)
    gates = [float(g) for g in re.findall(r"^gate = ([0-9.]+)$", text, flags=re.M)]
    assert [f.gate for f in exp.plan.filters] == gates
    n = len(gates)
    path.write_text(text.replace("gate = 0.9\n", "gate = 2.0\n"))
    with pytest.raises(ConfigError, match=rf"exp.toml:{last_line}: filters\[{n - 1}\].gate: must lie in \(0, 1\)"):
        load_experiment(path)


@pytest.mark.parametrize("cls", [pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter], ids=lambda c: c.__name__)
def test_gated_sigma_point_and_extended_filters_are_batch_invariant_bit_for_bit(cls):
    # Gating and the sigma-point Joseph form (einsum, stacked solve) must not make a run's
    # result depend on the other runs of its batch.
    sc = WSNRange(steps=30)
    runs = 7
    sim = sc.simulate(run_streams(1, range(runs), 0), runs)
    filt = cls(sc.motion, sc.measurement, gate=0.9)
    batch = pu.run(filt, sim.measurements, sim.prior)
    assert batch.info["gated"].any()
    for i in range(runs):
        one = pu.run(filt, sim.measurements[:, i : i + 1], pu.Gaussian(sim.prior.mean[i : i + 1], sim.prior.cov))
        assert np.array_equal(one.mean[:, 0], batch.mean[:, i])
        assert np.array_equal(one.cov[:, 0], batch.cov[:, i])


class _SkipFirstRun:
    """A fading strategy with an outlier gate of its own that always rejects run 0."""

    data_independent = False

    def init(self, batch):
        return None

    def factor(self, memory, ctx):
        from pursuit.filters.fading import Fade

        mask = np.zeros(ctx.pred_mean.shape[:-1], dtype=bool)
        mask[0] = True
        return Fade(1.0, skip=mask, info={"gated": mask}), memory


def test_a_fading_strategys_gate_and_the_chi2_gate_share_the_flag():
    sc = LinearCV(ndim=1, steps=3, sigma=1.0)
    filt = pu.KalmanFilter(sc.motion, sc.measurement, fading=_SkipFirstRun(), gate=0.99)
    state = filt.init(pu.Gaussian([0.0, 1.0], np.eye(2)), batch=(3,))
    z = np.array([[0.5], [0.5], [80.0]])  # run 2 is a chi-square outlier
    _, info = filt.step(state, z)
    assert info["gated"].tolist() == [True, False, True]


# --------------------------------------------------------------------------
# CS-family filters (one axis at a time) and the IMM
# --------------------------------------------------------------------------
QUIET = ManeuveringTarget(maneuvers=[], init="sampled", horizon=42)


def _quiet_data(runs=200, seed=8, outlier_rate=0.05, size=30.0):
    """A non-maneuvering target with gross outliers on the x axis."""
    sim = QUIET.simulate(run_streams(seed, range(runs), 0), runs)
    rng = np.random.default_rng(seed)
    outlier = rng.random((QUIET.steps, runs)) < outlier_rate
    outlier[:2] = False  # keep the start clean
    zs = sim.measurements.copy()
    zs[..., 0] += np.where(outlier, size * np.sqrt(QUIET.R), 0.0)
    return sim, zs, outlier


def _singer_kf(alpha, sigma, **kw):
    return pu.KalmanFilter(Singer(alpha=alpha, sigma=sigma, ndim=3), QUIET.measurement, **kw)


def _imm_singer(**kw):
    return InteractingMultipleModel([_singer_kf(a, s) for a, s in ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))], 0.95, **kw)


AXIS_FILTERS = {
    "cs": lambda **kw: CurrentStatisticalFilter(QUIET.measurement, **kw),
    "apcs": lambda **kw: AdaptiveCSFilter(QUIET.measurement, **kw),
    "ms": lambda **kw: ModifiedSingerFilter(QUIET.measurement, **kw),
}


@pytest.mark.parametrize("make", [*AXIS_FILTERS.values(), _imm_singer], ids=[*AXIS_FILTERS, "imm"])
def test_cs_family_and_imm_without_a_gate_gate_nothing(make):
    sim, zs, _ = _quiet_data(runs=5)
    track = pu.run(make(), zs, sim.prior)
    assert track.info["gated"].dtype == bool and track.info["gated"].shape == zs.shape[:2]
    assert not track.info["gated"].any()
    # and a gate changes nothing where it rejects nothing
    gated = pu.run(make(gate=1 - 1e-15), sim.measurements, sim.prior)
    assert not gated.info["gated"].any()
    np.testing.assert_array_equal(gated.mean, pu.run(make(), sim.measurements, sim.prior).mean)


@pytest.mark.parametrize("name", list(AXIS_FILTERS))
def test_cs_family_gate_keeps_the_prediction_and_flags_the_nis_above_the_quantile(name):
    sim, zs, outlier = _quiet_data()
    gate = 0.9 if name == "apcs" else 0.99  # APCS: a gate that fires on the steps it does not adapt to
    filt = AXIS_FILTERS[name](gate=gate)
    track = pu.run(filt, zs, sim.prior, store_predictions=True)
    gated = track.info["gated"]
    assert gated.any()
    np.testing.assert_array_equal(gated, track.info["nis"] > stats.chi2.ppf(gate, track.info["dof"]))
    np.testing.assert_array_equal(track.mean[gated], track.info["pred_mean"][gated])
    np.testing.assert_array_equal(track.cov[gated], track.info["pred_cov"][gated])
    if name != "apcs":  # APCS's strong-tracking λ absorbs a single outlier (next test)
        assert gated[outlier].all()
        assert gated[~outlier].mean() < 3 * (1 - gate)  # loose: steps after a rejection depend on it


@pytest.mark.parametrize(
    "name,kw",
    [("cs", {}), ("ms", {}), ("apcs", {"fading": "none", "alpha_rule": "none"})],
    ids=["cs", "ms", "apcs-detector-only"],
)
def test_a_gated_cs_family_run_equals_a_run_told_which_measurements_to_ignore(name, kw):
    # The prediction of these filters does not depend on the measurement, and a rejected
    # measurement teaches the adaptive quantities (σ_a², MS's autocorrelations) nothing.
    sim, zs, _ = _quiet_data()
    track = pu.run(AXIS_FILTERS[name](gate=0.99, **kw), zs, sim.prior)
    gated = track.info["gated"]
    assert gated.any()
    masked = zs.copy()
    masked[gated] = np.nan
    reference = pu.run(AXIS_FILTERS[name](**kw), masked, sim.prior)
    np.testing.assert_allclose(track.mean, reference.mean, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(track.cov, reference.cov, rtol=1e-12, atol=1e-12)
    for key in ("alpha", "sigma_a2"):
        np.testing.assert_allclose(track.info[key], reference.info[key], rtol=1e-12)


def test_apcs_learns_nothing_from_a_rejected_measurement():
    sim, zs, _ = _quiet_data()
    filt = AdaptiveCSFilter(QUIET.measurement, gate=0.9)
    state = filt.init(sim.prior, (zs.shape[1],))
    seen = 0
    for k in range(QUIET.steps):
        new, info = filt.step(state, zs[k])
        g = info["gated"]
        seen += g.sum()
        for key in ("sigma2", "V"):  # σ_a² and the strong-tracking memory stay as they were
            np.testing.assert_array_equal(new.memory[key][g], state.memory[key][g])
        state = new
    assert seen > 0


def test_apcs_detected_axes_have_nis_below_one_plus_rho_so_the_gate_rarely_fires_there():
    # With λ > 1 and α = α0 the strong-tracking rule makes S exactly the memory V, which has just
    # taken in ν²: ν²/V = (1 + ρ) ν² / (ρ V_old + ν²) < 1 + ρ.  An axis that detects nothing has
    # NIS = D ≤ M.  So a step whose axes are all quiet or faded has NIS < 3 max(M, 1 + ρ) = 9, below
    # the χ²(3) 99 % quantile 11.34: it is never gated, an outlier included.  (See pursuit.filters.cs.)
    sim, zs, outlier = _quiet_data()
    filt = AdaptiveCSFilter(QUIET.measurement, alpha_rule="none", rho=0.95, threshold=3.0, gate=0.99)
    info = pu.run(filt, zs, sim.prior).info
    faded = info["maneuver"] & (info["axis_fading"] > 1.0)
    axis_nis = info["innovation"] ** 2 / np.diagonal(info["S"], axis1=-2, axis2=-1)
    assert faded[..., 0][outlier].any()  # outliers are taken for maneuver onsets
    assert np.all(axis_nis[faded] < 1.0 + filt.rho)
    assert np.all(axis_nis[~info["maneuver"]] <= filt.threshold)
    covered = np.all(faded | ~info["maneuver"], axis=-1)
    assert 3 * max(filt.threshold, 1.0 + filt.rho) < stats.chi2.ppf(0.99, 3)
    assert covered[outlier].any() and not info["gated"][covered].any()


def test_an_imm_of_identical_modes_gates_as_the_single_filter():
    sim, zs, _ = _quiet_data(runs=50)
    single = pu.run(_singer_kf(0.05, 20.0, gate=0.99), zs, sim.prior)
    imm = pu.run(InteractingMultipleModel([_singer_kf(0.05, 20.0)] * 3, 0.9, gate=0.99), zs, sim.prior)
    assert single.info["gated"].any()
    np.testing.assert_array_equal(imm.info["gated"], single.info["gated"])
    np.testing.assert_allclose(imm.mean, single.mean, rtol=1e-12, atol=1e-8)
    np.testing.assert_allclose(imm.cov, single.cov, rtol=1e-8, atol=1e-9)


def test_a_gated_imm_step_is_a_step_without_the_measurement():
    sim, zs, outlier = _quiet_data(runs=100)
    track = pu.run(_imm_singer(gate=0.99), zs, sim.prior)
    gated = track.info["gated"]
    assert gated[outlier].any()
    masked = zs.copy()
    masked[gated] = np.nan
    reference = pu.run(_imm_singer(), masked, sim.prior)
    np.testing.assert_allclose(track.mean, reference.mean, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(track.cov, reference.cov, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(track.info["mode_probs"], reference.info["mode_probs"], rtol=1e-10, atol=1e-14)
    # the info describes the rejected measurement: its NIS is outside every mode's gate
    limit = stats.chi2.ppf(0.99, 3)
    np.testing.assert_array_equal(gated, np.all(track.info["mode_nis"] > limit, axis=-1))
    assert np.all(np.isfinite(track.info["nis"][gated]))


def test_the_imm_gate_is_the_union_of_the_mode_gates():
    # Two constant-velocity modes from the same prior: a quiet one that is almost certain (c̄ = 0.99)
    # and a maneuvering one (c̄ = 0.01) with a much larger S.  A 30 m miss is far outside the
    # quiet mode's gate, and outside the gate of the moment-matched mixture, but inside the
    # maneuvering mode's: the IMM keeps it.  A 100 m miss is outside both and is rejected.
    sc = LinearCV(ndim=1, sigma=1.0)
    modes = [pu.KalmanFilter(ConstantVelocity(ndim=1, q=q), sc.measurement) for q in (1e-4, 3000.0)]
    imm = InteractingMultipleModel(modes, np.eye(2), [0.99, 0.01], gate=0.99)
    state = imm.init(pu.Gaussian([0.0, 0.0], np.diag([0.01, 0.01])), (2,))
    new, info = imm.step(state, np.array([[30.0], [100.0]]))
    limit = stats.chi2.ppf(0.99, 1)
    assert np.all(info["mode_nis"][:, 0] > limit) and info["nis"][0] > limit  # quiet mode and mixture reject ...
    assert info["mode_nis"][0, 1] < limit  # ... the maneuvering mode accepts the 30 m miss
    assert info["gated"].tolist() == [False, True]
    assert new.probs[0, 1] > 0.5  # the measurement that was kept switches the IMM to the maneuvering mode
    np.testing.assert_allclose(new.probs[1], [0.99, 0.01], rtol=1e-12)  # a rejected one leaves μ = c̄


@pytest.mark.parametrize("bad", [0.0, 1.0, float("nan")])
@pytest.mark.parametrize("make", [*AXIS_FILTERS.values(), _imm_singer], ids=[*AXIS_FILTERS, "imm"])
def test_cs_family_and_imm_refuse_impossible_gates(make, bad):
    with pytest.raises(ValueError, match="^gate:"):
        make(gate=bad)


def test_gated_imm_is_batch_invariant():
    # A step where one run is rejected re-runs the modes for the whole batch with that run's
    # measurement missing: the other runs must not notice.
    sim, zs, outlier = _quiet_data(runs=6)
    filt = _imm_singer(gate=0.99)
    batch = pu.run(filt, zs, sim.prior)
    assert batch.info["gated"].any() and not batch.info["gated"].all(axis=1).any()
    for i in range(zs.shape[1]):
        one = pu.run(filt, zs[:, i : i + 1], pu.Gaussian(sim.prior.mean[i : i + 1], sim.prior.cov))
        np.testing.assert_allclose(one.mean[:, 0], batch.mean[:, i], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(one.cov[:, 0], batch.cov[:, i], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(one.info["gated"][:, 0], batch.info["gated"][:, i])
