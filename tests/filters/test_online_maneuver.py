"""The one-run step (batch ``()``) of the CS-family filters and the IMM against their general step.

``step`` on one run without a batch axis takes a lean path (``(A, 3)`` stacks
of the axes, closed-form scalar updates, the series of F, U and q as one
product for per-axis α; for the IMM the modes as one stacked array); every
batch, ``(1,)`` included, takes the general step, so that a run keeps its
bits alone in a Monte Carlo chunk of one.  From the same state and
measurement both must give the same estimate and the same info (keys,
shapes, dtypes) to 1e-12 relative (each key against its own largest
magnitude), in every situation the step meets: missing components, all-NaN
steps, a gate rejecting an outlier, a given dt, each adaptation variant, α
beyond the series range.
"""

from __future__ import annotations

from dataclasses import fields, is_dataclass, replace

import numpy as np
import pytest

import pursuit as pu
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, InteractingMultipleModel, ModifiedSingerFilter
from pursuit.filters.cs import AxisState, _matrices_for, _matrices_one_run
from pursuit.filters.imm import kinematic_map
from pursuit.models import ConstantVelocity, LinearGaussian, Singer

RTOL = 1e-12
STEPS = 70
SINGER = Singer(alpha=1 / 10, sigma=2.0, ndim=3)
MEAS = LinearGaussian.position(9, SINGER.position_indices, 2.0)
X0 = np.array([10.0, 3.0, 0.0, -20.0, 2.0, 0.0, 5.0, -4.0, 0.0])  # near the origin: ulps of the positions stay small
PRIOR = pu.Gaussian(X0 + 1.0, np.diag([25.0, 9.0, 4.0] * 3))


def _measurements(seed: int = 0) -> np.ndarray:
    """(STEPS, 3) position fixes of a maneuvering Singer track, with gaps, partly missing fixes and an outlier."""
    rng = np.random.default_rng(seed)
    x, out = X0.copy(), []
    for k in range(1, STEPS + 1):
        x = SINGER.sample(x, k, rng)
        if 25 <= k < 35:  # a hard turn on the first axis
            x[2] = 12.0
        out.append(MEAS.sample(x, k, rng))
    zs = np.array(out)
    zs[7] = np.nan  # all missing
    zs[8] = np.nan
    zs[15, 1] = np.nan  # one component missing
    zs[16, [0, 2]] = np.nan  # two missing
    zs[50, 2] += 400.0  # an outlier (a gate rejects it)
    return zs


def _assert_close(a, b, what, floor: float = 1e-300):
    """Equal to RTOL relative to the largest magnitude of ``b`` (at least ``floor``); NaN where ``b`` has NaN."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype, f"{what}: dtype {a.dtype} != {b.dtype}"
    assert a.shape == b.shape, f"{what}: shape {a.shape} != {b.shape}"
    if a.dtype == bool or np.issubdtype(a.dtype, np.integer):
        np.testing.assert_array_equal(a, b, err_msg=what)
        return
    scale = np.nanmax(np.abs(b)) if np.isfinite(b).any() else 0.0
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * max(scale, floor), equal_nan=True, err_msg=what)


def _batched(state, axis: bool):
    """``state`` with a batch axis of one run added (``axis``) or removed, recursively through IMM and mode states."""
    def conv(a):
        return np.asarray(a)[None] if axis else np.asarray(a)[0]

    if isinstance(state, dict):
        return {k: conv(v) for k, v in state.items()}
    if is_dataclass(state):
        changes = {}
        for f in fields(state):
            v = getattr(state, f.name)
            if f.name in ("mean", "cov", "probs"):
                changes[f.name] = conv(v)
            elif f.name == "modes":
                changes[f.name] = tuple(_batched(s, axis) for s in v)
            elif f.name == "memory" and isinstance(v, dict):
                changes[f.name] = _batched(v, axis)
        return replace(state, **changes)
    raise TypeError(type(state))


def _compare(filt, state, z, dt):
    """One step of the one-run path and of the general step (batch (1,)) from ``state``; the one-run result."""
    fast_state, fast = filt.step(state, z, dt=dt)
    ref_state, ref = filt.step(_batched(state, True), z[None], dt=dt)
    ref_state = _batched(ref_state, False)
    k = fast_state.k
    assert ref_state.k == k == state.k + 1
    for name in ("mean", "cov", "probs"):
        if hasattr(fast_state, name):
            _assert_close(getattr(fast_state, name), getattr(ref_state, name), f"step {k}: {name}")
    for key, v in getattr(fast_state, "memory", {}).items():
        _assert_close(v, ref_state.memory[key], f"step {k}: memory[{key!r}]")
    assert set(fast) == set(ref), f"step {k}: info keys {set(fast) ^ set(ref)}"
    for key in ref:
        # A log-likelihood is a sum of terms of order 1 (log c̄_j, log 2π): at least that is its scale.
        floor = 1.0 if "loglik" in key else 1e-300
        _assert_close(fast[key], np.asarray(ref[key])[0], f"step {k}: info[{key!r}]", floor)
    return fast_state, fast


def _sequence(filt, zs, dts):
    state = filt.init(PRIOR)
    infos = []
    for z, dt in zip(zs, dts):
        state, info = _compare(filt, state, z, dt)
        infos.append(info)
    return infos


def _dts(irregular: bool):
    return np.random.default_rng(3).uniform(0.3, 2.0, STEPS) if irregular else [None] * STEPS


AXIS_CASES = [
    (CurrentStatisticalFilter, {}),
    (CurrentStatisticalFilter, {"mean": "zero", "a_neg_max": 50.0, "sigma_min": 1.0, "gate": 0.999}),
    (AdaptiveCSFilter, {}),
    (AdaptiveCSFilter, {"variance": "linear", "fading": "ratio", "alpha_rule": "fading"}),
    (AdaptiveCSFilter, {"variance": "rayleigh", "fading": "none", "alpha_rule": "none", "gate": 0.999}),
    (AdaptiveCSFilter, {"variance": "fixed", "sigma_a": 5.0, "sigma_max": 30.0, "mean": "zero", "false_alarm": 0.05}),
    # α beyond the series range (αT > 1) on detections: the general matrices
    (AdaptiveCSFilter, {"alpha0": 0.2, "alpha_cap": 5.0, "threshold": 1.0, "beta_s": 1.5}),
    (ModifiedSingerFilter, {}),
    (ModifiedSingerFilter, {"forgetting": 0.9, "warmup": 0, "gate": 0.999}),
    (ModifiedSingerFilter, {"tau_min": 0.2, "alpha_init": 2.0}),  # α = 5 (β at its floor): beyond the series range
]


@pytest.mark.parametrize("irregular", [False, True], ids=["dt-model", "dt-given"])
@pytest.mark.parametrize("cls,kw", AXIS_CASES, ids=[f"{c.__name__}-{'-'.join(kw) or 'plain'}" for c, kw in AXIS_CASES])
def test_axis_filter_one_run_step_equals_the_general_step(cls, kw, irregular):
    filt = cls(MEAS, **kw)
    infos = _sequence(filt, _measurements(), _dts(irregular))
    assert int(infos[7]["dof"]) == 0 and np.isnan(infos[7]["nis"]) and float(infos[7]["loglik"]) == 0.0
    assert int(infos[15]["dof"]) == 2 and np.isnan(infos[15]["innovation"][1])
    if "gate" in kw:
        assert any(bool(i["gated"]) for i in infos)  # the outlier was rejected
    if cls is AdaptiveCSFilter and kw.get("fading") != "none":
        assert any(i["maneuver"].any() for i in infos)  # the turn was detected: λ and α adapted
    alphas = np.array([i["alpha"] for i in infos])
    if (cls is ModifiedSingerFilter and "tau_min" not in kw) or (cls is AdaptiveCSFilter and kw.get("alpha_rule") != "none"):
        assert np.any(alphas.max(axis=1) != alphas.min(axis=1))  # the per-axis α path was exercised


IMM_CASES = ["singer", "singer-gate", "cs-family", "cv-in-singer", "unreachable-mode"]


def _imm(case: str):
    modes = ((1 / 60, 5.0), (1 / 20, 20.0), (1 / 5, 60.0))
    if case.startswith("singer"):
        kfs = [pu.KalmanFilter(Singer(alpha=a, sigma=s, ndim=3), MEAS, backend="numpy") for a, s in modes]
        return InteractingMultipleModel(kfs, 0.95, gate=0.999 if case.endswith("gate") else None)
    if case == "cs-family":
        fs = [CurrentStatisticalFilter(MEAS), AdaptiveCSFilter(MEAS), ModifiedSingerFilter(MEAS)]
        return InteractingMultipleModel(fs, 0.9, gate=0.999)
    if case == "cv-in-singer":
        cv = ConstantVelocity(ndim=3, dt=1.0, q=0.5, noise="continuous")
        cv_kf = pu.KalmanFilter(cv, LinearGaussian.position(6, cv.position_indices, 2.0), backend="numpy")
        singer_kf = pu.KalmanFilter(SINGER, MEAS, backend="numpy")
        return InteractingMultipleModel([cv_kf, singer_kf], 0.9, maps=[kinematic_map(cv, SINGER, 4.0), None])
    # a mode that nothing can reach (c̄ = 0): the mixing weights fall back to μ
    kfs = [pu.KalmanFilter(Singer(alpha=a, sigma=s, ndim=3), MEAS, backend="numpy") for a, s in modes[:2]]
    return InteractingMultipleModel(kfs, np.eye(2), initial_probs=[1.0, 0.0])


@pytest.mark.parametrize("irregular", [False, True], ids=["dt-model", "dt-given"])
@pytest.mark.parametrize("case", IMM_CASES)
def test_imm_one_run_step_equals_the_general_step(case, irregular):
    filt = _imm(case)
    infos = _sequence(filt, _measurements(), _dts(irregular))
    assert int(infos[8]["dof"]) == 0 and np.isnan(infos[8]["nis"])
    assert int(infos[16]["dof"]) == 1
    if case == "singer-gate":  # (with the CS family, APCS's fading keeps the outlier inside its gate)
        assert any(bool(i["gated"]) for i in infos)
    if case == "unreachable-mode":
        assert all(float(i["mode_probs"][1]) == 0.0 for i in infos)
    else:
        probs = np.array([i["mode_probs"] for i in infos])
        assert probs.argmax(axis=1).min() != probs.argmax(axis=1).max()  # the modes took turns


@pytest.mark.parametrize("make", [lambda: AdaptiveCSFilter(MEAS, gate=0.999), lambda: ModifiedSingerFilter(MEAS), lambda: _imm("singer-gate")])
def test_a_batch_of_one_equals_the_same_run_in_a_batch_of_three_bit_for_bit(make):
    """A batch (1,) takes the general step: a Monte Carlo chunk of one run must not change a bit."""
    filt = make()
    zs = np.stack([_measurements(seed) for seed in range(3)], axis=1)  # (STEPS, 3, m)
    three, one = filt.init(PRIOR, batch=(3,)), filt.init(PRIOR, batch=(1,))
    for z in zs:
        three, _ = filt.step(three, z)
        one, _ = filt.step(one, z[2:3])
        assert np.array_equal(one.mean[0], three.mean[2]) and np.array_equal(one.cov[0], three.cov[2])


@pytest.mark.parametrize("make", [lambda: AdaptiveCSFilter(MEAS), lambda: _imm("singer")])
def test_the_one_run_path_runs_and_batches_take_the_general_one(make, monkeypatch):
    filt = make()
    cls = type(filt)
    general = cls._general_step

    def boom(*a, **k):
        raise AssertionError("general step called")

    monkeypatch.setattr(cls, "_general_step", boom)
    state = filt.init(PRIOR)
    for z in _measurements()[:10]:
        state, _ = filt.step(state, z)
    with pytest.raises(AssertionError, match="general step"):
        filt.step(filt.init(PRIOR, batch=(1,)), np.zeros((1, 3)))
    monkeypatch.setattr(cls, "_general_step", general)


@pytest.mark.parametrize("dt", [0.05, 1.0, 3.0])
def test_series_matrices_of_one_run_equal_the_model_functions(dt):
    """F, U, q of per-axis α by the product of powers = the Horner series of pursuit.models.maneuver, to a few ulps."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        alpha = np.exp(rng.uniform(np.log(1e-7), np.log(2.0 / dt), 3))  # up to αT = 2: the fallback too
        for got, want in zip(_matrices_one_run(alpha, dt), _matrices_for(alpha, dt)):
            assert got.shape[-2:] == want.shape[-2:]
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)
    same = _matrices_one_run(np.full(3, 0.01), dt)  # equal α: the cached, shared matrices
    assert same[0].shape == (3, 3) and not same[0].flags.writeable


@pytest.mark.parametrize("make", [lambda: CurrentStatisticalFilter(MEAS), lambda: _imm("singer")])
def test_one_run_measurement_checks_stay(make):
    filt = make()
    state = filt.init(PRIOR)
    with pytest.raises(ValueError, match="z: expected shape"):
        filt.step(state, np.zeros(2))
    with pytest.raises(ValueError, match="infinity"):
        filt.step(state, np.array([np.inf, 0.0, 0.0]))
    new, _ = filt.step(state, [1, 2, 3])  # lists and integers are still accepted
    assert new.mean.shape == (9,)
    assert isinstance(filt.step(state, np.zeros(3))[0], type(state))


def test_one_run_state_is_not_shared_with_the_info():
    """The state a step returns must not alias arrays of its info (a caller may modify either)."""
    filt = AdaptiveCSFilter(MEAS, gate=0.999)
    state = filt.init(PRIOR)
    for z in _measurements():
        state, info = filt.step(state, z)
        for key in ("pred_mean", "pred_cov", "cross_cov"):
            assert not np.shares_memory(state.mean, info[key]) and not np.shares_memory(state.cov, info[key])
        assert isinstance(state, AxisState)


def test_a_subclass_with_its_own_prediction_hook_keeps_the_general_step():
    """A user's ``_predict`` written for the general step (seven arguments) is never handed the one-run step's eighth."""

    class Damped(CurrentStatisticalFilter):
        def _predict(self, memory, x, P, z, measured, r, T):
            return super()._predict(memory, x, P, z, measured, r, T)

    filt, ref = Damped(MEAS), CurrentStatisticalFilter(MEAS)
    a, b = filt.init(PRIOR), ref.init(PRIOR, batch=(1,))
    for z in _measurements()[:12]:
        a, _ = filt.step(a, z)
        b, _ = ref.step(b, z[None])
        np.testing.assert_array_equal(a.mean, b.mean[0])  # the general step's bits: batch (1,) takes it too
