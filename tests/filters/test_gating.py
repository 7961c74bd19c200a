"""Chi-square gating of outliers in the Gaussian filters."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit.experiment import ConfigError, load_experiment
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, WSNRange

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


def test_gate_is_a_config_parameter_of_every_gaussian_filter(tmp_path):
    text = """
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
"""
    path = tmp_path / "exp.toml"
    path.write_text(text)
    exp = load_experiment(path)
    assert [f.gate for f in exp.plan.filters] == [0.99, 0.999, 0.9]
    path.write_text(text.replace("gate = 0.9\n", "gate = 2.0\n"))
    with pytest.raises(ConfigError, match=r"exp.toml:15: filters\[2\].gate: must lie in \(0, 1\)"):
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
