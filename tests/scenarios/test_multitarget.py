"""Multi-target scenarios: shapes, common random numbers, P_D and clutter statistics, birth and death,
the built-ins' numbers (Williams 2015 from the public MATLAB code), and parameter errors."""

import math

import numpy as np
import pytest
from scipy import stats

from pursuit.models import ConstantAcceleration, ConstantTurn, ConstantVelocity, LinearGaussian, RangeBearing
from pursuit.multitarget import CLUTTER, PADDING
from pursuit.rng import run_streams
from pursuit.scenarios import Leg, MultiTargetScenario, Target, crossing, maneuvering_radar, williams15
from pursuit.scenarios.multitarget import WILLIAMS15_GOSPA

BUILT_INS = [crossing, williams15, maneuvering_radar]
CV = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
POS = LinearGaussian.position(4, (0, 2), 1.0)
BOX = [[-50.0, 50.0], [-50.0, 50.0]]
# two-sided z bound for a significance of 1e-6: a correct simulator fails such a test once in a million
Z_BOUND = stats.norm.isf(0.5e-6)


def _scenario(**kw):
    args = dict(
        targets=(Target([0.0, 1.0, 0.0, 0.5]), Target([10.0, -1.0, 5.0, 0.0], birth=3, death=8)),
        motion=CV,
        measurement=POS,
        clutter_region=BOX,
        clutter_rate=2.0,
        p_detect=0.8,
        steps=10,
    )
    args.update(kw)
    return MultiTargetScenario(**args)


@pytest.mark.parametrize("make", BUILT_INS, ids=lambda f: f.__name__)
def test_built_in_shapes(make):
    sc = make()
    truth, scans = sc.simulate(run_streams(3, range(4), 0))
    K, N = sc.steps, len(sc.targets)
    assert truth.states.shape == (K, 4, N, 4) and scans.z.shape[:2] == (K, 4) and scans.dim == sc.measurement.dim
    np.testing.assert_array_equal(scans.times, sc.dt * np.arange(1, K + 1))
    np.testing.assert_array_equal(truth.labels, np.arange(N))
    assert sc.state_labels == ("x", "vx", "y", "vy") and sc.position_indices == (0, 2)
    # detections packed first, padding last, origin -2 exactly on the padding
    present = scans.present
    assert (np.sort(~present, axis=-1, kind="stable") == ~present).all()
    np.testing.assert_array_equal(scans.origin == PADDING, ~present)


@pytest.mark.parametrize("make", BUILT_INS, ids=lambda f: f.__name__)
def test_run_is_the_same_alone_in_a_batch_and_in_chunks(make):
    sc = make()
    truth5, scans5 = sc.simulate(run_streams(11, range(5), 0))
    for i in (0, 3):
        t1, s1 = sc.simulate(run_streams(11, [i], 0))
        np.testing.assert_array_equal(t1.states, truth5.states[:, i : i + 1])
        sel = scans5.select_runs([i])
        np.testing.assert_array_equal(s1.z, sel.z)
        np.testing.assert_array_equal(s1.origin, sel.origin)
    _, a = sc.simulate(run_streams(11, range(2), 0))
    _, b = sc.simulate(run_streams(11, range(2, 5), 0))
    np.testing.assert_array_equal(a.z, scans5.select_runs([0, 1]).z)
    np.testing.assert_array_equal(b.z, scans5.select_runs([2, 3, 4]).z)
    # same seed, same bits; another seed, other detections
    _, again = sc.simulate(run_streams(11, range(5), 0))
    np.testing.assert_array_equal(again.z, scans5.z)
    _, other = sc.simulate(run_streams(12, range(5), 0))
    assert other.z.shape != scans5.z.shape or not np.array_equal(other.z, scans5.z, equal_nan=True)


def test_single_generator_needs_runs_and_works():
    sc = _scenario()
    with pytest.raises(ValueError, match="^runs"):
        sc.simulate(np.random.default_rng(0))
    truth, scans = sc.simulate(np.random.default_rng(0), 6)
    assert truth.runs == scans.runs == 6


def test_truth_then_detections_equals_simulate():
    sc = _scenario()
    truth, scans = sc.simulate(run_streams(4, range(3), 0))
    streams = run_streams(4, range(3), 0)
    t2 = sc.simulate_truth(streams)
    np.testing.assert_array_equal(t2.states, truth.states)
    np.testing.assert_array_equal(sc.detect(t2, streams).z, scans.z)
    with pytest.raises(ValueError, match="^rng"):
        sc.detect(truth, run_streams(4, range(2), 0))


def test_detection_probability_is_p_d():
    # one target, no clutter: the number of its detections is Binomial(K·M, P_D)
    p = 0.7
    sc = _scenario(targets=(Target([0.0, 1.0, 0.0, 1.0]),), clutter_rate=0.0, p_detect=p, steps=50)
    truth, scans = sc.simulate(run_streams(5, range(400), 0))
    n = truth.exists.sum()
    hits = (scans.origin == 0).sum()
    assert (scans.origin == CLUTTER).sum() == 0
    assert scans.count.max() <= 1
    z = (hits - n * p) / math.sqrt(n * p * (1 - p))
    assert abs(z) < Z_BOUND


def test_every_target_detected_once_with_p_d_one_and_noise_is_r():
    sc = _scenario(clutter_rate=0.0, p_detect=1.0, steps=30)
    truth, scans = sc.simulate(run_streams(6, range(300), 0))
    np.testing.assert_array_equal(scans.count, truth.count)
    # each detection is h(x) + v with v ~ N(0, R): match rows to targets through the origin
    k, m, d = np.nonzero(scans.origin >= 0)
    resid = scans.z[k, m, d] - POS.h(truth.states[k, m, scans.origin[k, m, d]])
    n = resid.shape[0]
    assert np.all(np.abs(resid.mean(axis=0)) < Z_BOUND / math.sqrt(n))
    # sample variance of a unit normal: standard error sqrt(2 / (n - 1))
    assert np.all(np.abs(resid.var(axis=0, ddof=1) - 1.0) < Z_BOUND * math.sqrt(2 / (n - 1)))


def test_clutter_is_poisson_and_uniform_over_the_region():
    lam = 3.0
    sc = _scenario(p_detect=0.0, clutter_rate=lam, steps=40)
    _, scans = sc.simulate(run_streams(8, range(250), 0))
    counts = scans.count.ravel()
    n = counts.size
    assert (scans.origin[scans.present] == CLUTTER).all()
    assert abs(counts.mean() - lam) < Z_BOUND * math.sqrt(lam / n)
    # Poisson dispersion test: Σ (c − c̄)² / c̄ ~ χ²(n − 1)
    disp = ((counts - counts.mean()) ** 2).sum() / counts.mean()
    assert stats.chi2.sf(disp, n - 1) > 1e-6 and stats.chi2.cdf(disp, n - 1) > 1e-6
    points = scans.z[scans.present]
    for c, (lo, hi) in enumerate(BOX):
        assert stats.kstest(points[:, c], stats.uniform(lo, hi - lo).cdf).pvalue > 1e-6
    assert sc.clutter_volume == 100.0 * 100.0 and sc.clutter_density == lam / 1e4


def test_detections_are_shuffled_within_a_scan():
    sc = _scenario(clutter_rate=3.0, p_detect=1.0)
    _, scans = sc.simulate(run_streams(9, range(200), 0))
    first = scans.origin[:, :, 0]
    # target 0 always exists and is detected; shuffled, it is not always the first row
    frac = (first == 0).mean()
    assert 0.05 < frac < 0.9
    assert ((first == CLUTTER) | (first == 1)).any()


def test_birth_and_death_are_respected():
    sc = _scenario(p_detect=1.0, clutter_rate=1.0)
    truth, scans = sc.simulate(run_streams(2, range(20), 0))
    k = np.arange(1, sc.steps + 1)
    np.testing.assert_array_equal(truth.exists[:, :, 0], True)
    np.testing.assert_array_equal(truth.exists[:, :, 1], ((k >= 3) & (k < 8))[:, None] & np.ones((1, 20), bool))
    seen = (scans.origin == 1).any(axis=2)
    np.testing.assert_array_equal(seen, truth.exists[:, :, 1])
    # the state at birth is x0 exactly (no spread)
    np.testing.assert_array_equal(truth.states[2, :, 1], np.broadcast_to([10.0, -1.0, 5.0, 0.0], (20, 4)))


def test_legs_turn_and_accelerate():
    sc = _scenario(
        targets=(
            Target([0.0, 10.0, 0.0, 0.0], legs=(Leg(4, ConstantTurn(math.pi / 6, 0.0, 2, 1.0)), Leg(7))),
            Target([0.0, 0.0, 0.0, 0.0], legs=(Leg(2, accel=[1.0, -2.0]), Leg(5))),
        ),
        motion=ConstantTurn(0.0, 0.0, 2, 1.0),  # noise-free constant velocity
        steps=9,
    )
    truth, _ = sc.simulate(run_streams(0, range(2), 0))
    v = truth.states[:, 0, 0][:, [1, 3]]
    np.testing.assert_allclose(v[2], [10.0, 0.0])  # scan 3: before the turn
    np.testing.assert_allclose(v[5], [0.0, 10.0], atol=1e-12)  # three steps at 30°: a quarter turn
    np.testing.assert_allclose(v[8], [0.0, 10.0], atol=1e-12)
    s = truth.states[:, 0, 1]
    np.testing.assert_allclose(s[3][[1, 3]], [3.0, -6.0])  # three steps of (1, −2) m/s²
    np.testing.assert_allclose(s[3][[0, 2]], [4.5, -9.0])  # ½ a t²
    np.testing.assert_allclose(s[8][[1, 3]], [3.0, -6.0])  # then straight on


def test_crossing_numbers():
    sc = crossing()
    assert (sc.steps, sc.p_detect, sc.dt) == (20, 0.9, 1.0)
    np.testing.assert_allclose(sc.measurement.R, 0.75 * np.eye(2))
    assert sc.motion.q == 0.005 and sc.motion.noise == "continuous"
    np.testing.assert_array_equal(sc.targets[0].x0, [0, 1, 0, 1])
    np.testing.assert_array_equal(sc.targets[1].x0, [0, 1, 20, -1])
    truth, _ = sc.simulate(run_streams(0, range(3), 0))
    np.testing.assert_array_equal(truth.states[0, :, 1], np.broadcast_to([0.0, 1.0, 20.0, -1.0], (3, 4)))
    assert truth.exists.all()


def test_williams15_numbers_from_the_matlab_code():
    sc = williams15()
    # ScenarioWilliams15.m: T = 1, Nsteps = 81, Q = 0.02 [[T³/3, T²/2], [T²/2, T]] per axis, R = I, p_d = 0.9,
    # l_clutter = 10 over Area = [300 300]
    assert (sc.steps, sc.dt, sc.p_detect, sc.clutter_rate) == (81, 1.0, 0.9, 10.0)
    Q1 = 0.02 * np.array([[1 / 3, 1 / 2], [1 / 2, 1.0]])
    np.testing.assert_allclose(sc.motion.cov(), np.kron(np.eye(2), Q1))
    np.testing.assert_allclose(sc.measurement.R, np.eye(2))
    np.testing.assert_array_equal(sc.clutter_region, [[0, 300], [0, 300]])
    assert WILLIAMS15_GOSPA == {"c": 10.0, "p": 2.0, "alpha": 2.0}  # c_gospa = 10, p = 2, alpha = 2
    # TrajectoryWilliams15.m, scenario 1: t_birth = 1, t_death = [41, 82, 82, 82] (exists for birth <= k < death)
    M = 400
    truth, _ = sc.simulate_truth(run_streams(4, range(M), 0)), None
    k = np.arange(1, 82)
    np.testing.assert_array_equal(truth.exists[:, 0, 0], k < 41)
    assert truth.exists[:, :, 1:].all()
    # midpoint states ~ N((150, 0, 150, 0), 0.1 I): targets 1-3 at scan 41 (target 0 has just died)
    mid = truth.states[40, :, 1:].reshape(-1, 4)
    n = mid.shape[0]
    assert np.all(np.abs(mid.mean(axis=0) - [150, 0, 150, 0]) < Z_BOUND * math.sqrt(0.1 / n))
    assert np.all(np.abs(mid.var(axis=0, ddof=1) - 0.1) < Z_BOUND * 0.1 * math.sqrt(2 / (n - 1)))
    # forwards x_{k+1} = F x_k + w and backwards x_k = F⁻¹(x_{k+1} + w'), w, w' ~ N(0, Q)
    F = sc.motion.transition_matrix()
    x = truth.states[:, :, 1:]
    fwd = (x[41:] - x[40:-1] @ F.T).reshape(-1, 4)
    bwd = (x[:40] @ F.T - x[1:41]).reshape(-1, 4)
    Q = sc.motion.cov()
    for w in (fwd, bwd):
        C = np.cov(w.T)
        se = np.sqrt((Q**2 + np.outer(np.diag(Q), np.diag(Q))) / (w.shape[0] - 1))  # of a sample covariance
        assert np.all(np.abs(C - Q) < Z_BOUND * se)
    # the four targets nearly meet at the midpoint
    assert np.abs(truth.states[39, :, :, [0, 2]] - 150).max() < 3.0


def test_maneuvering_radar_stays_in_the_clutter_region():
    sc = maneuvering_radar()
    assert isinstance(sc.measurement, RangeBearing)
    truth, scans = sc.simulate(run_streams(1, range(50), 0))
    h = sc.measurement.h(truth.states[truth.exists])
    lo, hi = sc.clutter_region[:, 0], sc.clutter_region[:, 1]
    assert np.all((h > lo) & (h < hi))
    k = np.arange(1, 101)
    np.testing.assert_array_equal(truth.exists[:, 0, 2], (k >= 21) & (k < 91))
    # target 0 turns a quarter circle clockwise over scans 31-60; target 1 gains about 200 m/s in y over 41-50
    v0 = truth.states[:, :, 0][:, :, [1, 3]]
    turn = np.degrees(np.arctan2(v0[59, :, 1], v0[59, :, 0]) - np.arctan2(v0[29, :, 1], v0[29, :, 0]))
    turn = (turn + 180) % 360 - 180
    assert np.all(np.abs(turn + 90) < 10)
    dv = truth.states[49, :, 1, 3] - truth.states[39, :, 1, 3]
    assert np.all(np.abs(dv - 200) < 25)


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"p_detect": 1.5}, "p_detect"),
        ({"p_detect": -0.1}, "p_detect"),
        ({"clutter_rate": -1.0}, "clutter_rate"),
        ({"clutter_rate": math.inf}, "clutter_rate"),
        ({"clutter_region": [[0.0, 0.0], [0.0, 1.0]]}, "clutter_region"),
        ({"clutter_region": [[1.0, 0.0], [0.0, 1.0]]}, "clutter_region"),
        ({"clutter_region": [[0.0, 1.0]]}, "clutter_region"),
        ({"clutter_region": [[0.0, np.inf], [0.0, 1.0]]}, "clutter_region"),
        ({"steps": 0}, "steps"),
        ({"dt": 0.0}, "dt"),
        ({"targets": ()}, "targets"),
        ({"targets": (Target([0.0, 1.0, 0.0, 1.0], birth=11),)}, r"targets\[0\].birth"),
        ({"targets": (Target([0.0, 1.0, 0.0]),)}, r"targets\[0\].x0"),
        ({"targets": (Target([0.0] * 4, motion=ConstantAcceleration(ndim=2)),)}, r"targets\[0\].motion"),
        ({"targets": (Target([0.0] * 4, legs=(Leg(3, accel=[1.0]),)),)}, r"targets\[0\].legs\[0\].accel"),
        ({"targets": ("not a target",)}, r"targets\[0\]"),
    ],
)
def test_impossible_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        _scenario(**kwargs)


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"birth": 5, "death": 5}, "death"),
        ({"birth": 6, "death": 2}, "death"),
        ({"birth": 0}, "birth"),
        ({"birth": 1.5}, "birth"),
        ({"birth": 3, "anchor": 2}, "anchor"),
        ({"death": 4, "anchor": 5}, "anchor"),
        ({"legs": (Leg(3), Leg(3))}, r"legs\[1\].start"),
        ({"legs": (Leg(1),)}, r"legs\[0\].start"),
        ({"spread": -np.eye(4)}, "spread"),
    ],
)
def test_impossible_targets_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        Target([0.0, 1.0, 0.0, 1.0], **kwargs)
