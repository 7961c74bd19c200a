"""The compiled partial UPF agrees with the NumPy filter, draws the same numbers, and is batch invariant.

The proposal's unscented Kalman step goes through Cholesky factors, small
inverses (LAPACK and closed forms in NumPy, a Cholesky solve in the
kernel) and sums in another order, so the two backends agree to rounding,
not bit for bit: every estimate, covariance, per-particle covariance,
weight and info key within a relative 1e-8 (``RTOL``; observed about
1e-12) over a short sequence (docs/compiled-backend.md).  The random
streams must be left in exactly the same state (the same draws, in the
same order), and a run alone must equal the same run in a batch bit for
bit.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit.compute import CompiledBackendWarning  # noqa: E402
from pursuit.models import ConstantVelocity, LinearGaussian, RangeBearing, RangeSensors  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios.ungm import UNGM  # noqa: E402

RTOL = 1e-8
ONE_ANCHOR = RangeSensors([[0.0, 0.0]], 0.848528137423857, (0, 2))
FOUR_ANCHORS = RangeSensors([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]], 0.848528137423857, (0, 2))
MOTION = ConstantVelocity(ndim=2, dt=1.0, q=0.01, noise="continuous")


def _close(a, b, what):
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    assert a.shape == b.shape, what
    assert np.array_equal(np.isnan(a), np.isnan(b)), f"{what}: NaN pattern differs"
    fin = np.isfinite(a) & np.isfinite(b)
    assert np.array_equal(a[~fin], b[~fin], equal_nan=True), f"{what}: infinities differ"
    err = np.max(np.abs(a[fin] - b[fin]) / (1.0 + np.abs(a[fin])), initial=0.0)
    assert err <= RTOL, f"{what}: relative difference {err:.3g}"


def _data(meas, M=4, T=12, seed=3, missing=True):
    rng = np.random.default_rng(seed)
    x0 = np.array([10.0, 0.5, 40.0, 0.8])
    x = np.tile(x0, (M, 1))
    zs = np.empty((T, M, meas.dim))
    for k in range(T):
        x = MOTION.sample(x, k + 1, rng)
        zs[k] = meas.sample(x, k + 1, rng)
    if missing:
        zs[4, 1, 0] = np.nan  # one missing component
        zs[6] = np.nan  # a step with nothing measured
    return zs, pu.Gaussian(x0, np.diag([1.5, 1.4, 0.9, 0.03]))


def _step_both(make, zs, prior, seed=5):
    """Step the NumPy and the compiled filter side by side, comparing every state and info array at every step."""
    M = zs.shape[1]
    filts = {be: make(be) for be in ("numpy", "numba")}
    assert filts["numba"].compiled and not filts["numpy"].compiled
    streams = {be: run_streams(seed, range(M), 1) for be in filts}
    states = {be: filts[be].init(prior, (M,), streams[be]) for be in filts}
    for k, z in enumerate(zs, start=1):
        out = {be: filts[be].step(states[be], z, k) for be in filts}
        (a, ia), (b, ib) = out["numpy"], out["numba"]
        for field in ("particles", "logw", "mean", "cov", "particle_cov"):
            _close(getattr(a, field), getattr(b, field), f"step {k} {field}")
        assert a.uniform == b.uniform, f"step {k} uniform"
        assert sorted(ia) == sorted(ib)
        for key in ia:
            _close(ia[key], ib[key], f"step {k} {key}")
        states = {"numpy": a, "numba": b}
    for ga, gb in zip(streams["numpy"].generators, streams["numba"].generators):
        assert ga.bit_generator.state == gb.bit_generator.state  # the same draws, in the same order


@pytest.mark.parametrize("anchors", [ONE_ANCHOR, FOUR_ANCHORS], ids=["1-anchor", "4-anchors"])
@pytest.mark.parametrize("fraction", [0.0, 0.1, 0.5, 1.0])
def test_compiled_upf_agrees_with_numpy(fraction, anchors):
    zs, prior = _data(anchors)
    _step_both(lambda be: pu.PartialUPF(MOTION, anchors, particles=60, fraction=fraction, backend=be), zs, prior)


@pytest.mark.parametrize(
    "options",
    [
        dict(select="random"),
        dict(select="block", rounding="floor"),
        dict(cov_mode="propagate"),
        dict(cov_mode="reset", resampler="stratified"),
        dict(cov_mode="zero", ess_threshold=None, resampler="residual"),
        dict(alpha=1.0, beta=0.0, kappa=2.0, resampler="multinomial"),
    ],
    ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()),
)
def test_compiled_upf_options_agree(options):
    zs, prior = _data(FOUR_ANCHORS)
    _step_both(lambda be: pu.PartialUPF(MOTION, FOUR_ANCHORS, particles=40, fraction=0.5, backend=be, **options), zs, prior)


@pytest.mark.parametrize(
    "meas",
    [RangeBearing([0.0, -50.0], 1.0, 0.02), LinearGaussian.position(4, (0, 2), 1.0)],
    ids=["range-bearing", "linear"],
)
def test_compiled_upf_other_sensors_agree(meas):
    zs, prior = _data(meas)
    _step_both(lambda be: pu.PartialUPF(MOTION, meas, particles=40, fraction=0.5, backend=be), zs, prior)


def test_compiled_upf_ungm_agrees():
    sc = UNGM(steps=15)
    sim = sc.simulate(run_streams(1, range(4), 0), 4)
    zs = np.array(sim.measurements)
    zs[3, 2] = np.nan
    _step_both(lambda be: pu.PartialUPF(sc.motion, sc.measurement, particles=80, fraction=0.5, backend=be), zs, sim.prior)


def test_discrete_noise_is_compiled_as_the_continuous_model_it_is_replaced_by():
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.01)  # singular Q: the filter runs the CWNA model
    zs, prior = _data(FOUR_ANCHORS)
    _step_both(lambda be: pu.PartialUPF(motion, FOUR_ANCHORS, particles=40, fraction=0.5, backend=be), zs, prior)


@pytest.mark.parametrize("fraction", [0.1, 1.0])
def test_compiled_run_alone_equals_run_in_batch_bitwise(fraction):
    zs, prior = _data(ONE_ANCHOR, M=5)
    filt = pu.PartialUPF(MOTION, ONE_ANCHOR, particles=50, fraction=fraction, backend="numba")
    whole = pu.run(filt, zs, prior, rng=run_streams(9, range(5), 1))
    for i in (0, 3):
        alone = pu.run(filt, zs[:, i : i + 1], prior, rng=run_streams(9, [i], 1))
        assert np.array_equal(alone.mean[:, 0], whole.mean[:, i])
        assert np.array_equal(alone.cov[:, 0], whole.cov[:, i])
        for key in whole.info:
            assert np.array_equal(alone.info[key][:, 0], whole.info[key][:, i], equal_nan=True), key


def test_a_shared_generator_takes_the_numpy_step():
    zs, prior = _data(ONE_ANCHOR)
    a = pu.run(pu.PartialUPF(MOTION, ONE_ANCHOR, particles=30, fraction=0.5), zs, prior, rng=np.random.default_rng(4))
    b = pu.run(pu.PartialUPF(MOTION, ONE_ANCHOR, particles=30, fraction=0.5, backend="numba"), zs, prior, rng=np.random.default_rng(4))
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.cov, b.cov)


def test_unsupported_options_fall_back_with_the_reason():
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.01)
    with pytest.warns(CompiledBackendWarning, match="JitteredMotion.*singular_noise='jitter'"):
        assert not pu.PartialUPF(motion, ONE_ANCHOR, particles=20, singular_noise="jitter", backend="numba").compiled
    sc = UNGM(steps=5)
    with pytest.warns(CompiledBackendWarning, match="cov_mode='propagate' with the nonlinear motion model UNGMMotion"):
        assert not pu.PartialUPF(sc.motion, sc.measurement, particles=20, cov_mode="propagate", backend="numba").compiled
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pu.PartialUPF(sc.motion, sc.measurement, particles=20, backend="numba").compiled
