"""How much memory a Monte Carlo comparison needs, checked before anything runs.

The estimate is built from the shapes the engine allocates (see
:func:`needed_bytes`); :func:`check_memory` refuses a comparison whose
estimate exceeds the memory available, with one line that says how much it
needs, how much there is and which setting to change.  Without it, enormous
sizes (``runs = 10**12``, ``steps = 10**18``, a million particles) ended in a
``MemoryError`` or the operating system's out-of-memory killer, after minutes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Sequence

__all__ = [
    "MemoryNeeded",
    "Estimate",
    "available_bytes",
    "format_bytes",
    "needed_bytes",
    "check_memory",
    "MEMORY_LIMIT_ENV",
]

MEMORY_LIMIT_ENV = "PURSUIT_MEMORY_LIMIT"
"""Environment variable: the memory the engine may plan for (bytes, or with K/M/G/T), instead of what is available."""

INFO_SCALARS = 8
"""Scalar step-info values per run and step counted by the estimate (NIS, dof, log-likelihood, fading
factor or ESS, flags ...: the bundled filters keep 4 to 10, some of them one byte)."""

WORK_COPIES = 12
"""Particle-sized (or sigma-point-sized) arrays a filter step holds at its peak: the particles, the
propagated copy, noise draws, the predicted measurements, weights, resampling indices and temporaries.
Measured peak / estimate (tracemalloc, WSN range, 200-1000 particles): bootstrap PF 0.77, UPF 0.94,
UKF 0.99; ``tests/engine/test_memory.py`` checks 0.6-1.1."""

CUCKOO_DRAWS_PER_ITERATION = (4, 2)
"""A cuckoo-search step also draws, for each of its ``n_iter`` iterations, ``a·n + b`` numbers per
particle at once (Lévy u, v and ξ normals, ``(n_iter, 3, N, n)``; uniforms ``(n_iter, N n + 1 + 2N)``):
with them, measured peak / estimate is 0.76 (n_iter 0) to 1.05 (n_iter 10) and 1.01 (n_iter 40).
Without them, ``n_iter = 10**7`` ended in a 671 GiB ``MemoryError``."""

MH_DRAWS_PER_ITERATION = (3, 3)
"""The same for the MH cuckoo moves (``acceptance="mh"``): ``a·r + b`` numbers per particle and
iteration, r the dimension of the process noise (Lévy u, v normals ``(n_iter, 2, N, r)``; uniforms
``(n_iter, N (r + 3) + 2)``), with room for the moves' per-half temporaries."""


class MemoryNeeded(ValueError):
    """A comparison that cannot fit in memory; the message starts with the setting to change.

    Attributes
    ----------
    field
        The setting to change: ``"runs"``, ``"chunk_size"``, ``"steps"``
        (``"horizon"`` for a scenario that has one) or ``"particles"``.
    filter_name
        For ``"particles"``, the filter whose particles dominate.
    needed, available
        Bytes.
    """

    def __init__(self, message: str, field: str, needed: int, available: int, filter_name: str | None = None):
        super().__init__(message)
        self.field, self.needed, self.available, self.filter_name = field, needed, available, filter_name


def format_bytes(n: float) -> str:
    """``1536`` → ``"1.5 KiB"``; huge sizes stay readable (``"9.1e+06 TiB"``)."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024:
            return f"{n:.0f} B" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB" if n < 1e5 else f"{n:.1e} TiB"


def _parse_size(text: str) -> int:
    text = text.strip().upper().removesuffix("B").removesuffix("I")
    scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}.get(text[-1:], 1)
    number = text[:-1] if scale > 1 else text
    value = float(number)
    if not value > 0 or value != value:
        raise ValueError
    return int(value * scale)


def available_bytes() -> int | None:
    """Memory the engine may plan for: ``$PURSUIT_MEMORY_LIMIT``, else the available physical memory.

    ``MemAvailable`` from ``/proc/meminfo`` on Linux, else the physical
    memory; None where neither can be read (then nothing is refused).

    Raises
    ------
    ValueError
        For a ``$PURSUIT_MEMORY_LIMIT`` that is not a positive size.
    """
    env = os.environ.get(MEMORY_LIMIT_ENV)
    if env:
        try:
            return _parse_size(env)
        except (ValueError, IndexError):
            raise ValueError(f"${MEMORY_LIMIT_ENV}: expected a positive size such as 8G or 500M, got {env!r}") from None
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def _measurement_dim(scenario: Any, n: int) -> int:
    """The measurement dimension m of the scenario's model (``dim``, else the size of ``cov(1)``, else n)."""
    import numpy as np

    model = getattr(scenario, "measurement", None)
    dim = getattr(model, "dim", None)
    if isinstance(dim, (int, np.integer)) and not isinstance(dim, bool):
        return int(dim)
    try:
        return int(np.shape(model.cov(1))[-1])
    except Exception:  # a user's model without dim or cov(k): the state dimension is a fair guess
        return n


def _particles(filt: Any) -> int | None:
    p = getattr(filt, "particles", None)
    return p if isinstance(p, int) and not isinstance(p, bool) and p > 0 else None


def _noise_dim(motion: Any, n: int) -> int:
    """Columns r of the motion model's noise factor (n where it cannot be asked without a step)."""
    from ..filters.cuckoo_mh import noise_factor

    try:
        return int(noise_factor(motion, 1, None).shape[1])
    except Exception:  # noqa: BLE001 - an estimate: the state dimension bounds r
        return n


def _work_floats_per_run(filt: Any, n: int, m: int) -> int:
    """Floats one filter step holds per run at its peak (see :data:`WORK_COPIES`)."""
    from ..filters.cuckoo import CuckooParticleFilter
    from ..filters.upf import PartialUPF

    particles = _particles(filt)
    if particles is None:  # Gaussian filters: sigma points through both models, and a covariance
        return WORK_COPIES * ((2 * n + 1) * (n + m) + n * n)
    per_particle = n + 1 + (n * n if isinstance(filt, PartialUPF) else 0)  # state, weight, UPF's covariance
    floats = WORK_COPIES * particles * per_particle
    if isinstance(filt, CuckooParticleFilter):
        a, b = CUCKOO_DRAWS_PER_ITERATION
        dim = n
        if filt.acceptance == "mh":
            a, b = MH_DRAWS_PER_ITERATION
            dim = _noise_dim(filt.motion, n)
        floats += int(filt.search.n_iter) * particles * (a * dim + b)
    return floats


@dataclass(frozen=True)
class Estimate:
    """Bytes a comparison needs, by what holds them.

    ``result``: what is kept for every run (full mode: every run's arrays;
    summary mode: a few floats per run and filter).  ``chunk``: one chunk's
    arrays while it is computed.  ``work``: the largest filter's working
    memory for one chunk (``work_filter``; ``work_particles``: whether it is
    a particle filter; ``work_iterations``: whether it iterates a search
    per step, whose draws grow with ``n_iter``).  ``in_flight``: chunks computed at once on this
    machine.
    """

    result: int
    chunk: int
    work: int
    in_flight: int
    work_filter: str | None
    work_particles: bool = False
    work_iterations: bool = False

    @property
    def total(self) -> int:
        return self.result + self.in_flight * (self.chunk + self.work)


def result_bytes_full(scenario: Any, n_filters: int, runs: int, keep_cov: bool) -> int:
    """Bytes of the arrays a full-mode result holds for ``runs`` runs.

    Per run and step, in float64: truth (n), measurements (m), and per filter
    its estimates (n), covariances (n², when kept) and step info: the
    innovation (m), its covariance S (m²) and :data:`INFO_SCALARS` scalars.
    """
    n = len(scenario.state_labels)
    m = _measurement_dim(scenario, n)
    steps = int(getattr(scenario, "steps", 100))
    per_filter = n + (n * n if keep_cov else 0) + m + m * m + INFO_SCALARS
    return 8 * steps * runs * (n + m + n_filters * per_filter)


def needed_bytes(
    scenario: Any, filters: Sequence[Any], runs: int, chunk_size: int, *, store: str, keep_cov: bool, in_flight: int = 1
) -> Estimate:
    """Estimate the memory of ``monte_carlo`` with these settings (``store`` is ``"full"`` or ``"summary"``)."""
    from ..reduction import component_groups

    n = len(scenario.state_labels)
    m = _measurement_dim(scenario, n)
    chunk = min(chunk_size, runs)
    if store == "full":
        result = result_bytes_full(scenario, len(filters), runs, keep_cov)
    else:  # per filter and run: one mean squared error per component group, concatenated once at the end
        groups = len(component_groups(n, scenario.position_indices, scenario.velocity_indices))
        result = 8 * 2 * groups * len(filters) * runs
    work, work_filter = 0, None
    for filt in filters:
        w = 8 * chunk * _work_floats_per_run(filt, n, m)
        if w > work:
            work, work_filter = w, filt
    chunk_bytes = result_bytes_full(scenario, len(filters), chunk, keep_cov)
    name = None if work_filter is None else getattr(work_filter, "name", type(work_filter).__name__)
    iterations = getattr(getattr(work_filter, "search", None), "n_iter", 0)
    return Estimate(
        result, chunk_bytes, work, max(1, in_flight), name, _particles(work_filter) is not None, bool(iterations)
    )


def check_memory(
    scenario: Any,
    filters: Sequence[Any],
    runs: int,
    chunk_size: int,
    *,
    store: str,
    keep_cov: bool,
    in_flight: int = 1,
    available: int | None = None,
    can_summarise: bool = True,
) -> Estimate:
    """Refuse, before anything runs, a comparison whose estimate exceeds the memory available.

    Returns the estimate when it fits (or when the memory available is
    unknown).  ``available`` overrides :func:`available_bytes`;
    ``can_summarise`` says whether the caller may switch to summary mode
    (then a full-mode refusal suggests it).

    Raises
    ------
    MemoryNeeded
        One line: the setting to change, the bytes needed, the bytes
        available and what to do.
    """
    est = needed_bytes(scenario, filters, runs, chunk_size, store=store, keep_cov=keep_cov, in_flight=in_flight)
    avail = available_bytes() if available is None else available
    if avail is None or est.total <= avail:
        return est
    need, have = f"about {format_bytes(est.total)} of memory", f"{format_bytes(avail)} available"
    per_chunk = est.in_flight * (est.chunk + est.work)
    chunk = min(chunk_size, runs)
    if est.result >= per_chunk:
        if store == "full":
            fit = max(0, (avail - per_chunk) * runs // max(est.result, 1))
            summary = "store summary (--store summary) or " if can_summarise else ""
            msg = f"runs: {runs} runs need {need} to keep every run's arrays, {have}; use {summary}at most about {fit} runs"
        else:
            fit = max(0, (avail - per_chunk) * runs // max(est.result, 1))
            msg = f"runs: {runs} runs need {need} even in summary mode, {have}; use at most about {fit} runs"
        raise MemoryNeeded(msg, "runs", est.total, avail)
    # one chunk is what does not fit
    per_run = max(1, per_chunk // chunk)
    fit = (avail - est.result) // per_run
    if chunk > 1 and fit >= 1:
        msg = f"chunk_size: chunks of {chunk} runs need {need}, {have}; use a chunk size (--chunk-size) of {fit} or less"
        raise MemoryNeeded(msg, "chunk_size", est.total, avail)
    if est.work > est.chunk and est.work_particles:
        what = "particles" + (" or n_iter" if est.work_iterations else "")
        msg = f"particles: one run of filter {est.work_filter!r} needs {need}, {have}; lower its {what}"
        raise MemoryNeeded(msg, "particles", est.total, avail, est.work_filter)
    if est.chunk >= est.work:
        steps = int(getattr(scenario, "steps", 0))
        knob = "horizon" if hasattr(scenario, "horizon") else "steps"  # the maneuvering target's is its horizon
        msg = f"{knob}: one run of {steps} steps needs {need}, {have}; lower the scenario's {knob}"
        raise MemoryNeeded(msg, knob, est.total, avail)
    msg = f"runs: one run of filter {est.work_filter!r} needs {need}, {have}"
    raise MemoryNeeded(msg, "runs", est.total, avail)
