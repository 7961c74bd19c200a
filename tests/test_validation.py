"""Shared input checks (pursuit._validation): the measurement infinity checks the filters use."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit._validation import no_infinite_measurement, no_infinite_measurements, state_of_size


def test_an_infinite_measurement_names_its_step_and_nan_passes():
    no_infinite_measurement(np.array([1.0, np.nan]), 3)
    with pytest.raises(ValueError, match=r"^step 3: measurement contains infinity \(use NaN for a missing value\)$"):
        no_infinite_measurement(np.array([1.0, -np.inf]), 3)


def test_a_sequence_names_the_first_infinite_step():
    zs = np.zeros((6, 4, 2))
    zs[1, 0, 0] = np.nan
    no_infinite_measurements(zs)
    no_infinite_measurements(np.zeros((0, 4, 2)))
    zs[4, 2, 1] = np.inf
    zs[5, 0, 0] = -np.inf
    with pytest.raises(ValueError, match="^step 5: measurement contains infinity"):
        no_infinite_measurements(zs)


def test_a_measurement_of_the_wrong_size_names_step_argument_and_shapes():
    from pursuit._validation import measurement_for_step

    with pytest.raises(ValueError, match=r"^step 3: z: expected shape \(5, 2\) \(m = 2 components per measurement\), got \(5, 3\)$"):
        measurement_for_step(np.zeros((5, 3)), (5,), 2, 3)
    with pytest.raises(ValueError, match=r"^step 1: z: expected shape \(5, 2\) for a batch of \(5,\), got \(4, 2\)$"):
        measurement_for_step(np.zeros((4, 2)), (5,), 2, 1)
    assert measurement_for_step(np.zeros(2), (5,), 2, 1).shape == (5, 2)  # one measurement for every run
    assert measurement_for_step(1.5, (), None, 1).shape == (1,)


def test_a_prior_of_the_wrong_size_names_the_model_and_both_sizes():
    from pursuit._validation import prior_of_size
    from pursuit.models import ConstantVelocity

    prior_of_size(4, 4, ConstantVelocity())
    prior_of_size(3, None, object())  # a user's model that declares no dim
    with pytest.raises(ValueError, match=r"^prior: expected 4 state components for the ConstantVelocity motion model .*got 3$"):
        prior_of_size(3, 4, ConstantVelocity())


@pytest.mark.parametrize("dt", [-1.0, 0.0, float("nan"), float("inf"), True, "1"])
def test_a_time_step_that_is_not_a_positive_finite_number_names_the_step(dt):
    from pursuit._validation import time_step

    with pytest.raises(ValueError, match=r"^step 4: dt: "):
        time_step(dt, 4)


def test_a_positive_time_step_passes_and_none_means_the_models_own():
    from pursuit._validation import time_step

    assert time_step(None, 1) is None and time_step(2, 1) == 2.0 and time_step(np.float32(0.5), 1) == 0.5


def test_a_measurement_too_large_to_square_names_its_step_component_and_the_limit():
    from pursuit._validation import MAX_MEASUREMENT

    assert np.isfinite(MAX_MEASUREMENT**2 * 2.0**23)  # the documented headroom: squares and sums of them stay finite
    no_infinite_measurement(np.array([MAX_MEASUREMENT, -MAX_MEASUREMENT, np.nan]), 2)  # the limit itself is accepted
    with pytest.raises(ValueError, match=r"^step 7: measurement z\[1\] = -1e\+300 is beyond ±2\^500 ≈ 3\.27e\+150"):
        no_infinite_measurement(np.array([1.0, -1e300]), 7)
    zs = np.zeros((4, 3, 2))
    zs[2, 1, 0] = 1e200
    with pytest.raises(ValueError, match=r"^step 3: measurement z\[1, 0\] = 1e\+200 is beyond"):
        no_infinite_measurements(zs)


def test_a_time_step_whose_fifth_power_overflows_names_the_step_and_the_limit():
    # dt = 1e300 raised Python's OverflowError ("Numerical result out of range") inside the motion models
    from pursuit._validation import MAX_TIME_STEP, time_step
    from pursuit.models import ConstantAcceleration

    with pytest.raises(ValueError, match=r"^step 4: dt: 1e\+300 s is beyond 2\^200 ≈ 1\.61e\+60 s"):
        time_step(1e300, 4)
    assert time_step(MAX_TIME_STEP, 4) == MAX_TIME_STEP
    # at the limit the largest power the models take (dt⁵ of the continuous-noise CA model) is finite
    Q = ConstantAcceleration(ndim=1, q=1.0, noise="continuous").cov(1, MAX_TIME_STEP)
    assert np.all(np.isfinite(Q))


def test_a_state_of_the_wrong_size_names_the_model_size_and_every_shape():
    from types import SimpleNamespace

    gauss = SimpleNamespace(mean=np.zeros((2, 4)), cov=np.zeros((2, 4, 4)))
    state_of_size(gauss, 4)
    state_of_size(gauss, None)  # a user's model that does not say its size: nothing to check
    for n in (3, 5):
        with pytest.raises(ValueError, match=rf"state: the filter's model has {n} states, got mean \(2, 4\), cov \(2, 4, 4\)$"):
            state_of_size(gauss, n)
    with pytest.raises(ValueError, match=r"got mean \(4,\), cov \(3, 3\)"):  # the covariance alone is wrong
        state_of_size(SimpleNamespace(mean=np.zeros(4), cov=np.zeros((3, 3))), 4)
    cloud = SimpleNamespace(particles=np.zeros((2, 50, 3)), mean=np.zeros((2, 4)), cov=np.zeros((2, 4, 4)))
    with pytest.raises(ValueError, match=r"got mean \(2, 4\), cov \(2, 4, 4\), particles \(2, 50, 3\)"):
        state_of_size(cloud, 4)


def test_the_sequence_check_passes_missing_values_and_catches_a_bad_value_anywhere():
    """The fast whole-array bounds (NaN skipped) agree with the step-by-step check: all-NaN and the limit itself pass,
    one value beyond ±2^500 or one infinity anywhere (first or last step, either sign) names its step."""
    from pursuit._validation import MAX_MEASUREMENT

    no_infinite_measurements(np.full((3, 2, 2), np.nan))  # nothing measured: passes
    no_infinite_measurements(np.array([[[MAX_MEASUREMENT, -MAX_MEASUREMENT]]]))
    no_infinite_measurements(np.arange(12).reshape(3, 2, 2))  # integers
    for step, value in [(0, np.inf), (0, -np.inf), (5, 1e151), (5, -1e151)]:
        zs = np.full((6, 3, 2), np.nan)
        zs[step, 2, 1] = value
        with pytest.raises(ValueError, match=f"^step {step + 1}: measurement"):
            no_infinite_measurements(zs)
