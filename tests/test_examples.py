"""The documented examples run and do what the docs say."""

import importlib.util
import sys
from pathlib import Path

import numpy as np

from pursuit._linalg import numerical_jacobian
from pursuit.filters.gaussian import measurement_jacobian

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # dataclasses look their module up while the file runs
    spec.loader.exec_module(mod)
    return mod


def test_bearings_only_user_model_runs_through_the_engine(capsys):
    mod = _load("bearings_only")
    result = mod.main(runs=60)
    assert "EKF" in capsys.readouterr().out
    for name in ("EKF", "UKF", "CKF"):
        # the prior's position standard deviation is 5 m; tracking must do much better
        assert result.rmse(name, "position") < 2.5
        c = result.consistency(name)
        assert c["anees_inside"] > 0.8


def test_user_model_without_jacobian_gets_the_analytic_one_numerically():
    mod = _load("bearings_only")
    sc = mod.BearingsScenario()
    x = np.array([[50.0, 1.0, 150.0, 0.0], [120.0, 0.0, 80.0, 1.0]])
    J = measurement_jacobian(sc.measurement, x, 1)
    # analytic: d atan2(dy, dx) = (-dy dx' + dx dy') / r^2
    for i, s in enumerate(sc.measurement.sensors):
        dx, dy = x[:, 0] - s[0], x[:, 2] - s[1]
        r2 = dx**2 + dy**2
        np.testing.assert_allclose(J[:, i, 0], -dy / r2, rtol=1e-7)
        np.testing.assert_allclose(J[:, i, 2], dx / r2, rtol=1e-7)
        assert np.all(J[:, i, [1, 3]] == 0)
    # the EKF's fallback is central differences through the model's residual (bearings wrap at ±π)
    np.testing.assert_array_equal(J, numerical_jacobian(lambda xs: sc.measurement.h(xs), x, residual=sc.measurement.residual))
