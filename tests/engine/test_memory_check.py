"""Refusing, before anything runs, what cannot fit in memory; chunks that are never listed."""

import dataclasses
import time
import tracemalloc

import pytest

import pursuit as pu
import pursuit.engine.memory as mem
from pursuit.engine import monte_carlo
from pursuit.engine.memory import MemoryNeeded, check_memory, needed_bytes
from pursuit.engine.montecarlo import Spans
from pursuit.scenarios import WSNRange

from .helpers import SMALL, small_filters

FIVE = WSNRange(steps=5)
# measured peak / estimate stated in pursuit.engine.memory.WORK_COPIES
LOW, HIGH = 0.6, 1.1


def _peak(filt, runs: int) -> int:
    monte_carlo(FIVE, [filt], 2, 1, store="summary")  # warm caches (imports, workspaces)
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        monte_carlo(FIVE, [filt], runs, 1, chunk_size=runs, store="summary")
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


def _with_iterations(filt, n_iter: int):
    return dataclasses.replace(filt, search=dataclasses.replace(filt.search, n_iter=n_iter))


@pytest.mark.parametrize(
    "make",
    [
        lambda s: pu.BootstrapParticleFilter(s.motion, s.measurement, particles=400),
        lambda s: pu.PartialUPF(s.motion, s.measurement, particles=200, fraction=0.5),
        lambda s: pu.CSPF(s.motion, s.measurement, particles=200),
        lambda s: _with_iterations(pu.ICSPF(s.motion, s.measurement, particles=100), 40),
        lambda s: _with_iterations(pu.ICSPF(s.motion, s.measurement, particles=100), 0),
        lambda s: pu.UnscentedKalmanFilter(s.motion, s.measurement),
    ],
    ids=["pf", "upf", "cspf", "icspf-40-iterations", "icspf-0-iterations", "ukf"],
)
def test_working_memory_estimate_is_within_the_stated_factor_of_the_measured_peak(make):
    filt, runs = make(FIVE), 30
    est = needed_bytes(FIVE, [filt], runs, runs, store="summary", keep_cov=True)
    ratio = _peak(filt, runs) / (est.chunk + est.work + est.result)
    assert LOW <= ratio <= HIGH, ratio


def test_a_comparison_that_fits_runs(monkeypatch):
    filters = small_filters()
    est = needed_bytes(SMALL, filters, 8, 4, store="full", keep_cov=True)
    monkeypatch.setenv(mem.MEMORY_LIMIT_ENV, str(2 * est.total))
    res = monte_carlo(SMALL, filters, 8, 1, chunk_size=4, store="full")
    assert res.runs == 8


def test_one_that_does_not_fit_is_refused_naming_the_size_and_the_setting(monkeypatch):
    filters = small_filters()
    est = needed_bytes(SMALL, filters, 8, 4, store="full", keep_cov=True)
    monkeypatch.setenv(mem.MEMORY_LIMIT_ENV, str(est.total - 1))
    with pytest.raises(MemoryNeeded) as e:
        monte_carlo(SMALL, filters, 8, 1, chunk_size=4)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("runs: 8 runs need about ")
    assert mem.format_bytes(est.total) in msg and "--store summary" in msg
    assert e.value.field == "runs" and e.value.needed == est.total


def test_enormous_runs_are_refused_at_once_even_in_summary_mode():
    t0 = time.perf_counter()
    with pytest.raises(MemoryNeeded, match=r"^runs: 1000000000000 runs need about .* TiB .* even in summary mode") as e:
        monte_carlo(SMALL, small_filters(), 10**12, 1, store="summary")
    assert e.value.field == "runs"
    assert time.perf_counter() - t0 < 5  # building 10**9 chunk tuples first took minutes, then MemoryError


def test_enormous_steps_and_particles_name_their_setting():
    huge = WSNRange(steps=10**18)
    with pytest.raises(MemoryNeeded, match=r"^steps: one run of 1000000000000000000 steps needs about") as e:
        check_memory(huge, small_filters(), 10, 1, store="summary", keep_cov=True, available=1 << 34)
    assert e.value.field == "steps"
    pf = pu.BootstrapParticleFilter(FIVE.motion, FIVE.measurement, particles=10**9, name="PF")
    with pytest.raises(MemoryNeeded, match=r"^particles: one run of filter 'PF' needs about") as e:
        check_memory(FIVE, [pf], 10, 1, store="summary", keep_cov=True, available=1 << 34)
    assert e.value.filter_name == "PF"
    # with chunks of several runs, the chunk size is the setting to lower, to a size that fits
    pf = pu.BootstrapParticleFilter(FIVE.motion, FIVE.measurement, particles=10**6, name="PF")
    with pytest.raises(MemoryNeeded, match=r"^chunk_size: chunks of 100 runs need about .*--chunk-size\) of (\d+) or less") as e:
        check_memory(FIVE, [pf], 100, 100, store="summary", keep_cov=True, available=1 << 34)
    fit = int(e.value.args[0].rsplit("of ", 1)[1].split()[0])
    check_memory(FIVE, [pf], 100, fit, store="summary", keep_cov=True, available=1 << 34)  # fits
    with pytest.raises(MemoryNeeded):
        check_memory(FIVE, [pf], 100, fit + 1, store="summary", keep_cov=True, available=1 << 34)


def test_a_sweep_that_needs_every_run_is_not_told_to_summarise(monkeypatch):
    monkeypatch.setenv(mem.MEMORY_LIMIT_ENV, "1K")
    with pytest.raises(MemoryNeeded) as e:
        monte_carlo(SMALL, small_filters(), 8, 1, store="full")
    assert "summary" not in str(e.value)


@pytest.mark.parametrize("bad", ["0", "-5G", "lots", "nan"])
def test_a_bad_memory_limit_is_an_error_naming_the_variable(monkeypatch, bad):
    monkeypatch.setenv(mem.MEMORY_LIMIT_ENV, bad)
    with pytest.raises(ValueError, match=r"\$PURSUIT_MEMORY_LIMIT: expected a positive size"):
        mem.available_bytes()


def test_memory_limit_units(monkeypatch):
    for text, value in (("512", 512), ("2K", 2048), ("1.5G", 3 << 29), ("3MiB", 3 << 20), ("1t", 1 << 40)):
        monkeypatch.setenv(mem.MEMORY_LIMIT_ENV, text)
        assert mem.available_bytes() == value


def test_spans_are_lazy_and_tile_the_runs():
    t0 = time.perf_counter()
    spans = Spans(10**12, 1)  # a list of these took ~100 GB
    assert len(spans) == 10**12 and spans[0] == (0, 1) and spans[-1] == (10**12 - 1, 10**12)
    assert (5, 6) in spans and (5, 7) not in spans and (10**12, 10**12 + 1) not in spans
    assert time.perf_counter() - t0 < 1
    for runs, chunk in ((10, 3), (9, 3), (1, 5), (7, 1)):
        s = Spans(runs, chunk)
        listed = [(a, min(a + chunk, runs)) for a in range(0, runs, chunk)]
        assert list(s) == listed == [s[i] for i in range(len(s))] == s[:]
        assert all(span in s for span in listed)


class _FirstSpanOnly:
    """A backend that computes the first chunk it is given, then stops the comparison."""

    def __init__(self):
        self.first = None

    def map_chunks(self, task, spans, on_result, **kwargs):
        for span in spans:
            self.first = span
            raise KeyboardInterrupt


def test_enormous_runs_start_without_listing_the_chunks(monkeypatch):
    # With memory enough for the per-run statistics (patched), 10**12 runs start at once:
    # the backend is handed the lazy chunks, not a list of 10**12 tuples.
    monkeypatch.setattr(mem, "available_bytes", lambda: 1 << 62)
    backend = _FirstSpanOnly()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        monte_carlo(SMALL, small_filters(), 10**12, 1, chunk_size=1, store="summary", backend=backend)
    assert backend.first == (0, 1)
    assert time.perf_counter() - t0 < 5


def test_a_gaussian_filter_is_never_told_to_lower_particles():
    with pytest.raises(MemoryNeeded) as e:
        check_memory(FIVE, small_filters(), 3, 3, store="full", keep_cov=True, available=1024)
    assert "particles" not in str(e.value) and e.value.field in ("runs", "steps")


def test_a_maneuvering_target_with_an_enormous_horizon_is_refused_before_its_truth_is_integrated():
    from pursuit.scenarios import ManeuveringTarget

    t0 = time.perf_counter()
    target = ManeuveringTarget(horizon=10**7)  # integrating its truth at construction took minutes
    with pytest.raises(MemoryNeeded, match=r"^horizon: one run of 9999998 steps needs about .*lower the scenario's horizon"):
        check_memory(target, [pu.KalmanFilter(target.motion, target.measurement)], 10, 10, store="full", keep_cov=True,
                     available=1 << 34)
    assert time.perf_counter() - t0 < 5
    small = ManeuveringTarget(horizon=50)
    assert small.true_states().shape == (50, 9) and small.true_states() is small.true_states()


def test_workers_beyond_the_number_of_chunks_are_not_counted(monkeypatch):
    # found in review: --workers 8 with one chunk was planned as 8 chunks in flight
    from pursuit.engine import montecarlo

    seen = []
    real = montecarlo.check_memory
    monkeypatch.setattr(montecarlo, "check_memory", lambda *a, **k: (seen.append(k["in_flight"]), real(*a, **k))[1])
    from .helpers import SMALL, small_filters

    montecarlo.monte_carlo(SMALL, small_filters(), 6, 1, chunk_size=3, backend=Serial8())
    assert seen == [2]  # two chunks of 3 runs, not eight


class Serial8:
    """A backend that says it has 8 workers and computes in this process (what check_memory is told is the point)."""

    workers = 8

    def map_chunks(self, task, spans, on_result, **serial_kwargs):
        for span in spans:
            on_result(span, task(*span, **serial_kwargs))

    def describe(self):
        return {"backend": "test", "workers": 8}

    def close(self):
        pass
