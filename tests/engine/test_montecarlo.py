"""Monte Carlo engine: common random numbers, chunk invariance, seeding, validation."""

import numpy as np
import pytest

import pursuit as pu
from pursuit.engine import monte_carlo
from pursuit.engine.progress import Progress
from pursuit.scenarios import LinearCV, WSNRange


def _filters(sc):
    return [pu.ExtendedKalmanFilter(sc.motion, sc.measurement), pu.UnscentedKalmanFilter(sc.motion, sc.measurement)]


def _assert_same(a, b):
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.measurements, b.measurements)
    for name in a.filter_names:
        fa, fb = a.filters[name], b.filters[name]
        np.testing.assert_array_equal(fa.estimates, fb.estimates)
        np.testing.assert_array_equal(fa.covariances, fb.covariances)
        for key in fa.info:
            np.testing.assert_array_equal(fa.info[key], fb.info[key])


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_results_are_bit_identical_whatever_the_chunk_size(chunk):
    sc = WSNRange(steps=15)
    whole = monte_carlo(sc, _filters(sc), runs=20, seed=5, chunk_size=1000)
    chunked = monte_carlo(sc, _filters(sc), runs=20, seed=5, chunk_size=chunk)
    _assert_same(whole, chunked)


def test_kf_shared_and_batched_paths_give_the_same_bits_across_chunks():
    # Missing measurements in some runs push the KF off its shared-covariance path only in the chunks
    # that hold those runs; the results must not change.
    class Gappy(LinearCV):
        def simulate(self, rng, runs=None):
            sim = super().simulate(rng, runs)
            first = np.array([g.random() for g in rng.generators]) < 0.3  # drawn per run: chunk-invariant
            sim.measurements[4, first] = np.nan
            return sim

    sc = Gappy(ndim=2, steps=12)
    kf = [pu.KalmanFilter(sc.motion, sc.measurement)]
    _assert_same(monte_carlo(sc, kf, 30, 9, chunk_size=30), monte_carlo(sc, kf, 30, 9, chunk_size=4))


def test_a_run_does_not_depend_on_how_many_runs_follow():
    sc = WSNRange(steps=10)
    small = monte_carlo(sc, _filters(sc), runs=3, seed=11)
    large = monte_carlo(sc, _filters(sc), runs=8, seed=11)
    np.testing.assert_array_equal(small.truth, large.truth[:, :3])
    np.testing.assert_array_equal(small.filters["EKF"].estimates, large.filters["EKF"].estimates[:, :3])


def test_common_random_numbers_and_seed_dependence():
    sc = WSNRange(steps=10)
    a = monte_carlo(sc, _filters(sc)[:1], runs=4, seed=1)
    b = monte_carlo(sc, _filters(sc)[1:], runs=4, seed=1)
    np.testing.assert_array_equal(a.measurements, b.measurements)  # each filter saw the same data
    c = monte_carlo(sc, _filters(sc)[:1], runs=4, seed=2)
    assert not np.array_equal(a.measurements, c.measurements)
    assert a.seed == 1 and a.runs == 4 and a.steps == 10


@pytest.mark.parametrize(
    "kwargs,msg",
    [
        ({"runs": 0}, "runs"),
        ({"seed": -1}, "seed"),
        ({"chunk_size": 0}, "chunk_size"),
        ({"filters": []}, "filters"),
    ],
)
def test_bad_arguments(kwargs, msg):
    sc = LinearCV(steps=3)
    args = {"scenario": sc, "filters": [pu.KalmanFilter(sc.motion, sc.measurement)], "runs": 2, "seed": 0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=msg):
        monte_carlo(**args)


def test_duplicate_filter_names_are_refused():
    sc = LinearCV(steps=3)
    f = pu.KalmanFilter(sc.motion, sc.measurement)
    with pytest.raises(ValueError, match="unique"):
        monte_carlo(sc, [f, f], 2, 0)


class _Tty:
    def __init__(self, tty):
        self.tty, self.text = tty, ""

    def isatty(self):
        return self.tty

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_progress_bar_draws_only_on_a_terminal():
    quiet = _Tty(False)
    bar = Progress(4, "x", stream=quiet)
    bar.advance(4)
    bar.close()
    assert quiet.text == ""
    loud = _Tty(True)
    bar = Progress(4, "x", stream=loud)
    for _ in range(4):
        bar.advance()
    bar.close()
    assert "100.0%" in loud.text and loud.text.endswith("\n")


def test_the_compile_warm_up_leaves_a_compiled_filters_draws_alone():
    pytest.importorskip("numba")
    from pursuit.engine.montecarlo import FILTER_STREAM, SCENARIO_STREAM
    from pursuit.rng import run_streams

    sc = WSNRange(steps=12)
    pf = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=50, backend="numba")
    assert pf.compiled
    result = monte_carlo(sc, [pf], runs=6, seed=11)
    sim = sc.simulate(run_streams(11, range(6), SCENARIO_STREAM), 6)
    direct = pu.run(pf, sim.measurements, sim.prior, rng=run_streams(11, range(6), FILTER_STREAM))
    # the untimed one-step call draws from its own stream: the timed run is the filter's own, bit for bit
    np.testing.assert_array_equal(result.filters[pf.name].estimates, direct.mean)
