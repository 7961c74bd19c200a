"""Per-run random streams and seeding."""

import inspect

import numpy as np
import pytest

import pursuit
import pursuit.rng
import pursuit.scenarios
from pursuit.rng import RunStreams, as_rng, permutations, run_seed, run_streams


def test_run_seed_equals_spawning():
    root = np.random.SeedSequence(42)
    children = root.spawn(5)
    for i, child in enumerate(children):
        mine = run_seed(42, i)
        assert mine.entropy == child.entropy and mine.spawn_key == child.spawn_key
        assert np.array_equal(mine.generate_state(4), child.generate_state(4))


def test_run_streams_rows_are_independent_of_the_chunk():
    whole = run_streams(7, range(10), 0).standard_normal((10, 3))
    part = run_streams(7, range(4, 7), 0).standard_normal((3, 3))
    np.testing.assert_array_equal(whole[4:7], part)


def test_purposes_give_different_streams():
    a = run_streams(7, range(2), 0).standard_normal((2, 4))
    b = run_streams(7, range(2), 1).standard_normal((2, 4))
    assert not np.allclose(a, b)


def test_run_streams_draws_match_each_generator():
    gens = [np.random.default_rng(i) for i in range(3)]
    rs = RunStreams([np.random.default_rng(i) for i in range(3)])
    x = rs.standard_normal((3, 2, 5))
    for g, row in zip(gens, x):
        np.testing.assert_array_equal(row, g.standard_normal((2, 5)))
    u = rs.uniform(2.0, 3.0, (3, 4))
    assert np.all((u >= 2.0) & (u < 3.0))
    ints = rs.integers(0, 5, (3, 6))
    assert ints.shape == (3, 6) and ints.min() >= 0 and ints.max() < 5


def test_permutations_are_permutations():
    for rng in (np.random.default_rng(0), run_streams(1, range(4), 0)):
        p = permutations(rng, 9, (4, 2))
        assert p.shape == (4, 2, 9)
        assert np.all(np.sort(p, axis=-1) == np.arange(9))


def test_run_streams_refuse_wrong_row_counts():
    with pytest.raises(ValueError, match="streams"):
        run_streams(1, range(3), 0).standard_normal((4, 2))


def test_as_rng():
    assert isinstance(as_rng(None), np.random.Generator)
    assert as_rng(5).standard_normal() == np.random.default_rng(5).standard_normal()
    with pytest.raises(TypeError):
        as_rng("seed")
    with pytest.raises(TypeError):
        RunStreams([1, 2])


def test_a_run_streams_draw_needs_a_size():
    streams = run_streams(1, range(3), 0)
    with pytest.raises(ValueError, match="size: RunStreams needs a size"):
        streams.uniform()
    with pytest.raises(ValueError, match="3 streams"):
        streams.standard_normal((2, 4))


@pytest.mark.parametrize(
    "fn",
    [
        RunStreams.standard_normal,
        RunStreams.random,
        RunStreams.uniform,
        RunStreams.integers,
        RunStreams.permutations,
        pursuit.rng.permutations,
        pursuit.scenarios.simulate_markov,
        pursuit.load,
    ],
    ids=lambda f: f.__qualname__,
)
def test_public_draws_and_loaders_are_annotated_and_documented(fn):
    sig = inspect.signature(fn)
    missing = [p for p in sig.parameters if p != "self" and sig.parameters[p].annotation is inspect.Parameter.empty]
    assert not missing, missing
    assert sig.return_annotation is not inspect.Signature.empty
    doc = inspect.getdoc(fn)
    assert "Parameters\n----------" in doc and "Returns\n-------" in doc
