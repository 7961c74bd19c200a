"""Order-independent sums over runs (pursuit.reduction)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pursuit.reduction import block_sums, merge_blocks, run_sum


def _chunked(values, cuts):
    bounds = [0, *sorted(set(cuts)), len(values)]
    return [block_sums(values[a:b], a) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


@given(
    st.integers(min_value=1, max_value=300),
    st.lists(st.integers(min_value=1, max_value=299), max_size=12),
    st.integers(min_value=0, max_value=2**31),
)
def test_chunked_sums_are_bit_identical_to_one_pass(m, cuts, seed):
    rng = np.random.default_rng(seed)
    # Values of very different magnitudes make the order of additions visible.
    values = rng.standard_normal((m, 3)) * 10.0 ** rng.integers(-8, 9, size=(m, 1))
    cuts = [c for c in cuts if c < m]
    whole = run_sum(values)
    assert np.array_equal(merge_blocks(_chunked(values, cuts), m), whole)
    # Chunks may arrive in any order.
    assert np.array_equal(merge_blocks(reversed(_chunked(values, cuts)), m), whole)
    assert np.allclose(whole, values.sum(axis=0), rtol=1e-12, atol=1e-12 * np.abs(values).sum(axis=0).max())


def test_naive_chunk_sums_differ_but_canonical_ones_do_not():
    """The problem this module solves is real: plain chunk sums change with the chunking."""
    rng = np.random.default_rng(7)
    values = rng.standard_normal(1000) * 10.0 ** rng.integers(-6, 7, size=1000)
    naive = {c: sum(values[s : s + c].sum() for s in range(0, 1000, c)) for c in (1, 3, 7, 64, 1000)}
    assert len(set(naive.values())) > 1
    canonical = {c: merge_blocks(_chunked(values, range(c, 1000, c)), 1000)[()] for c in (1, 3, 7, 64, 1000)}
    assert len(set(canonical.values())) == 1


def test_missing_and_duplicate_runs_are_errors():
    values = np.arange(10.0)
    with pytest.raises(ValueError, match="run 9 is missing"):
        merge_blocks([block_sums(values[:9], 0)], 10)
    with pytest.raises(ValueError, match="twice"):
        merge_blocks([block_sums(values[:4], 0), block_sums(values[:4], 0)], 4)


def test_run_sum_along_other_axis():
    x = np.arange(24.0).reshape(2, 12)
    assert np.array_equal(run_sum(x, axis=1), x.sum(axis=1))


def test_accumulator_folds_chunks_in_any_order_with_little_memory():
    from pursuit.reduction import RunSumAccumulator

    rng = np.random.default_rng(3)
    values = rng.standard_normal((1000, 2)) * 10.0 ** rng.integers(-8, 9, size=(1000, 1))
    parts = _chunked(values, range(37, 1000, 37))
    order = rng.permutation(len(parts))
    acc = RunSumAccumulator(1000)
    for i in order:
        acc.add(parts[i])
    assert np.array_equal(acc.result(), run_sum(values))
    assert len(acc.pool) <= 10  # the canonical top blocks of 1000 runs: 512+256+128+64+32+8
    in_order = RunSumAccumulator(1000)
    for p in parts:
        in_order.add(p)
        assert len(in_order.pool) <= 2 * 10
