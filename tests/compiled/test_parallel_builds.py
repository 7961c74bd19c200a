"""The parallel kernel builds give the serial builds' bits (``PURSUIT_NUMBA_PARALLEL``).

``make test`` runs on the serial builds only (``PURSUIT_NUMBA_PARALLEL=0``: the parallel builds cost
about four times the compile time); this slow module compiles the parallel ones and checks every
compiled filter family batched through them, step by step and whole sequence, against the serial
builds (docs/compiled-backend.md#threads).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import pursuit as pu  # noqa: E402
from pursuit._compiled import gauss_kernels, particle  # noqa: E402
from pursuit.rng import run_streams  # noqa: E402
from pursuit.scenarios import LinearCV, WSNRange  # noqa: E402

from ..filters.cases import CASES  # noqa: E402

# three blocks of the Gaussian step kernels (the last one short): the parallel builds' prange and the
# generated KF's thread pool (blocks of 128) split the batch among threads
RUNS = 2 * gauss_kernels.BLOCK + 7

NUMBA_CASES = [c for c in CASES if c.id.endswith("-numba")]


def _scenario(case):
    if case.scenario is not None:
        return case.scenario
    return LinearCV(ndim=2, steps=6) if case.id.startswith("kf-") else WSNRange(steps=6)


def _track(case, parallel: bool, sequence: bool, monkeypatch) -> pu.Track:
    monkeypatch.setattr(particle, "PARALLEL", parallel)
    assert particle.use_parallel(RUNS) is parallel
    scenario = _scenario(case)
    sim = scenario.simulate(run_streams(1, range(RUNS), 0), RUNS)
    filt = case.build(scenario)
    return pu.run(filt, sim.measurements, sim.prior, rng=run_streams(2, range(RUNS), 1), sequence=sequence)


@pytest.mark.slow
@pytest.mark.parametrize("sequence", [True, False], ids=["sequence", "step"])
@pytest.mark.parametrize("case", NUMBA_CASES, ids=[c.id for c in NUMBA_CASES])
def test_parallel_builds_give_the_serial_builds_bits(case, sequence, monkeypatch):
    serial = _track(case, False, sequence, monkeypatch)
    parallel = _track(case, True, sequence, monkeypatch)
    assert parallel.mean.tobytes() == serial.mean.tobytes()
    if serial.cov is not None:
        assert parallel.cov.tobytes() == serial.cov.tobytes()
    assert parallel.info.keys() == serial.info.keys()
    for key in serial.info:
        assert np.asarray(parallel.info[key]).tobytes() == np.asarray(serial.info[key]).tobytes(), key


@pytest.mark.parametrize("value, allowed", [(None, True), ("1", True), ("0", False), (" 0 ", False)])
def test_the_environment_variable_chooses_the_builds(value, allowed):
    environ = {} if value is None else {"PURSUIT_NUMBA_PARALLEL": value}
    assert particle._parallel_allowed(environ) is allowed


@pytest.mark.parametrize("value", ["2", "yes", "", "true"])
def test_a_bad_value_of_the_environment_variable_is_an_error_naming_it(value):
    with pytest.raises(ValueError, match="PURSUIT_NUMBA_PARALLEL: expected 0 or 1"):
        particle._parallel_allowed({"PURSUIT_NUMBA_PARALLEL": value})


def _shared_generator_run(monkeypatch, parallel: bool, sequence: bool) -> pu.Track:
    """A bootstrap PF batch on one NumPy Generator: the kernels resample with NumPy's uniforms."""
    monkeypatch.setattr(particle, "PARALLEL", parallel)
    scenario = WSNRange(steps=6)
    sim = scenario.simulate(run_streams(1, range(RUNS), 0), RUNS)
    filt = pu.BootstrapParticleFilter(scenario.motion, scenario.measurement, particles=200, backend="numba")
    return pu.run(filt, sim.measurements, sim.prior, rng=np.random.default_rng(5), sequence=sequence)


@pytest.mark.slow
@pytest.mark.parametrize("sequence", [True, False], ids=["sequence", "step"])
def test_the_shared_generator_resampling_gives_the_same_bits_on_both_builds(sequence, monkeypatch):
    serial = _shared_generator_run(monkeypatch, False, sequence)
    parallel = _shared_generator_run(monkeypatch, True, sequence)
    assert serial.info["resampled"].any()  # the resampling kernel ran
    assert parallel.mean.tobytes() == serial.mean.tobytes()
    for key in serial.info:
        assert np.asarray(parallel.info[key]).tobytes() == np.asarray(serial.info[key]).tobytes(), key


def test_serial_builds_only_never_call_a_parallel_build(monkeypatch):
    """``PURSUIT_NUMBA_PARALLEL=0`` keeps the shared-Generator resampling serial too (it always took the parallel build)."""
    from pursuit._compiled import pf_kernels

    def refuse(*args):
        raise AssertionError("a parallel build ran")

    monkeypatch.setattr(pf_kernels, "pf_resample_parallel", refuse)
    monkeypatch.setattr(pf_kernels, "pf_step_parallel", refuse)
    track = _shared_generator_run(monkeypatch, False, sequence=False)
    assert track.info["resampled"].any()
