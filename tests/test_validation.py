"""Shared input checks (pursuit._validation): the measurement infinity checks the filters use."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit._validation import no_infinite_measurement, no_infinite_measurements


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
