"""The compiled PCG64 streams draw NumPy's numbers and leave the Generator where NumPy would."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import streams  # noqa: E402
from pursuit.filters.workspace import Workspace, recycled  # noqa: E402
from pursuit.rng import RunStreams, run_streams  # noqa: E402
from pursuit.scenarios.ungm import UNGM  # noqa: E402


def test_layout_check_passes_on_this_numpy():
    assert streams.fast_streams_available()


@pytest.mark.parametrize("seed", [0, 1, 20261201])
def test_normals_are_numpys_bit_for_bit(seed):
    # 2 million draws reach the ziggurat's tail (idx 0) and wedges many times over
    g, ref = np.random.default_rng(seed), np.random.default_rng(seed)
    (addr,) = streams.stream_addresses([g])
    out = np.empty(2_000_000)
    streams.fill_normal(addr, out)
    expected = ref.standard_normal(out.size)
    assert np.array_equal(out, expected)
    assert np.any(np.abs(expected) > 3.6541528853610088)  # beyond the ziggurat's r: the tail branch ran
    # the Generator continues exactly where NumPy's would
    assert g.standard_normal(7).tolist() == ref.standard_normal(7).tolist()


def test_uniforms_are_numpys_and_interleave_with_numpy_draws():
    g, ref = np.random.default_rng(5), np.random.default_rng(5)
    (addr,) = streams.stream_addresses([g])
    out = np.empty(1001)
    streams.fill_random(addr, out)
    assert np.array_equal(out, ref.random(out.size))
    assert g.random() == ref.random()  # NumPy draw in between
    assert streams.next_random(addr) == ref.random()
    streams.fill_normal(addr, out[:3])
    assert np.array_equal(out[:3], ref.standard_normal(3))
    assert g.integers(0, 10**9) == ref.integers(0, 10**9)


def test_streams_refused_for_other_bit_generators_and_shared_generators():
    g = np.random.default_rng(1)
    assert streams.stream_addresses([np.random.Generator(np.random.Philox(1))]) is None
    assert streams.stream_addresses([g, g]) is None
    assert streams.stream_addresses([g, np.random.default_rng(2)]).shape == (2,)


def test_pf_with_other_bit_generators_draws_with_numpy_and_agrees():
    """RunStreams of Philox generators take the NumPy-draw path of the compiled PF: same numbers as NumPy."""
    sc = UNGM(steps=15)
    M = 4
    sim = sc.simulate(run_streams(1, range(M), 0), M)

    def philox():
        return RunStreams([np.random.Generator(np.random.Philox(i)) for i in range(M)])

    tracks = [
        pu.run(pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=200, ess_threshold=0.5, backend=b),
               sim.measurements, sim.prior, rng=philox())
        for b in ("numpy", "numba")
    ]
    np.testing.assert_allclose(tracks[1].mean, tracks[0].mean, rtol=1e-9, atol=1e-12)
    assert np.array_equal(tracks[1].info["resampled"], tracks[0].info["resampled"])


def test_recycled_never_reuses_an_array_someone_holds():
    work = Workspace()
    a = recycled(work, "x", (4,))
    a[:] = 1.0
    b = recycled(work, "x", (4,))
    b[:] = 2.0
    view = a[1:]  # a view keeps its base alive
    del a
    c = recycled(work, "x", (4,))
    c[:] = 3.0
    assert np.all(view == 1.0) and np.all(b == 2.0)
    del view, b
    d = recycled(work, "x", (4,))
    assert d is not c  # c is still held here
    assert recycled(work, "x", (5,)).shape == (5,)  # another shape: fresh


def test_compiled_pf_states_held_by_the_caller_never_change():
    sc = UNGM(steps=6)
    sim = sc.simulate(run_streams(1, range(3), 0), 3)
    filt = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=50, backend="numba")
    state = filt.init(sim.prior, (3,), run_streams(2, range(3), 1))
    held = []
    for k in range(6):
        state, _ = filt.step(state, sim.measurements[k], k + 1)
        held.append((state, state.particles.copy(), state.logw.copy()))
    for st, x, lw in held:
        assert np.array_equal(st.particles, x) and np.array_equal(st.logw, lw)
