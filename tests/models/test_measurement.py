"""Measurement models: values, analytic Jacobians against numerical ones, likelihoods, wrapping."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from pursuit._linalg import numerical_jacobian
from pursuit.models import LinearGaussian, RangeBearing, RangeSensors, TimeOfArrival, gaussian_loglik, wrap_angle
from pursuit.models.measurement import measured_somewhere

ANCHORS = np.array([[0.0, 0.0], [50.0, 0.0], [0.0, 50.0]])


def test_range_values():
    m = RangeSensors(ANCHORS, 0.5)
    x = np.array([30.0, 1.0, 40.0, -1.0])
    np.testing.assert_allclose(m.h(x), [50.0, np.hypot(20, 40), np.hypot(30, 10)])
    np.testing.assert_allclose(m.cov(), 0.25 * np.eye(3))


def test_toa_is_range_over_c():
    r = RangeSensors(ANCHORS, 1.0)
    t = TimeOfArrival(ANCHORS, 1e-5, c=1480.0)
    x = np.array([[12.0, 0.0, 7.0, 0.0], [3.0, 1.0, 44.0, 2.0]])
    np.testing.assert_allclose(t.h(x), r.h(x) / 1480.0)
    np.testing.assert_allclose(t.jacobian(x), r.jacobian(x) / 1480.0)


finite = st.floats(-200, 200, allow_nan=False)


@given(st.tuples(finite, finite, finite, finite))
def test_analytic_jacobians_match_numerical_ones(state):
    x = np.array(state)
    for model in (RangeSensors(ANCHORS, 1.0), TimeOfArrival(ANCHORS, 1e-4), RangeBearing([5.0, -3.0], 1.0, 0.01)):
        d = x[[0, 2]] - (ANCHORS if not isinstance(model, RangeBearing) else model.sensor)
        if np.min(np.abs(d)) < 1.0 or np.min(np.hypot(*np.atleast_2d(d).T)) < 1.0:
            continue  # too close to a sensor for finite differences
        J = model.jacobian(x)
        Jn = numerical_jacobian(lambda xs: model.h(xs), x)
        if isinstance(model, RangeBearing):
            Jn = numerical_jacobian(lambda xs: np.unwrap(model.h(xs), axis=-2), x)
        np.testing.assert_allclose(J, Jn, rtol=1e-5, atol=1e-8 * np.max(np.abs(J)))


def test_range_jacobian_at_an_anchor_is_zero_not_nan():
    m = RangeSensors(ANCHORS, 1.0)
    J = m.jacobian(np.array([0.0, 0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(J)) and np.all(J[0] == 0)


def test_bearing_residual_wraps():
    m = RangeBearing([0.0, 0.0], 1.0, 0.1)
    a = np.array([10.0, np.pi - 0.01])
    b = np.array([9.0, -np.pi + 0.01])
    np.testing.assert_allclose(m.residual(a, b), [1.0, -0.02], atol=1e-12)
    assert wrap_angle(np.array([3 * np.pi]))[0] == pytest.approx(-np.pi)


def test_loglik_matches_scipy(rng):
    R = np.array([[2.0, 0.3], [0.3, 1.0]])
    H = rng.standard_normal((2, 4))
    m = LinearGaussian(H, R)
    x = rng.standard_normal((5, 4))
    z = rng.standard_normal(2)
    expected = [stats.multivariate_normal(H @ xi, R).logpdf(z) for xi in x]
    np.testing.assert_allclose(m.loglik(z, x), expected, rtol=1e-12)


def test_loglik_skips_missing_components_with_diagonal_noise():
    res = np.array([1.0, np.nan, -2.0])
    R = np.diag([1.0, 4.0, 2.0])
    expected = stats.norm(0, 1).logpdf(1.0) + stats.norm(0, np.sqrt(2.0)).logpdf(-2.0)
    assert gaussian_loglik(res, R) == pytest.approx(expected)
    with pytest.raises(ValueError, match="diagonal"):
        gaussian_loglik(res, np.array([[1, 0.1, 0], [0.1, 4, 0], [0, 0, 2.0]]))


def _masked_loglik(residual, R):
    """The diagonal-R log-likelihood written the plain way: missing components masked first, then added in order."""
    diag = np.diag(R)
    valid = ~np.isnan(residual)
    r = np.where(valid, residual, 0.0)
    terms = r * r / diag + np.where(valid, np.log(diag) + np.log(2.0 * np.pi), 0.0)
    total = 0.0 + terms[..., 0]
    for j in range(1, terms.shape[-1]):  # in order: a row with a missing component
        total = total + terms[..., j]
    return -0.5 * np.where(valid.all(axis=-1), terms.sum(axis=-1), total)


def test_range_models_measure_a_subset_of_their_anchors_with_the_bits_of_all(rng):
    from pursuit.filters.particle import _has_h_components

    grid = np.array([[x, y] for y in (5.0, 55.0, 105.0, 155.0) for x in (-40.0, 10.0, 60.0, 110.0)])
    X = rng.normal([30.0, 1.0, 80.0, 0.5], 20.0, (6, 50, 4))
    cols = np.array([1, 4, 5, 9, 15])
    for model in (RangeSensors(grid, 0.8), TimeOfArrival(grid, 1e-3)):
        assert np.array_equal(model.h_components(X, 3, cols), model.h(X, 3)[..., cols])
        assert _has_h_components(model)

    class Offset(RangeSensors):  # a user's subclass that changes h alone must not be measured by h_components
        def h(self, x, k=None):
            return super().h(x, k) + 1.0

    assert not _has_h_components(Offset(grid, 0.8)) and not _has_h_components(LinearGaussian(np.eye(2), np.eye(2)))


def test_measured_somewhere_names_the_components_some_run_measured():
    valid = np.zeros((2, 3, 5), dtype=bool)
    valid[0, 1, [1, 3]] = True
    valid[1, 2, 3] = True
    np.testing.assert_array_equal(measured_somewhere(valid), [1, 3])
    assert measured_somewhere(np.ones((4, 5), dtype=bool)) is None  # nothing to leave out
    assert measured_somewhere(np.zeros((4, 5), dtype=bool)) is None  # nothing left: the filters' own rules
    assert measured_somewhere(np.array([True, False])).tolist() == [0]  # one run, unbatched
    assert measured_somewhere(np.zeros((4, 0), dtype=bool)) is None  # no components at all


def test_leaving_out_missing_components_gives_the_bits_of_all_of_them(rng):
    """Sixteen range nodes of which a few measure: the log-likelihood over the measured columns only, summed
    in_order, has the bits of the full width with the others NaN (a row with a missing component is added in
    order, a missing one as +0.0); NumPy's own sum over 16 associates differently."""
    m = 16
    R = np.diag(rng.uniform(0.3, 2.0, m))
    residual = rng.standard_normal((5, 200, m)) * 3.0
    residual[..., [0, 2, 3, 6, 7, 8, 10, 11, 12, 14]] = np.nan  # never measured
    residual[1, :, 5] = np.nan  # and some runs miss more
    residual[4, :, [1, 9]] = np.nan
    kept = measured_somewhere(~np.isnan(residual[:, 0]))
    np.testing.assert_array_equal(kept, [1, 4, 5, 9, 13, 15])
    full = gaussian_loglik(residual, R)
    narrow = gaussian_loglik(residual[..., kept], R[np.ix_(kept, kept)], in_order=True)
    assert np.array_equal(full, narrow)
    assert np.array_equal(full, _masked_loglik(residual, R))
    # a complete row keeps NumPy's sum (its bits as before), in a call with incomplete rows too
    mixed = residual.copy()
    mixed[2] = rng.standard_normal((200, m))
    got = gaussian_loglik(mixed, R)
    assert np.array_equal(got, _masked_loglik(mixed, R))
    assert np.array_equal(got[2], gaussian_loglik(mixed[2], R)) and np.array_equal(got[:2], full[:2])


def test_diagonal_loglik_gives_the_bits_of_masking_first(rng):
    """gaussian_loglik takes the missing components out only where a sum is NaN: the same bits, any layout."""
    R = np.diag([1.0, 4.0, 2.0])
    base = rng.standard_normal((4, 50, 3))
    holed = base.copy()
    holed[1, 7, 1] = np.nan
    holed[3, :, 0] = np.nan
    holed[2, 5] = np.nan  # nothing measured in that row: log-likelihood 0
    cases = {
        "C": base, "F": np.asfortranarray(base), "transposed": rng.standard_normal((3, 50, 4)).T,
        "strided": rng.standard_normal((4, 100, 6))[:, ::2, ::2], "missing": holed,
        "missing, F": np.asfortranarray(holed), "float32": holed.astype(np.float32),
        "broadcast against R": base[..., :1], "overflow": np.where(base > 2.0, 1e200, holed),
    }
    for name, residual in cases.items():
        with np.errstate(over="ignore"):  # 1e200² overflows to inf in both, as it should
            got, want = gaussian_loglik(residual, R), _masked_loglik(residual, R)
        assert got.dtype == want.dtype and got.shape == want.shape, name
        assert np.array_equal(got, want), name
    scale = np.sqrt(np.diag(R))
    want = np.where(np.isnan(holed), 0.0, stats.norm(0, scale).logpdf(np.nan_to_num(holed))).sum(axis=-1)
    np.testing.assert_allclose(gaussian_loglik(holed, R), want, rtol=1e-12)
    assert gaussian_loglik(holed, R)[2, 5] == 0.0
    assert gaussian_loglik(np.array([1, 2, 0]), R) == gaussian_loglik(np.array([1.0, 2.0, 0.0]), R)  # integer residuals
    # a zero variance (no valid covariance, but no crash either): the missing term is 0/0 as when masking first
    degenerate = np.diag([1.0, 0.0, 2.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        np.testing.assert_array_equal(gaussian_loglik(holed, degenerate), _masked_loglik(holed, degenerate))


def test_samples_have_the_model_noise(rng):
    m = RangeSensors(ANCHORS, [0.5, 1.0, 2.0])
    x = np.tile([10.0, 0.0, 20.0, 0.0], (100_000, 1))
    d = m.sample(x, 1, rng) - m.h(x)
    np.testing.assert_allclose(d.std(axis=0), [0.5, 1.0, 2.0], rtol=0.02)


def test_position_helper():
    m = LinearGaussian.position(6, (0, 2, 4), [1.0, 2.0, 3.0])
    assert m.matrix().shape == (3, 6)
    np.testing.assert_array_equal(m.h(np.arange(6.0)), [0.0, 2.0, 4.0])
    np.testing.assert_allclose(np.diag(m.cov()), [1.0, 4.0, 9.0])


@pytest.mark.parametrize(
    "build,field",
    [
        (lambda: RangeSensors(ANCHORS, -1.0), "sigma"),
        (lambda: RangeSensors(ANCHORS, [1.0, 2.0]), "sigma"),
        (lambda: RangeSensors(np.zeros((2, 3)), 1.0), "anchors"),
        (lambda: TimeOfArrival(ANCHORS, 1e-5, c=0.0), "c"),
        (lambda: LinearGaussian([[1.0, 0.0]], [[-1.0]]), "R"),
        (lambda: LinearGaussian([[1.0, 0.0]], [[1.0, 0.5], [0.5, 1.0]]), "R"),
        (lambda: LinearGaussian([[1.0, np.nan]], [[1.0]]), "H"),
        (lambda: RangeBearing([0.0], 1.0, 0.1), "sensor"),
        (lambda: LinearGaussian.position(4, (0, 2), -1.0), "sigma"),
        (lambda: LinearGaussian.position(4, (0, 2), [1.0, 0.0]), "sigma"),
        (lambda: LinearGaussian.position(4, (0, 2), [1.0, 2.0, 3.0]), "sigma"),
        (lambda: LinearGaussian.position(4, (0, 2), np.nan), "sigma"),
        (lambda: LinearGaussian.position(4, (0, 4), 1.0), "position_indices"),
        (lambda: LinearGaussian.position(0, (), 1.0), "state_dim"),
    ],
)
def test_bad_parameters_name_the_field(build, field):
    with pytest.raises(ValueError, match=f"^{field}"):
        build()
