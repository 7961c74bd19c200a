"""Innovation-driven fading factors: EWFMKF (exponentially weighted) and STF (strong tracking).

Both strategies compare the covariance of the innovations the filter actually
sees with the one it predicts, and fade when the actual one is larger:

    N_k = Ĉ_k − H_k Q_k H_kᵀ − β R_k,     M_k = H_k P̄_k H_kᵀ,
    λ_k = min(λ_max, ceiling_k, max(1, tr N_k / tr M_k)),

where P̄_k = F P_{k−1} Fᵀ is the propagated covariance before Q and Ĉ_k is
a running estimate of E[ν_k ν_kᵀ] (ν_k = z_k − h(x̂⁻_k)).  With λ_k in place
of 1, the filter's predicted innovation covariance H(λ P̄ + Q)Hᵀ + R matches
Ĉ_k in trace.  The two strategies differ only in how they average ν νᵀ:

* :class:`ExponentiallyWeighted` (EWFMKF of paper P2; docs/spec/03-fading-memory-ekf.md §4.2, a
  reconstruction): Sage–Husa weights d_j = (1 − b)/(1 − b^{j+1}), so early
  steps are averaged with equal weight and later ones are forgotten at rate b;
* :class:`StrongTracking` (Zhou Donghua's suboptimal fading factor; docs/spec/03-fading-memory-ekf.md
  §4.3): V_1 = ν_1ν_1ᵀ, V_j = (ρ V_{j−1} + ν_jν_jᵀ)/(1 + ρ), with a weakening
  factor β ≥ 1 on R.

λ_max defaults to :data:`LAM_MAX` = 1e4, the bound docs/spec/03-fading-memory-ekf.md §4.4 gives IFMKF, and
the numerical ceiling max(1, κ tr R / tr(H P̄ Hᵀ)) (κ = 1/√ε, see
:attr:`~pursuit.filters.fading.FadingContext.lam_ceiling`) applies whatever
λ_max is.  Both bind only far from the TOA experiments' values (λ of order
10² to 10⁴), but without them the trace ratio reaches 1e10 to 1e28 once a
filter has lost the target on irregularly sampled data (a short step after
a long one, where P̄ is tiny against the innovations remembered in Ĉ), and
the covariances lose positive definiteness (tests/filters/test_robustness.py).

Only traces enter λ, so only the diagonals of Ĉ, HQHᵀ, R and HP̄Hᵀ are
computed.  j counts the steps at which something was measured; a missing
component keeps its running average and is left out of both traces.  H_k is
the filter's linearisation (:attr:`FadingContext.linearization`): the
Jacobian for the EKF, the statistical linearisation for the UKF and CKF.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import in_range
from .fading import Fade, FadingContext, diag_sandwich

__all__ = ["ExponentiallyWeighted", "StrongTracking", "TraceMemory", "diag_sandwich", "LAM_MAX"]

LAM_MAX = 1.0e4
"""Default upper bound on λ of the adaptive strategies (EWFMKF, STF, IFMKF): the λ_max of docs/spec/03-fading-memory-ekf.md §4.4."""


@dataclass(frozen=True)
class TraceMemory:
    """Running diagonal of the innovation covariance and the count of measured steps.

    Attributes
    ----------
    second_moment
        ``(*batch, m)`` running average of ν², per component; None before
        the first step.
    count
        ``(*batch,)`` number of steps with at least one measured component.
    """

    second_moment: np.ndarray | None
    count: np.ndarray


def _trace_ratio(ctx: FadingContext, second_moment: np.ndarray, beta: float, lam_max: float | np.ndarray) -> np.ndarray:
    """λ = min(λ_max, ceiling, max(1, tr N / tr M)) over the measured components (ceiling: ``ctx.lam_ceiling``)."""
    H = ctx.linearization
    valid = ctx.measured
    hqh = diag_sandwich(H, ctx.process_cov)
    hph = diag_sandwich(H, ctx.propagated_cov)
    r = np.diagonal(ctx.measurement_cov)
    tr_n = np.where(valid, second_moment - hqh - beta * r, 0.0).sum(axis=-1)
    tr_m = np.where(valid, hph, 0.0).sum(axis=-1)
    # tr M = 0 (nothing measured, or no propagated uncertainty): no fading.
    ratio = np.divide(tr_n, tr_m, out=np.ones_like(tr_n), where=tr_m > 0)
    return np.minimum(np.maximum(ratio, 1.0), np.minimum(lam_max, ctx.lam_ceiling))


def _update_moment(ctx: FadingContext, memory: TraceMemory, weight_new) -> TraceMemory:
    """Blend ν² into the running average with weight ``weight_new(count)`` (1 on the first step)."""
    valid = ctx.measured
    nu = np.where(valid, ctx.innovation, 0.0)
    sq = nu * nu
    any_valid = valid.any(axis=-1)
    d = weight_new(memory.count)[..., None]
    prev = sq if memory.second_moment is None else memory.second_moment
    blended = (1.0 - d) * prev + d * sq
    moment = np.where(valid, blended, prev)
    count = memory.count + any_valid
    return TraceMemory(moment, count)


@dataclass(frozen=True)
class ExponentiallyWeighted:
    """EWFMKF: exponentially weighted adaptive fading factor (paper P2's baseline).

    The running innovation covariance uses the Sage–Husa weights
    d_j = (1 − b)/(1 − b^{j+1}) (j = measured steps so far; d_0 = 1), so

        Ĉ_j = (1 − d_j) Ĉ_{j−1} + d_j ν_j ν_jᵀ,
        λ_k = min(λ_max, ceiling, max(1, tr(Ĉ − HQHᵀ − R) / tr(H P̄ Hᵀ))).

    Paper P2 gives only the name, a parameter b in (0, 1) and its reference
    [14]; this form is the reconstruction of docs/spec/03-fading-memory-ekf.md §4.2 [RECON + LIT].

    Parameters
    ----------
    b
        Forgetting factor in (0, 1); larger b remembers longer (default 0.95).
    lam_max
        Upper bound on λ (default :data:`LAM_MAX` = 1e4; ``inf``: only the
        numerical ceiling; 1 gives the plain filter).
    """

    b: float = 0.95
    lam_max: float = LAM_MAX
    data_independent: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "b", in_range("b", self.b, 0.0, 1.0, low_open=True, high_open=True))
        object.__setattr__(self, "lam_max", _lam_max(self.lam_max))

    def init(self, batch: tuple[int, ...]) -> TraceMemory:
        """No innovations seen yet."""
        return TraceMemory(None, np.zeros(batch, dtype=np.int64))

    def weight(self, count: np.ndarray) -> np.ndarray:
        """d_j for j measured steps so far: (1 − b)/(1 − b^{j+1})."""
        return (1.0 - self.b) / (1.0 - self.b ** (count + 1.0))

    def factor(self, memory: TraceMemory, ctx: FadingContext) -> tuple[Fade, TraceMemory]:
        """Update Ĉ with this step's innovation and return λ_k."""
        memory = _update_moment(ctx, memory, self.weight)
        return Fade(_trace_ratio(ctx, memory.second_moment, 1.0, self.lam_max)), memory


@dataclass(frozen=True)
class StrongTracking:
    """STF: Zhou Donghua's single suboptimal fading factor.

        V_1 = ν_1ν_1ᵀ,   V_j = (ρ V_{j−1} + ν_jν_jᵀ)/(1 + ρ),
        λ_k = min(λ_max, ceiling, max(1, tr(V − HQHᵀ − β R) / tr(H P̄ Hᵀ))).

    Parameters
    ----------
    rho
        Forgetting factor in (0, 1] (default 0.95).
    beta
        Weakening factor β ≥ 1 on R (default 1): larger β fades less and
        smooths the estimate.
    lam_max
        Upper bound on λ (default :data:`LAM_MAX` = 1e4; ``inf``: only the
        numerical ceiling; 1 gives the plain filter).
    """

    rho: float = 0.95
    beta: float = 1.0
    lam_max: float = LAM_MAX
    data_independent: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "rho", in_range("rho", self.rho, 0.0, 1.0, low_open=True))
        object.__setattr__(self, "beta", in_range("beta", self.beta, 1.0, np.inf, high_open=True))
        object.__setattr__(self, "lam_max", _lam_max(self.lam_max))

    def init(self, batch: tuple[int, ...]) -> TraceMemory:
        """No innovations seen yet."""
        return TraceMemory(None, np.zeros(batch, dtype=np.int64))

    def weight(self, count: np.ndarray) -> np.ndarray:
        """Weight of the new ν νᵀ: 1 on the first measured step, then 1/(1 + ρ)."""
        return np.where(count == 0, 1.0, 1.0 / (1.0 + self.rho))

    def factor(self, memory: TraceMemory, ctx: FadingContext) -> tuple[Fade, TraceMemory]:
        """Update V with this step's innovation and return λ_k."""
        memory = _update_moment(ctx, memory, self.weight)
        return Fade(_trace_ratio(ctx, memory.second_moment, self.beta, self.lam_max)), memory


def _lam_max(value: float) -> float:
    """λ_max ≥ 1; infinity means no bound."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"lam_max: expected a number, got {value!r}")
    v = float(value)
    if not v >= 1.0:  # also refuses NaN
        raise ValueError(f"lam_max: must be at least 1 (inf for no bound), got {value!r}")
    return v
