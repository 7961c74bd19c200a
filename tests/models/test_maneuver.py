"""Maneuvering-target models against numerical integration, high-precision closed forms and reference values."""

from __future__ import annotations

from decimal import Decimal, getcontext

import numpy as np
import pytest
from scipy import stats
from scipy.linalg import expm

from pursuit._linalg import numerical_jacobian
from pursuit.models import ConstantTurn, ConstantVelocity, CoordinatedTurn, CurrentStatistical, Jerk, Singer
from pursuit.models.maneuver import (
    _turn_functions,
    cs_variance,
    exp_correlated_input,
    exp_correlated_noise,
    exp_correlated_transition,
    singer_sigma2,
)

ALPHAS = [1e-6, 1e-5, 1e-4, 1e-3, 0.01, 0.05, 0.1, 0.3, 1.0, 1.7, 3.0, 10.0]


# --------------------------------------------------------------------------
# references
# --------------------------------------------------------------------------
def _generator(n: int, alpha: float) -> np.ndarray:
    """Continuous model: integrators ending in ċ = −α c (+ white noise on c)."""
    A = np.diag(np.ones(n - 1), 1)
    A[-1, -1] = -alpha
    return A


def _gauss_legendre(fun, T: float, panels: int = 4, nodes: int = 30) -> np.ndarray:
    """Composite Gauss-Legendre quadrature of a matrix-valued function on [0, T]."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    total = 0.0
    for p in range(panels):
        a, b = p * T / panels, (p + 1) * T / panels
        for xi, wi in zip(x, w):
            total = total + wi * (b - a) / 2 * fun((b - a) / 2 * xi + (a + b) / 2)
    return total


def _integrated(n: int, alpha: float, T: float):
    """F = e^{AT}, q = ∫ Φ(s) b bᵀ Φ(s)ᵀ ds and U = α ∫ Φ(s) b ds by quadrature of the matrix exponential."""
    A = _generator(n, alpha)
    q = _gauss_legendre(lambda s: np.outer(expm(A * s)[:, -1], expm(A * s)[:, -1]), T)
    U = alpha * _gauss_legendre(lambda s: expm(A * s)[:, -1], T)
    return expm(A * T), q, U


def _rel(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    mask = b != 0
    assert np.all(a[~mask] == 0)
    return np.max(np.abs(a[mask] / b[mask] - 1.0))


# --------------------------------------------------------------------------
# F, q, U of Singer / CS / Jerk
# --------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 4], ids=["singer", "jerk"])
@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("T", [1.0, 0.25])
def test_matrices_match_numerical_integration_of_the_continuous_model(n, alpha, T):
    F_ref, q_ref, U_ref = _integrated(n, alpha, T)
    assert _rel(exp_correlated_transition(n, alpha, T), F_ref) < 1e-10
    assert _rel(exp_correlated_noise(n, alpha, T), q_ref) < 1e-10
    assert _rel(exp_correlated_input(n, alpha, T), U_ref) < 1e-10


def _singer_closed_forms(alpha: float, T: float) -> dict[str, Decimal]:
    """Spec 04 §1 closed forms (Zhou / Singer) in 60-digit arithmetic, where cancellation is harmless."""
    getcontext().prec = 60
    a, T = Decimal(alpha), Decimal(T)
    x = a * T
    e1, e2 = (-x).exp(), (-2 * x).exp()
    return {
        "q11": (1 - e2 + 2 * x + 2 * x**3 / 3 - 2 * x**2 - 4 * x * e1) / (2 * a**5),
        "q12": (e2 + 1 - 2 * e1 + 2 * x * e1 - 2 * x + x**2) / (2 * a**4),
        "q13": (1 - e2 - 2 * x * e1) / (2 * a**3),
        "q22": (4 * e1 - 3 - e2 + 2 * x) / (2 * a**3),
        "q23": (e2 + 1 - 2 * e1) / (2 * a**2),
        "q33": (1 - e2) / (2 * a),
        "F13": (x - 1 + e1) / a**2,
        "F23": (1 - e1) / a,
        "F33": e1,
        "U1": (-T + a * T**2 / 2 + (1 - e1) / a) / a,
        "U2": T - (1 - e1) / a,
        "U3": 1 - e1,
    }


@pytest.mark.parametrize("alpha", ALPHAS)
def test_singer_and_cs_match_the_closed_forms_in_high_precision(alpha):
    T = 1.3
    ref = {k: float(v) for k, v in _singer_closed_forms(alpha, T).items()}
    q = exp_correlated_noise(3, alpha, T)
    F = exp_correlated_transition(3, alpha, T)
    U = exp_correlated_input(3, alpha, T)
    got = {
        "q11": q[0, 0], "q12": q[0, 1], "q13": q[0, 2], "q22": q[1, 1], "q23": q[1, 2], "q33": q[2, 2],
        "F13": F[0, 2], "F23": F[1, 2], "F33": F[2, 2], "U1": U[0], "U2": U[1], "U3": U[2],
    }  # fmt: skip
    for key, value in ref.items():
        assert got[key] == pytest.approx(value, rel=1e-12), key


@pytest.mark.parametrize("alpha", ALPHAS)
def test_jerk_matches_the_closed_forms_in_high_precision(alpha):
    getcontext().prec = 80
    T = 1.7
    a, Td = Decimal(alpha), Decimal(T)
    x = a * Td
    e1, e2 = (-x).exp(), (-2 * x).exp()
    ref = {
        (0, 0): (x**5 / 10 - x**4 / 2 + 4 * x**3 / 3 - 2 * x**2 + 2 * x - 3 + 4 * e1 + 2 * x**2 * e1 - e2) / (2 * a**7),
        (0, 1): (1 - 2 * x + 2 * x**2 - x**3 + x**4 / 4 + e2 + 2 * x * e1 - 2 * e1 - x**2 * e1) / (2 * a**6),
        (0, 2): (2 * x - x**2 + x**3 / 3 - 3 - e2 + 4 * e1 + x**2 * e1) / (2 * a**5),
        (0, 3): (1 + e2 - 2 * e1 - x**2 * e1) / (2 * a**4),
    }
    q = exp_correlated_noise(4, alpha, T)
    for (i, j), v in ref.items():
        assert q[i, j] == pytest.approx(float(v), rel=1e-12), (i, j)
    # lower-right block equals the Singer block
    np.testing.assert_allclose(q[1:, 1:], exp_correlated_noise(3, alpha, T), rtol=1e-14)
    F = exp_correlated_transition(4, alpha, T)
    p1 = (2 - 2 * x + x**2 - 2 * e1) / (2 * a**3)
    assert F[0, 3] == pytest.approx(float(p1), rel=1e-12)
    np.testing.assert_allclose(F[:3, :3], [[1, T, T * T / 2], [0, 1, T], [0, 0, 1]], rtol=0, atol=0)


def test_singer_q_matches_the_published_reference_values():
    # spec 04 §1: MATLAB singerProcessNoise, Q = 2ασ²[q], σ = 1, 4 decimals
    cases = {
        (0.05, 1.0): (0.0049, 0.0121, 0.0159, 0.0321, 0.0476, 0.0952),
        (0.1, 2.0): (0.2868, 0.3508, 0.2188, 0.4603, 0.3286, 0.3297),
    }
    for (alpha, T), expected in cases.items():
        Q = Singer(alpha=alpha, sigma=1.0, dt=T).cov()
        got = Q[np.triu_indices(3)]
        np.testing.assert_allclose(got, expected, rtol=0, atol=5e-5)


def test_jerk_q_matches_the_spec_check_values():
    # spec 04 §4.4: the bracket [Q_ij] (Q = 2ασ_j²[Q_ij]) at α = 0.3, T = 1.7
    q = Jerk(alpha=0.3, sigma=1.0, dt=1.7).cov() / (2 * 0.3)
    np.testing.assert_allclose(q[0], [0.131282, 0.262260, 0.348411, 0.210795], rtol=0, atol=5e-7)


def test_the_textbook_closed_form_cancels_and_ours_does_not():
    # spec 04 §1 numerical warning: at α = 1e−3, T = 1 the double-precision closed form gives q11 ≈ 0.0434
    a, T = 1e-3, 1.0
    x = a * T
    naive = (1 - np.exp(-2 * x) + 2 * x + 2 * x**3 / 3 - 2 * x**2 - 4 * x * np.exp(-x)) / (2 * a**5)
    ours = exp_correlated_noise(3, a, T)[0, 0]
    series = T**5 * (1 / 20 - x / 36 + 5 * x**2 / 504 - x**3 / 360)  # spec's series, error O(x⁴)
    assert abs(naive - 0.05) > 0.005
    assert ours == pytest.approx(series, rel=1e-12)


@pytest.mark.parametrize("alpha", [0.0, 1e-9])
def test_alpha_to_zero_gives_constant_acceleration_with_white_jerk(alpha):
    T = 0.7
    F = exp_correlated_transition(3, alpha, T)
    np.testing.assert_allclose(F, [[1, T, T * T / 2], [0, 1, T], [0, 0, 1]], rtol=1e-8, atol=0)
    q = exp_correlated_noise(3, alpha, T)
    white_jerk = np.array([[T**5 / 20, T**4 / 8, T**3 / 6], [T**4 / 8, T**3 / 3, T**2 / 2], [T**3 / 6, T**2 / 2, T]])
    np.testing.assert_allclose(q, white_jerk, rtol=1e-8)


def test_cs_input_makes_the_prediction_a_constant_acceleration_extrapolation(rng):
    # spec 04 §1: with ā = â(k|k), F x + U ā = [x + vT + aT²/2, v + aT, a] for any α
    T = 1.0
    x = rng.normal(size=(50, 3)) * [1e5, 300.0, 40.0]
    alphas = np.array([1e-6, 1e-3, 0.05, 1.0, 5.0, 30.0])
    F = exp_correlated_transition(3, alphas, T)[:, None]
    U = exp_correlated_input(3, alphas, T)[:, None]
    pred = np.einsum("...ij,...j->...i", F, x) + U * x[..., 2:3]
    ca = np.stack([x[:, 0] + x[:, 1] * T + x[:, 2] * T * T / 2, x[:, 1] + x[:, 2] * T, x[:, 2]], axis=-1)
    np.testing.assert_allclose(pred, np.broadcast_to(ca, pred.shape), rtol=1e-13, atol=1e-9)


def test_batched_alpha_equals_scalar_evaluation():
    alphas = np.array([[1e-6, 0.02, 0.9], [1.2, 4.0, 10.0]])
    for fn in (exp_correlated_transition, exp_correlated_noise, exp_correlated_input):
        batched = fn(3, alphas, 0.5)
        for idx in np.ndindex(alphas.shape):
            np.testing.assert_allclose(batched[idx], fn(3, alphas[idx], 0.5), rtol=1e-15, atol=0)


@pytest.mark.parametrize("n", [3, 4])
def test_process_noise_is_positive_definite_everywhere(n):
    for alpha in ALPHAS + [100.0, 1000.0]:
        q = exp_correlated_noise(n, alpha, 1.0)
        assert np.all(q > 0)
        np.linalg.cholesky(q)


# --------------------------------------------------------------------------
# model classes
# --------------------------------------------------------------------------
def test_singer_is_block_diagonal_over_axes_with_per_axis_layout():
    m = Singer(alpha=0.1, sigma=3.0, ndim=3, dt=0.5)
    assert m.dim == 9
    assert m.position_indices == (0, 3, 6) and m.velocity_indices == (1, 4, 7) and m.acceleration_indices == (2, 5, 8)
    Fa = exp_correlated_transition(3, 0.1, 0.5)
    Qa = 2 * 0.1 * 9.0 * exp_correlated_noise(3, 0.1, 0.5)
    np.testing.assert_array_equal(m.transition_matrix(), np.kron(np.eye(3), Fa))
    np.testing.assert_allclose(m.cov(), np.kron(np.eye(3), Qa), rtol=1e-15)
    G = m.noise_factor()
    np.testing.assert_allclose(G @ G.T, m.cov(), rtol=1e-12, atol=1e-15)
    # dt overrides the model's own period
    np.testing.assert_array_equal(m.cov(dt=2.0), Singer(alpha=0.1, sigma=3.0, ndim=3, dt=2.0).cov())


def test_jerk_layout():
    m = Jerk(alpha=0.2, sigma=1.0, ndim=2)
    assert m.dim == 8 and m.jerk_indices == (3, 7) and m.position_indices == (0, 4)


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"alpha": 0.0}, "alpha"),
        ({"alpha": -1.0}, "alpha"),
        ({"sigma": -1.0}, "sigma"),
        ({"ndim": 4}, "ndim"),
        ({"dt": 0.0}, "dt"),
        ({"alpha": float("nan")}, "alpha"),
    ],
)
def test_bad_singer_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        Singer(**kwargs)


def test_cs_variance_follows_the_modified_rayleigh_rule():
    c = (4 - np.pi) / np.pi
    a = np.array([30.0, -20.0, 0.0])
    np.testing.assert_allclose(cs_variance(a, 100.0), c * np.array([70.0, 80.0, 100.0]) ** 2)
    np.testing.assert_allclose(cs_variance(a, 100.0, 50.0), c * np.array([70.0, 30.0, 100.0]) ** 2)


def test_singer_sigma2_rule_and_its_checks():
    assert singer_sigma2(100.0, 0.1, 0.5) == pytest.approx(100.0**2 / 3 * 0.9)
    with pytest.raises(ValueError, match="p_max"):
        singer_sigma2(10.0, 0.6, 0.0)
    with pytest.raises(ValueError, match="a_max"):
        singer_sigma2(-1.0)


def test_cs_model_prediction_and_state_dependent_noise(rng):
    m = CurrentStatistical(alpha=0.05, a_max=100.0, ndim=1, dt=1.0)
    x = np.array([10.0, 2.0, 3.0])
    np.testing.assert_allclose(m.f(x), [10 + 2 + 1.5, 5.0, 3.0])
    Q0 = m.cov()
    np.testing.assert_allclose(Q0, 2 * 0.05 * cs_variance(0.0, 100.0) * exp_correlated_noise(3, 0.05, 1.0))
    np.testing.assert_allclose(m.process_cov(np.array([[50.0]]))[0], Q0 * 0.25, rtol=1e-14)
    # the sampled acceleration variance follows σ²(ā): compare a = 0 and a = 50 (σ² ratio 4)
    n = 4000
    draws = {}
    for a in (0.0, 50.0):
        xs = np.broadcast_to([0.0, 0.0, a], (n, 3))
        draws[a] = m.sample(xs, 1, rng)[:, 2] - a
    for a, factor in ((0.0, 1.0), (50.0, 0.25)):
        var = Q0[2, 2] * factor
        s2 = draws[a].var(ddof=1)
        lo, hi = stats.chi2.ppf([0.0005, 0.9995], n - 1) / (n - 1)
        assert lo <= s2 / var <= hi


# --------------------------------------------------------------------------
# constant turn
# --------------------------------------------------------------------------
def test_constant_turn_at_zero_rate_is_constant_velocity():
    ct = ConstantTurn(omega=0.0, q=0.3, ndim=2, dt=0.8)
    cv = ConstantVelocity(ndim=2, dt=0.8, q=0.3)
    np.testing.assert_array_equal(ct.transition_matrix(), cv.transition_matrix())
    np.testing.assert_array_equal(ct.cov(), cv.cov())


@pytest.mark.parametrize("omega", [-0.7, -1e-3, 1e-9, 0.05, 0.3, 2.0])
def test_constant_turn_matches_the_matrix_exponential(omega):
    T = 1.5
    A = np.zeros((4, 4))
    A[0, 1] = A[2, 3] = 1.0
    A[1, 3], A[3, 1] = -omega, omega
    np.testing.assert_allclose(ConstantTurn(omega=omega, dt=T).transition_matrix(), expm(A * T), rtol=0, atol=1e-13)
    F3 = ConstantTurn(omega=omega, dt=T, ndim=3).transition_matrix()
    np.testing.assert_allclose(F3[4:, 4:], [[1, T], [0, 1]])


def test_turn_functions_are_continuous_across_the_series_switch():
    u = np.array([0.5 - 1e-12, 0.5 + 1e-12, -0.5 - 1e-12, -0.5 + 1e-12])
    S, C, dS, dC = _turn_functions(u)
    for f in (S, C, dS, dC):
        assert abs(f[0] - f[1]) < 1e-12 and abs(f[2] - f[3]) < 1e-12
    v = np.array([0.3, 1.3])
    S, C, dS, dC = _turn_functions(v)
    np.testing.assert_allclose(S, np.sin(v) / v, rtol=1e-15)
    np.testing.assert_allclose(C, (1 - np.cos(v)) / v, rtol=1e-14)
    np.testing.assert_allclose(dS, (v * np.cos(v) - np.sin(v)) / v**2, rtol=1e-12)
    np.testing.assert_allclose(dC, (v * np.sin(v) - 1 + np.cos(v)) / v**2, rtol=1e-12)


@pytest.mark.parametrize("ndim", [2, 3])
def test_coordinated_turn_transition_and_jacobian(ndim, rng):
    m = CoordinatedTurn(q=0.1, q_omega=1e-4, ndim=ndim, dt=1.2)
    omegas = np.array([0.0, 1e-9, 0.02, -0.4, 1.1])
    x = rng.normal(size=(omegas.size, m.dim)) * 10.0
    x[:, m.turn_rate_index] = omegas
    fx = m.f(x)
    for i, w in enumerate(omegas):
        F = ConstantTurn(omega=w, ndim=ndim, dt=1.2).transition_matrix()
        np.testing.assert_allclose(fx[i, :-1], F @ x[i, :-1], rtol=1e-13, atol=1e-12)
        assert fx[i, -1] == w
    J = m.jacobian(x)
    J_num = numerical_jacobian(m.f, x)
    np.testing.assert_allclose(J, J_num, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("filter_name", ["ExtendedKalmanFilter", "UnscentedKalmanFilter"])
def test_coordinated_turn_filters_recover_the_turn_rate(filter_name):
    import pursuit
    from pursuit import Gaussian, run
    from pursuit.models import LinearGaussian

    truth_model = CoordinatedTurn(q=0.0, q_omega=0.0, dt=1.0)
    x = np.array([0.0, 100.0, 0.0, 0.0, 0.04])
    states = []
    for _ in range(60):
        x = truth_model.f(x)
        states.append(x)
    states = np.array(states)
    meas = LinearGaussian.position(5, (0, 2), 1e-3)
    zs = states[:, None, [0, 2]]
    filt = getattr(pursuit, filter_name)(CoordinatedTurn(q=1e-6, q_omega=1e-8, dt=1.0), meas)
    prior = Gaussian([0.0, 100.0, 0.0, 0.0, 0.0], np.diag([1.0, 4.0, 1.0, 4.0, 0.01]))
    track = run(filt, zs, prior)
    assert track.mean[-1, 0, 4] == pytest.approx(0.04, rel=1e-3)
