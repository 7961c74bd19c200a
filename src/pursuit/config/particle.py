"""Registrations of the particle filters and the UNGM scenario."""

from __future__ import annotations

from typing import Any

from ..filters.cuckoo import CSPF, ICSPF, CuckooSearch
from ..filters.particle import BootstrapParticleFilter
from ..filters.resample import RESAMPLERS
from ..filters.upf import PartialUPF
from ..registry import Param, field_param, params_from, register
from ..scenarios.ungm import UNGM
from .filters import BACKEND, NAME

_RESAMPLER_DOC = "resampling scheme"
_PARTICLES_DOC = "number of particles N per run"


def _particle_params(cls: type) -> tuple[Param, ...]:
    """``particles`` and ``resampler``, shared by every particle filter, from ``cls``."""
    return params_from(
        cls,
        ["particles", "resampler"],
        docs={"particles": _PARTICLES_DOC, "resampler": _RESAMPLER_DOC},
        choices={"resampler": tuple(RESAMPLERS)},
    )


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
        *_particle_params(BootstrapParticleFilter),
        Param("resample", "str", "always", "when to resample", choices=("always", "ess", "never"), own=True),
        # the class's ess_threshold = None means "always"; here it is the threshold used with resample = 'ess'
        Param("ess_threshold", "float", 0.5, "with resample = 'ess': resample when ESS < ess_threshold * N", own=True),
        BACKEND,
    ),
    aliases=("sir",),
    target=BootstrapParticleFilter,
)
def _pf(scenario, where="filter", *, resample: str, ess_threshold: float, **kw):
    thr = {"always": None, "ess": ess_threshold, "never": 0.0}[resample]
    return _checked(where, lambda: BootstrapParticleFilter(scenario.motion, scenario.measurement, ess_threshold=thr, **kw))


@register(
    "filter",
    "upf",
    "Partial-UKF unscented particle filter (patent CN101631395B): a fraction l of the particles get a UKF proposal",
    params=(
        NAME,
        *params_from(
            PartialUPF,
            ["particles", "fraction", "resampler", "ess_threshold", "select", "rounding", "cov_mode", "alpha", "beta", "kappa", "singular_noise", "jitter"],
            choices={
                "resampler": tuple(RESAMPLERS),
                "select": ("weight", "random", "block"),
                "rounding": ("nearest", "floor", "ceil"),
                "cov_mode": ("population", "propagate", "reset", "zero"),
                "singular_noise": ("cwna", "jitter"),
            },
            docs={
                "particles": _PARTICLES_DOC,
                "fraction": "l: share of particles with a UKF proposal (0 = bootstrap PF, 1 = full UPF)",
                "resampler": _RESAMPLER_DOC,
                "ess_threshold": "resample when ESS < ess_threshold * N (the patent's N/2)",
                "select": "important particles",
                "rounding": "n_u from l*N",
                "cov_mode": "covariance of prior-group particles",
                "alpha": "unscented-transform spread",
                "beta": "unscented-transform prior-knowledge weight",
                "kappa": "unscented-transform secondary scaling",
                "singular_noise": "replacement for a singular process noise",
                "jitter": "with singular_noise = 'jitter': added to the diagonal of Q",
            },
        ),
    ),
    target=PartialUPF,
)
def _upf(scenario, where="filter", **kw):
    return _checked(where, lambda: PartialUPF(scenario.motion, scenario.measurement, **kw))


# the cuckoo-search keys: TOML key -> field of the filter's default CuckooSearch (`search`)
_SEARCH_DOCS = {
    "n_iter": "cuckoo iterations per time step",
    "levy_beta": "Lévy stability index beta = lambda - 1, in (0, 2]",
    "step_scaling": "Lévy step scaling (unset: relative for greedy acceptance; mh takes only absolute)",
    "discovery": "move entries with s > Pa (yang) or s < Pa",
    "f_stop": "greedy only: stop a run's iterations once its best fitness reaches this (0, 1]",
    "lower": "greedy only: per-dimension lower bounds applied after each move",
    "upper": "greedy only: per-dimension upper bounds applied after each move",
}
_FILTER_DOCS = {
    "acceptance": "mh: resample-move with Metropolis-Hastings cuckoo moves that keep the posterior; greedy: the paper-literal search (can diverge)",
    "weight_mode": "greedy only: weights after the moves (unset: reset)",
    "ess_threshold": "greedy with weight_mode = 'sequential': resample when ESS < ess_threshold * N",
    "estimate": "mean of the moved particles; weighted (mh): weighted mean before resampling; best (greedy): best nest",
}


def _cuckoo_common(cls: type) -> tuple[Param, ...]:
    """The keys CS-PF and ICS-PF share, with ``cls``'s defaults."""
    return (
        *params_from(
            cls,
            ["search.n_iter", "search.beta", "search.step_scaling", "search.discovery", "search.f_stop", "search.lower", "search.upper"],
            rename={"search.beta": "levy_beta"},
            types={"lower": "vector", "upper": "vector"},
            choices={"step_scaling": ("relative", "absolute", "std"), "discovery": ("yang", "literal_pa")},
            docs=_SEARCH_DOCS,
        ),
        *params_from(
            cls,
            ["acceptance", "weight_mode", "ess_threshold", "estimate"],
            choices={"acceptance": ("mh", "greedy"), "weight_mode": ("reset", "sequential"), "estimate": ("mean", "weighted", "best")},
            docs=_FILTER_DOCS,
        ),
        *params_from(cls, ["resampler"], choices={"resampler": tuple(RESAMPLERS)}, docs={"resampler": _RESAMPLER_DOC}),
        BACKEND,
    )


def _cuckoo_filter(cls, scenario, where: str, search_kw: dict[str, Any], kw: dict[str, Any]):
    """Build ``cls`` with a :class:`CuckooSearch` from the search keys of ``kw`` (mapped back to its fields)."""
    kw = dict(kw)
    search_kw = dict(search_kw)
    for key in ("n_iter", "step_scaling", "discovery", "f_stop", "lower", "upper"):
        search_kw[key] = kw.pop(key)
    search_kw["beta"] = kw.pop("levy_beta")

    def build():
        return cls(scenario.motion, scenario.measurement, search=CuckooSearch(**search_kw), **kw)

    return _checked(where, build)


@register(
    "filter",
    "cs-pf",
    "Cuckoo-search particle filter (CS-PF): Metropolis-Hastings moves by Lévy flights and discovery with a fixed step size and discovery probability (acceptance = \"greedy\": the paper-literal search)",
    params=(
        NAME,
        field_param(CSPF, "particles", doc=_PARTICLES_DOC),
        # CS-PF's constant step and Pa: one key each, set as both ends of CuckooSearch's schedules
        field_param(CSPF, "search.alpha_max", name="alpha", doc="Lévy step size"),
        field_param(CSPF, "search.pa_max", name="pa", doc="discovery probability"),
        *_cuckoo_common(CSPF),
    ),
    target=CSPF,
)
def _cs_pf(scenario, where="filter", *, alpha: float, pa: float, **kw):
    search = dict(alpha_max=alpha, alpha_min=alpha, pa_max=pa, pa_min=pa, pa_schedule="constant", trend="off")
    return _cuckoo_filter(CSPF, scenario, where, search, kw)


_ICS_KEYS = ("alpha_max", "alpha_min", "pa_max", "pa_min", "pa_schedule", "trend", "kappa")


@register(
    "filter",
    "ics-pf",
    "Improved cuckoo-search particle filter (Wei & Guo, \"WSN target tracking based on improved cuckoo particle filter algorithm\"): shrinking step size and Pa, fitness-trend step; Metropolis-Hastings moves (acceptance = \"greedy\": the paper-literal search)",
    params=(
        NAME,
        field_param(ICSPF, "particles", doc=_PARTICLES_DOC),
        *params_from(
            ICSPF,
            [f"search.{k}" for k in _ICS_KEYS],
            choices={"pa_schedule": ("sine", "linear", "cosine", "constant"), "trend": ("exp", "linear", "off")},
            docs={
                "alpha_max": "step size at the first iteration",
                "alpha_min": "step size at the last iteration",
                "pa_max": "discovery probability at the first iteration",
                "pa_min": "discovery probability at the last iteration",
                "pa_schedule": "shape of the Pa schedule",
                "trend": "fitness-trend factor on the step size",
                "kappa": "trend gain",
            },
        ),
        *_cuckoo_common(ICSPF),
    ),
    target=ICSPF,
)
def _ics_pf(scenario, where="filter", **kw: Any):
    search = {k: kw.pop(k) for k in _ICS_KEYS}
    return _cuckoo_filter(ICSPF, scenario, where, search, kw)


@register(
    "scenario",
    "ungm",
    "Univariate nonstationary growth model, the classic nonlinear benchmark (Gordon, Salmond & Smith 1993); state [x]",
    params=params_from(
        UNGM,
        ["steps", "q", "r", "x0", "P0", "prior_mean"],
        docs={
            "steps": "number of measurement steps K",
            "q": "process-noise variance Q",
            "r": "measurement-noise variance R",
            "x0": "true initial state",
            "P0": "prior variance of the filters",
            "prior_mean": "prior mean: x0 itself or drawn from N(x0, P0)",
        },
    ),
    target=UNGM,
)
def _ungm(where: str = "scenario", **kw) -> UNGM:
    try:
        return UNGM(**kw)
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None
