"""Small batched linear algebra: closed forms against LAPACK, repair, batch invariance."""

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pursuit._linalg import cholesky_psd, inv_spd, is_shared, logdet_spd, numerical_jacobian, psd_factor, quad, quadratic_form


@given(st.integers(1, 5), st.integers(0, 2**31 - 1))
def test_closed_form_inverse_and_logdet_match_numpy(m, seed):
    r = np.random.default_rng(seed)
    A = r.standard_normal((6, m, m))
    S = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(m)
    np.testing.assert_allclose(inv_spd(S), np.linalg.inv(S), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(logdet_spd(S), np.linalg.slogdet(S)[1], rtol=1e-10, atol=1e-10)


def test_inverse_is_batch_invariant_bitwise(rng):
    A = rng.standard_normal((50, 3, 3))
    S = A @ np.swapaxes(A, -1, -2) + np.eye(3)
    full = inv_spd(S)
    for i in range(0, 50, 7):
        np.testing.assert_array_equal(inv_spd(S[i : i + 7]), full[i : i + 7])


@given(st.integers(1, 6), st.integers(0, 2**31 - 1))
def test_quadratic_form_matches_einsum(n, seed):
    """x^T A x for a batch of vectors against one shared matrix, and against a matrix per vector (broadcast)."""
    r = np.random.default_rng(seed)
    x = r.standard_normal((3, 5, n))
    A_shared = r.standard_normal((n, n))
    A_each = r.standard_normal((5, n, n))  # broadcast over the leading axis of x
    np.testing.assert_allclose(quadratic_form(x, A_shared), np.einsum("...i,ij,...j->...", x, A_shared, x), rtol=1e-12, atol=1e-12)
    want = np.einsum("bki,kij,bkj->bk", x, A_each, x)
    np.testing.assert_allclose(quadratic_form(x, A_each), want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(quad(x, np.broadcast_to(A_each, (3, 5, n, n))), want, rtol=1e-12, atol=1e-12)


def test_quadratic_form_is_batch_invariant_bitwise_and_keeps_nan(rng):
    x = rng.standard_normal((40, 7, 3))
    A = rng.standard_normal((40, 1, 3, 3))
    full = quadratic_form(x, A)
    assert full.shape == (40, 7)
    for i in range(0, 40, 9):
        np.testing.assert_array_equal(quadratic_form(x[i : i + 9], A[i : i + 9]), full[i : i + 9])
    x[3, 2, 1] = np.nan
    out = quadratic_form(x, A)
    assert np.isnan(out[3, 2]) and np.isfinite(np.delete(out.ravel(), 3 * 7 + 2)).all()


def test_quadratic_form_passes_inf_and_nan_through_without_warnings_and_leaves_its_inputs():
    """As einsum did: an overflow gives inf, an inf input NaN or inf, with no RuntimeWarning (errors in pursuit's tests)."""
    x = np.array([[1e200, 1e200], [np.inf, 1.0], [1.0, 2.0]])
    A = np.eye(2)
    x0, A0 = x.copy(), A.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = quadratic_form(x, A)
    with np.errstate(all="ignore"):
        want = np.einsum("...i,ij,...j->...", x, A, x)
    np.testing.assert_array_equal(got, want)
    assert np.isinf(got[0]) and got[2] == 5.0
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(A, A0)


def test_quadratic_form_rejects_mismatched_sizes_and_sums_nothing_for_n_0():
    with pytest.raises(ValueError, match="A must end in"):
        quadratic_form(np.ones((4, 3)), np.ones((2, 2)))
    assert np.array_equal(quadratic_form(np.ones((4, 0)), np.ones((0, 0))), np.zeros(4))


def test_cholesky_psd_repairs_only_broken_matrices():
    good = np.array([[2.0, 0.5], [0.5, 1.0]])
    bad = np.array([[1.0, 1.0], [1.0, 1.0 - 1e-13]])  # slightly indefinite from round-off
    L, repaired = cholesky_psd(np.stack([good, bad]))
    assert repaired.tolist() == [False, True]
    np.testing.assert_array_equal(L[0], np.linalg.cholesky(good))
    np.testing.assert_allclose(L[1] @ L[1].T, bad, atol=1e-10)


def test_psd_factor_of_a_singular_covariance():
    G = np.array([[0.5], [1.0]])
    Q = G @ G.T
    F = psd_factor(Q)
    assert F.shape == (2, 1)
    np.testing.assert_allclose(F @ F.T, Q, atol=1e-15)
    with pytest.raises(ValueError, match="semidefinite"):
        psd_factor(np.array([[1.0, 0.0], [0.0, -1.0]]))
    with pytest.raises(ValueError, match="symmetric"):
        psd_factor(np.array([[1.0, 0.5], [0.0, 1.0]]))


def test_numerical_jacobian_of_a_known_function():
    def f(x):
        return np.stack([x[..., 0] ** 2 * x[..., 1], np.sin(x[..., 1])], axis=-1)

    x = np.array([[1.5, 0.3], [-2.0, 1.0]])
    J = numerical_jacobian(f, x)
    expected = np.array([[[2 * x0 * x1, x0**2], [0.0, np.cos(x1)]] for x0, x1 in x])
    np.testing.assert_allclose(J, expected, rtol=1e-8, atol=1e-10)


def test_is_shared_detects_broadcast_views():
    P = np.eye(3)
    assert is_shared(np.broadcast_to(P, (5, 3, 3)), 2)
    assert not is_shared(np.broadcast_to(P, (5, 3, 3)).copy(), 2)
    assert is_shared(P, 2)


@pytest.mark.parametrize("m", [2, 3])
def test_ill_conditioned_spd_matrices_fall_back_to_lapack(m, rng):
    # eigenvalues met by a UKF with λ = 1e4 on the TOA scenario: 56, 1314, 4.3e11 (condition 1e10)
    w = np.array([56.0, 1314.0, 4.3e11])[-m:] if m == 3 else np.array([56.0, 4.3e11])
    V = np.linalg.qr(rng.standard_normal((200, m, m)))[0]
    S = np.einsum("bij,j,bkj->bik", V, w, V)
    S = 0.5 * (S + np.swapaxes(S, 1, 2))
    if m == 3:
        a = S
        det = (
            a[:, 0, 0] * (a[:, 1, 1] * a[:, 2, 2] - a[:, 1, 2] * a[:, 2, 1])
            - a[:, 0, 1] * (a[:, 1, 0] * a[:, 2, 2] - a[:, 1, 2] * a[:, 2, 0])
            + a[:, 0, 2] * (a[:, 1, 0] * a[:, 2, 1] - a[:, 1, 1] * a[:, 2, 0])
        )
    else:
        det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    # many take the fallback; for 3x3 the cofactor determinant even loses its sign on some
    assert np.mean(det < 1e-6 * np.prod(np.diagonal(S, axis1=1, axis2=2), axis=1)) > 0.5
    assert m == 2 or np.any(det <= 0)
    np.testing.assert_allclose(logdet_spd(S), np.linalg.slogdet(S)[1], rtol=1e-6)
    inv = inv_spd(S)
    # S is SPD, so its inverse's quadratic form on its own eigenvectors must be positive and finite
    assert np.all(np.isfinite(inv))
    w, V = np.linalg.eigh(S)
    np.testing.assert_allclose(np.einsum("bij,bjk,bki->bi", np.swapaxes(V, 1, 2), inv, V), 1.0 / w, rtol=1e-4)


def test_well_conditioned_matrices_keep_the_closed_form_unbatched_too(rng):
    A = rng.standard_normal((20, 3, 3))
    S = A @ np.swapaxes(A, 1, 2) + np.eye(3)
    np.testing.assert_allclose(inv_spd(S), np.linalg.inv(S), rtol=1e-10)
    np.testing.assert_allclose(logdet_spd(S), np.linalg.slogdet(S)[1], rtol=1e-12)
    assert np.isfinite(logdet_spd(S[0])) and inv_spd(S[0]).shape == (3, 3)


def _spd(eigenvalues, rng, batch=50):
    """SPD matrices with known eigenvalues and random eigenvectors."""
    m = len(eigenvalues)
    Q, _ = np.linalg.qr(rng.standard_normal((batch, m, m)))
    S = Q @ (np.asarray(eigenvalues)[:, None] * np.swapaxes(Q, -1, -2))
    return 0.5 * (S + np.swapaxes(S, -1, -2)), Q


@pytest.mark.parametrize("m", [2, 3, 4])
def test_inverse_and_logdet_stay_accurate_with_two_tiny_eigenvalues(m, rng):
    # Three precise TOA sensors and a target known much better along some directions give S
    # with eigenvalues like (0.6, 1e-12, 1e-12): the 3x3 cofactor determinant errs by eps·κ²
    # and flips sign; the fallback must keep the inverse and log-determinant accurate.
    w = np.array([0.6] + [1e-12] * (m - 1))
    S, Q = _spd(w, rng)
    true_logdet = np.sum(np.log(w))
    np.testing.assert_allclose(logdet_spd(S), true_logdet, rtol=1e-3)
    true_inv = Q @ ((1.0 / w)[:, None] * np.swapaxes(Q, -1, -2))
    err = np.max(np.abs(inv_spd(S) - true_inv)) / np.max(np.abs(true_inv))
    assert err < 1e-2


def _bearing(xs):
    """Bearing (rad) of a 2-D point seen from the origin."""
    return np.arctan2(xs[..., 1], xs[..., 0])[..., None]


def _wrap(a, b):
    return (a - b + np.pi) % (2 * np.pi) - np.pi


def test_numerical_jacobian_differences_through_the_residual_at_the_angle_cut():
    # a target at (-100, 1e-6) sits on the ±π cut: the perturbed bearings straddle it
    x = np.array([[-100.0, 1e-6], [50.0, 80.0]])
    r2 = x[:, 0] ** 2 + x[:, 1] ** 2
    exact = np.stack([-x[:, 1] / r2, x[:, 0] / r2], axis=-1)[:, None, :]  # d atan2(y, x)
    raw = numerical_jacobian(_bearing, x)
    assert abs(raw[0, 0, 1]) > 1e5  # plain differences jump by 2π over the cut (5.2e5 instead of -0.01)
    J = numerical_jacobian(_bearing, x, residual=_wrap)
    np.testing.assert_allclose(J, exact, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(J[1], raw[1])  # away from the cut the wrap changes nothing


def test_sensor_stack_without_jacobian_uses_each_parts_residual():
    from pursuit.models.sensors import StackedMeasurement

    class Bearings:  # a user's bearing model: h and residual, no jacobian
        dim = 1

        def h(self, x, k=None):
            return _bearing(x[..., [0, 2]])

        def residual(self, a, b):
            return _wrap(a, b)

        def cov(self, k=None):
            return np.eye(1)

    class Ranges:
        dim = 1

        def h(self, x, k=None):
            return np.hypot(x[..., 0], x[..., 2])[..., None]

        def cov(self, k=None):
            return np.eye(1)

    model = StackedMeasurement((Bearings(), Ranges()))
    x = np.array([[-100.0, 1.0, 1e-6, 0.0]])
    J = model.jacobian(x, 1)
    np.testing.assert_allclose(J[0, 0], [-1e-6 / 1e4, 0.0, -0.01, 0.0], rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(J[0, 1], [-1.0, 0.0, 1e-8, 0.0], rtol=1e-6, atol=1e-9)  # d r = (x, y) / r


def test_ekf_jacobian_of_a_user_bearing_model_at_the_cut():
    from pursuit.filters.gaussian import measurement_jacobian

    class TwoBearings:
        sensors = np.array([[0.0, 0.0], [200.0, 0.0]])

        def h(self, x, k=None):
            return np.arctan2(x[..., None, 2] - self.sensors[:, 1], x[..., None, 0] - self.sensors[:, 0])

        def residual(self, a, b):
            return _wrap(a, b)

    J = measurement_jacobian(TwoBearings(), np.array([[-100.0, 1.0, 1e-6, 0.0]]), 1)
    np.testing.assert_allclose(J[0, 0, 2], -0.01, rtol=1e-6)


@pytest.mark.parametrize("batched", [True, False])
def test_inverse_of_a_floating_point_singular_4x4_is_the_pseudo_inverse(batched, rng):
    # Four precise ranges of a target whose predicted position variance is 1e12 m²
    # against R = 1e-6 m²: H P Hᵀ (rank 2) swamps R, S is singular in floating
    # point and LAPACK's inverse raises.  The healthy matrices of the stack keep
    # LAPACK's inverse bit for bit; the singular one gets the pseudo-inverse.
    A = rng.standard_normal((6, 4, 4))
    good = A @ np.swapaxes(A, -1, -2) + np.eye(4)
    H = rng.standard_normal((4, 2))
    singular = 1e12 * H @ H.T + 1e-6 * np.eye(4)
    singular = 0.5 * (singular + singular.T)
    S = np.concatenate([good[:3], singular[None], good[3:]]) if batched else singular
    assert np.linalg.slogdet(singular)[0] == 0  # the hazard is real ...
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.inv(S)  # ... and LAPACK refuses
    out = inv_spd(S)
    assert np.all(np.isfinite(out))
    pinv = np.linalg.pinv(singular, hermitian=True)
    if batched:
        np.testing.assert_array_equal(out[[0, 1, 2, 4, 5, 6]], np.linalg.inv(good))
        np.testing.assert_array_equal(out[3], pinv)
    else:
        np.testing.assert_array_equal(out, pinv)


def test_inv_spd_gives_nan_for_an_overflowed_matrix_and_inverts_the_rest():
    # an overflowed covariance (inf, or inf - inf = NaN) made LAPACK raise "Eigenvalues did not converge"
    from pursuit._linalg import inv_spd

    for m in (2, 3, 4):
        good = np.eye(m) * 2.0
        S = np.stack([good, np.full((m, m), np.inf), good])
        S[1][np.triu_indices(m, 1)] = np.nan
        with np.errstate(invalid="ignore", over="ignore"):
            out = inv_spd(S)
        assert np.isnan(out[1]).all()
        np.testing.assert_allclose(out[0], np.eye(m) / 2.0)
        np.testing.assert_allclose(out[2], np.eye(m) / 2.0)
