"""Registrations of the particle filters and the UNGM scenario."""

from __future__ import annotations

from typing import Any

from ..filters.cuckoo import CSPF, ICSPF, CuckooSearch
from ..filters.particle import BootstrapParticleFilter
from ..filters.resample import RESAMPLERS
from ..filters.upf import PartialUPF
from ..registry import Param, register
from ..scenarios.ungm import UNGM
from .filters import BACKEND, NAME

_RESAMPLER = Param("resampler", "str", "systematic", "resampling scheme", choices=tuple(RESAMPLERS))
_PARTICLES = Param("particles", "int", 1000, "number of particles N per run")


def _checked(where: str, build):
    try:
        return build()
    except TypeError as e:  # the filter cannot use this scenario's models
        raise ValueError(f"{where}.type: {e}") from None
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


@register(
    "filter",
    "pf",
    "Bootstrap / SIR particle filter (prior proposal; resample every step or on low ESS)",
    params=(
        NAME,
        _PARTICLES,
        _RESAMPLER,
        Param("resample", "str", "always", "when to resample", choices=("always", "ess", "never")),
        Param("ess_threshold", "float", 0.5, "with resample = 'ess': resample when ESS < ess_threshold * N"),
        BACKEND,
    ),
    aliases=("sir",),
)
def _pf(
    scenario, where="filter", name=None, particles=1000, resampler="systematic", resample="always", ess_threshold=0.5, backend=None
):
    thr = {"always": None, "ess": ess_threshold, "never": 0.0}[resample]
    return _checked(
        where,
        lambda: BootstrapParticleFilter(
            scenario.motion,
            scenario.measurement,
            particles=particles,
            resampler=resampler,
            ess_threshold=thr,
            name=name or "",
            backend=backend,
        ),
    )


@register(
    "filter",
    "upf",
    "Partial-UKF unscented particle filter (patent CN101631395B): a fraction l of the particles get a UKF proposal",
    params=(
        NAME,
        _PARTICLES,
        Param("fraction", "float", 0.5, "l: share of particles with a UKF proposal (0 = bootstrap PF, 1 = full UPF)"),
        _RESAMPLER,
        Param("ess_threshold", "float", 0.5, "resample when ESS < ess_threshold * N (the patent's N/2)"),
        Param("select", "str", "weight", "important particles", choices=("weight", "random", "block")),
        Param("rounding", "str", "nearest", "n_u from l*N", choices=("nearest", "floor", "ceil")),
        Param("cov_mode", "str", "population", "covariance of prior-group particles", choices=("population", "propagate", "reset", "zero")),
        Param("alpha", "float", 1.0, "unscented-transform spread"),
        Param("beta", "float", 2.0, "unscented-transform prior-knowledge weight"),
        Param("kappa", "float", 0.0, "unscented-transform secondary scaling"),
        Param("singular_noise", "str", "cwna", "replacement for a singular process noise", choices=("cwna", "jitter")),
        Param("jitter", "float", 1e-6, "with singular_noise = 'jitter': added to the diagonal of Q"),
    ),
)
def _upf(scenario, where="filter", name=None, **kw):
    return _checked(where, lambda: PartialUPF(scenario.motion, scenario.measurement, name=name or "", **kw))


_CUCKOO_COMMON = (
    Param("n_iter", "int", 10, "cuckoo iterations per time step"),
    Param("levy_beta", "float", 1.5, "Lévy stability index beta = lambda - 1, in (0, 2]"),
    Param("step_scaling", "str", "relative", "Lévy step scaling", choices=("relative", "absolute", "std")),
    Param("discovery", "str", "yang", "move entries with s > Pa (yang) or s < Pa", choices=("yang", "literal_pa")),
    Param("f_stop", "float", None, "stop a run's iterations once its best fitness reaches this (0, 1]"),
    Param("lower", "vector", None, "per-dimension lower bounds applied after each move"),
    Param("upper", "vector", None, "per-dimension upper bounds applied after each move"),
    Param("weight_mode", "str", "reset", "weights after the moves", choices=("reset", "sequential")),
    Param("ess_threshold", "float", 0.5, "with weight_mode = 'sequential': resample when ESS < ess_threshold * N"),
    Param("estimate", "str", "mean", "weighted mean or best nest", choices=("mean", "best")),
    _RESAMPLER,
    BACKEND,
)


def _cuckoo_filter(cls, scenario, where, name, particles, search_kw, common):
    common = dict(common)
    search_kw = dict(search_kw)
    for key in ("n_iter", "step_scaling", "discovery", "f_stop", "lower", "upper"):
        search_kw[key] = common.pop(key)
    search_kw["beta"] = common.pop("levy_beta")

    def build():
        search = CuckooSearch(**search_kw)
        return cls(scenario.motion, scenario.measurement, particles=particles, search=search, name=name or "", **common)

    return _checked(where, build)


@register(
    "filter",
    "cs-pf",
    "Cuckoo-search particle filter (CS-PF): particles moved by Lévy flights with a fixed step size and discovery probability",
    params=(
        NAME,
        _PARTICLES,
        Param("alpha", "float", 0.01, "Lévy step size"),
        Param("pa", "float", 0.25, "discovery probability"),
        *_CUCKOO_COMMON,
    ),
)
def _cs_pf(scenario, where="filter", name=None, particles=1000, alpha=0.01, pa=0.25, **common):
    search = dict(alpha_max=alpha, alpha_min=alpha, pa_max=pa, pa_min=pa, pa_schedule="constant", trend="off")
    return _cuckoo_filter(CSPF, scenario, where, name, particles, search, common)


@register(
    "filter",
    "ics-pf",
    "Improved cuckoo-search particle filter (Wei & Guo, \"WSN target tracking based on improved cuckoo particle filter algorithm\"): shrinking step size and Pa, fitness-trend step",
    params=(
        NAME,
        _PARTICLES,
        Param("alpha_max", "float", 0.5, "step size at the first iteration"),
        Param("alpha_min", "float", 0.01, "step size at the last iteration"),
        Param("pa_max", "float", 0.3, "discovery probability at the first iteration"),
        Param("pa_min", "float", 0.01, "discovery probability at the last iteration"),
        Param("pa_schedule", "str", "sine", "shape of the Pa schedule", choices=("sine", "linear", "cosine", "constant")),
        Param("trend", "str", "exp", "fitness-trend factor on the step size", choices=("exp", "linear", "off")),
        Param("kappa", "float", 1.0, "trend gain"),
        *_CUCKOO_COMMON,
    ),
)
def _ics_pf(
    scenario,
    where="filter",
    name=None,
    particles=1000,
    alpha_max=0.5,
    alpha_min=0.01,
    pa_max=0.3,
    pa_min=0.01,
    pa_schedule="sine",
    trend="exp",
    kappa=1.0,
    **common: Any,
):
    search = dict(
        alpha_max=alpha_max, alpha_min=alpha_min, pa_max=pa_max, pa_min=pa_min, pa_schedule=pa_schedule, trend=trend, kappa=kappa
    )
    return _cuckoo_filter(ICSPF, scenario, where, name, particles, search, common)


@register(
    "scenario",
    "ungm",
    "Univariate nonstationary growth model, the classic nonlinear benchmark (Gordon, Salmond & Smith 1993); state [x]",
    params=(
        Param("steps", "int", 50, "number of measurement steps K"),
        Param("q", "float", 1.0, "process-noise variance Q"),
        Param("r", "float", 1.0, "measurement-noise variance R"),
        Param("x0", "float", 0.1, "true initial state"),
        Param("P0", "float", 2.0, "prior variance of the filters"),
        Param("prior_mean", "str", "truth", "prior mean: x0 itself or drawn from N(x0, P0)", choices=("truth", "sampled")),
    ),
)
def _ungm(where: str = "scenario", **kw) -> UNGM:
    try:
        return UNGM(**kw)
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None
