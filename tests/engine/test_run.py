"""The run driver."""

import numpy as np
import pytest

import pursuit as pu
from pursuit.scenarios import LinearCV


@pytest.fixture
def setup():
    sc = LinearCV(ndim=1, steps=10)
    sim = sc.simulate(np.random.default_rng(0), 3)
    return sc, sim


def test_track_shapes_and_info(setup):
    sc, sim = setup
    tr = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior)
    assert tr.mean.shape == (10, 3, 2) and tr.cov.shape == (10, 3, 2, 2)
    assert tr.steps == 10 and tr.name == "KF" and tr.wall_time > 0
    assert "pred_mean" not in tr.info  # smoother data only on request
    tr2 = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior, keep_cov=False, keep_info=["nis"])
    assert tr2.cov is None and set(tr2.info) == {"nis", "diverged"}  # the divergence flag is always kept


def test_dts_equal_to_the_model_dt_change_nothing(setup):
    sc, sim = setup
    kf = pu.KalmanFilter(sc.motion, sc.measurement)
    a = pu.run(kf, sim.measurements, sim.prior)
    b = pu.run(kf, sim.measurements, sim.prior, dts=np.full(10, sc.dt))
    np.testing.assert_array_equal(a.mean, b.mean)


def test_irregular_dts_use_the_matching_transition(setup):
    sc, sim = setup
    kf = pu.KalmanFilter(sc.motion, sc.measurement)
    dts = np.linspace(0.5, 2.0, 10)
    tr = pu.run(kf, sim.measurements, sim.prior, dts=dts, store_predictions=True)
    F = sc.motion.transition_matrix(dt=dts[0])
    np.testing.assert_allclose(tr.info["pred_mean"][0], sim.prior.mean @ F.T)


@pytest.mark.parametrize(
    "kwargs,msg",
    [({"dts": np.ones(3)}, "dts"), ({"dts": -np.ones(10)}, "positive")],
)
def test_bad_arguments(setup, kwargs, msg):
    sc, sim = setup
    with pytest.raises(ValueError, match=msg):
        pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior, **kwargs)


def test_zs_must_have_a_time_axis(setup):
    sc, sim = setup
    with pytest.raises(ValueError, match="zs"):
        pu.run(pu.KalmanFilter(sc.motion, sc.measurement), np.zeros(3), sim.prior)
