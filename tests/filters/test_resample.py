"""The four resampling schemes: unbiasedness, exactness, batching."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pursuit.filters import resample as rs
from pursuit.rng import run_streams

SCHEMES = sorted(rs.RESAMPLERS)


def _counts(idx: np.ndarray, N: int) -> np.ndarray:
    return np.stack([(idx == i).sum(axis=-1) for i in range(N)], axis=-1)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_expected_copies_equal_n_times_the_weight(scheme, rng):
    N, M = 8, 20000
    w = np.array([0.30, 0.01, 0.0, 0.12, 0.07, 0.25, 0.005, 0.245])
    idx = rs.RESAMPLERS[scheme](np.broadcast_to(w, (M, N)).copy(), rng)
    mean = _counts(idx, N).mean(axis=0)
    # Copies of particle i have variance at most N w_i (1 - w_i) (multinomial is the
    # largest of the four); five standard errors of the mean over M rows.
    bound = 5.0 * np.sqrt(N * w * (1 - w) / M) + 1e-12
    assert np.all(np.abs(mean - N * w) <= bound), (scheme, mean, N * w)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual"])
def test_low_variance_schemes_bound_the_copies(scheme, rng):
    # systematic keeps each particle floor(N w) or ceil(N w) times, stratified at most
    # one copy further away, residual at least floor(N w); multinomial guarantees nothing.
    N = 50
    w = rng.dirichlet(np.full(N, 0.5), size=200)
    counts = _counts(rs.RESAMPLERS[scheme](w, rng), N)
    slack = {"systematic": 0, "stratified": 1, "residual": 0}[scheme]
    assert np.all(counts >= np.floor(N * w - 1e-9) - slack)
    if scheme != "residual":
        assert np.all(counts <= np.ceil(N * w + 1e-9) + slack)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "residual"])
def test_equal_weights_return_every_index_once(scheme, rng):
    for N in (1, 7, 100, 1000):
        idx = rs.RESAMPLERS[scheme](np.full((5, N), 1.0 / N), rng)
        np.testing.assert_array_equal(idx, np.broadcast_to(np.arange(N), (5, N)))


@settings(max_examples=60)
@given(
    N=st.integers(1, 60),
    M=st.integers(1, 4),
    seed=st.integers(0, 2**31 - 1),
    spread=st.floats(0.05, 50.0),
    scheme=st.sampled_from(SCHEMES),
)
def test_any_weights_give_n_sorted_valid_indices(N, M, seed, spread, scheme):
    g = np.random.default_rng(seed)
    logw = g.standard_normal((M, N)) * spread
    w = np.exp(logw - logw.max(axis=-1, keepdims=True))
    w[g.random((M, N)) < 0.3] = 0.0  # zero weights, but not a whole row
    w[:, 0] += 1e-300 * (w.sum(axis=-1) == 0)
    idx = rs.RESAMPLERS[scheme](w / w.sum(axis=-1, keepdims=True), g)
    assert idx.shape == (M, N)
    assert np.all(np.diff(idx, axis=-1) >= 0)
    assert np.all(w[np.arange(M)[:, None], idx] > 0), "a zero-weight particle was selected"
    counts = rs.COUNTS[scheme](w, g)
    assert np.all(counts.sum(axis=-1) == N) and np.all(counts >= 0)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_a_run_resamples_the_same_alone_or_in_a_batch(scheme, rng):
    M, N = 6, 40
    w = rng.dirichlet(np.ones(N), size=M)
    batch = rs.RESAMPLERS[scheme](w, run_streams(9, range(M), 1))
    for i in range(M):
        alone = rs.RESAMPLERS[scheme](w[i : i + 1], run_streams(9, [i], 1))
        np.testing.assert_array_equal(alone[0], batch[i])


def test_unnormalised_weights_give_the_same_counts(rng):
    w = rng.random((3, 25))
    a = rs.systematic_counts(w, np.random.default_rng(1))
    b = rs.systematic_counts(w / w.sum(axis=-1, keepdims=True), np.random.default_rng(1))
    np.testing.assert_array_equal(a, b)


def test_effective_sample_size():
    N = 10
    assert rs.effective_sample_size(np.full(N, 1 / N)) == pytest.approx(N)
    assert rs.effective_sample_size(np.eye(N)[3]) == pytest.approx(1.0)


def test_repeat_particles_copies_rows_with_their_covariances(rng):
    X = rng.standard_normal((2, 4, 3))
    P = rng.standard_normal((2, 4, 3, 3))
    counts = np.array([[0, 2, 1, 1], [4, 0, 0, 0]])
    np.testing.assert_array_equal(rs.repeat_particles(X, counts), X[[[0], [1]], [[1, 1, 2, 3], [0, 0, 0, 0]]])
    np.testing.assert_array_equal(rs.repeat_particles(P, counts)[1], np.broadcast_to(P[1, 0], (4, 3, 3)))
    idx = rs.counts_to_indices(counts)
    np.testing.assert_array_equal(rs.gather(X, idx), rs.repeat_particles(X, counts))


def test_unknown_scheme_is_refused():
    with pytest.raises(ValueError, match="resampler"):
        rs.get_resampler("bogus")


@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_gather_takes_any_number_of_rows_as_take_along_axis(batch, rng):
    """``gather`` with K ≠ N rows per batch entry, trailing axes of any rank, against ``np.take_along_axis``."""
    X = rng.standard_normal((*batch, 7, 4))
    P = rng.standard_normal((*batch, 7, 2, 2))
    idx = rng.integers(0, 7, size=(*batch, 5))
    np.testing.assert_array_equal(rs.gather(X, idx), np.take_along_axis(X, idx[..., None], axis=-2))
    np.testing.assert_array_equal(rs.gather(P, idx), np.take_along_axis(P, idx[..., None, None], axis=-3))
