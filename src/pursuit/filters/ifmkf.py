"""IFMKF: the improved fading-memory rule of paper P2 (divergence test, then observation-referenced λ).

Paper P2 (Ma & Zheng 2022) keeps λ = 1 unless the filter is *abnormally*
diverging, and then picks the λ that makes the updated estimate agree with
the observation.  Its equation (3) is lost; this module implements the
reconstruction of docs/spec/03-fading-memory-ekf.md §4.4, with every open choice a parameter:

1. Residual of the preliminary prediction and its expected level
   (per step k, over the measured components)::

       e_k  = ‖z_k − h(x̂⁻_k)‖_max
       w'_k = max_i sqrt( (H_k Q_k H_kᵀ)_ii )     model std mapped into the observation domain
       v_k  = max_i sqrt( R_ii )                  observation std
       τ_k  = β (w'_k + v_k)                      β = reserve coefficient

2. Divergence test (``test``):

   * ``"window"`` (default, variant c): over the last L residuals, median m
     and least-squares slope s.  Enter the diverging state when m > τ and
     s ≥ 0; stay in it while m > τ (``hysteresis``); never diverging during
     the first L measured steps.  The median ignores an isolated outlier and
     a decaying start-up transient has s < 0.
   * ``"instant"`` (variant a): e_k > τ_k, the classical criterion.
   * ``"mean"`` (variant b): the mean of e over all steps so far > τ_k.

3. Outlier gate (``gate``): while not diverging, a residual
   e_k > g·max(τ_k, m_{k−1}) (m_{k−1} = median of the previous L residuals)
   skips the measurement update at k (prediction only, λ = 1, even if the
   test of step 2 now reports divergence), at most G consecutive steps,
   never in the first L.  The spec gates only when m_{k−1} ≤ τ; where that
   holds the two rules agree.  Ours also gates a residual g times above a
   median that sits just over τ (measured on the TOA scenario: about 1 run
   in 300 at each step, and such a run then faded on the outlier), and
   still never gates the large but typical residuals of a filter that is
   falling behind (m_{k−1} ≫ τ).

4. λ when diverging (``search``):

   * ``"consistent"`` (default, variant i): the smallest λ in [1, λ_max] with
     ‖z_k − h(x̂_k(λ))‖_max ≤ β v_k, where x̂_k(λ) is the filter's update with
     P⁻ = λP̄ + Q.  Found by bisection on log λ.  The max-norm residual of
     a vector measurement need not decrease monotonically in λ; where the
     bisection sees it grow while still above the level (a hint that it may
     dip below the level further left), the run also searches the log grid
     and keeps the smaller λ that fits.  If even λ_max does not reach the
     level (``unreachable``):

     - ``"innovation"`` (default): the one-step innovation-matching factor
       λ_ν = min(λ_max, max(1, tr(ν νᵀ − H Q Hᵀ − R) / tr(H P̄ Hᵀ))) over
       the measured components, the largest fading the innovation itself
       supports (with it, the predicted innovation covariance
       H(λP̄ + Q)Hᵀ + R matches ν νᵀ in trace);
     - ``"lam_max"`` (the spec's default): λ_max;
     - ``"minimise"``: the grid λ with the smallest post-fit residual.

     The trial update is one linearised step, so the level can be out of
     reach at any λ.  On the TOA "actual" condition that happens in 2 % of
     the EKF's diverging run-steps, and in about 20 % of the UKF's and CKF's:
     at large λ their sigma points spread far beyond the region where the
     ranges are nearly linear and the post-fit residual grows again.  The
     spec's λ_max then inflates P̄ ten thousandfold.  The EKF survives that
     (its update only forgets the past), but for the UKF and CKF the
     sigma points land 100 times further out, the linearisation-error
     covariance D keeps the posterior from collapsing, and the next step
     multiplies the larger P̄ by λ_max again, until overflow (measured:
     position RMSE ~1e79 m, a third of the runs, within 60 steps).  λ_ν
     keeps λP̄ at the size of the error the innovation shows.
   * ``"minimise"`` (variant ii): the λ on the log grid minimising the
     post-fit residual (smallest such λ).
   * ``"stf"`` (variant iii): the strong-tracking factor with forgetting
     factor ``rho``.

Everything is vectorised over the batch; the bisection is a fixed number of
trial updates of the whole batch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import in_range, positive, positive_int
from .fading import Fade, FadingContext
from .fading_adaptive import LAM_MAX, StrongTracking, TraceMemory, _trace_ratio, _update_moment, diag_sandwich

__all__ = ["Improved", "ImprovedMemory"]

TESTS = ("window", "instant", "mean")
SEARCHES = ("consistent", "minimise", "stf")
UNREACHABLE = ("innovation", "lam_max", "minimise")

# Relative slack when checking that the post-fit residual does not grow with λ.
_MONOTONE_RTOL = 1e-9


@dataclass(frozen=True)
class ImprovedMemory:
    """Per-run state of the IFMKF rule.

    Attributes
    ----------
    window
        ``(*batch, L)`` the last L residuals e, oldest first.
    count
        ``(*batch,)`` steps with at least one measured component.
    total
        ``(*batch,)`` sum of all residuals (for ``test="mean"``).
    diverging
        ``(*batch,)`` the diverging state after the last step.
    gated_run
        ``(*batch,)`` consecutive gated steps up to the last step.
    stf
        The strong-tracking memory (only for ``search="stf"``).
    """

    window: np.ndarray
    count: np.ndarray
    total: np.ndarray
    diverging: np.ndarray
    gated_run: np.ndarray
    stf: TraceMemory | None = None


@dataclass(frozen=True)
class Improved:
    """IFMKF fading strategy: fade only on abnormal divergence, just enough to agree with the observation.

    Parameters
    ----------
    beta
        Reserve coefficient β of the divergence threshold τ = β(w' + v) and
        of the post-fit level β v (default 3).
    window
        Window length L of the divergence test and of the gate (default 5).
    test
        Divergence test: ``"window"`` (default), ``"instant"`` or ``"mean"``.
    hysteresis
        With ``test="window"``: stay diverging while the median exceeds τ,
        whatever the slope (default True).
    search
        How λ is chosen when diverging: ``"consistent"`` (default),
        ``"minimise"`` or ``"stf"``.
    lam_max
        Largest λ considered (default 1e4).  The numerical ceiling
        :attr:`~pursuit.filters.fading.FadingContext.lam_ceiling` also
        bounds every search.
    iterations
        Bisection steps on log λ (default 20: λ to a relative 1e-5 for λ_max = 1e4).
    grid
        Points of the log grid for ``search="minimise"`` and for the
        bisection's fallback (default 200).
    gate
        Skip the update for an isolated outlier (default True).
    gate_factor
        g: a residual above g·max(τ, median of the last L) counts as an
        outlier (default 10).
    gate_max
        G: at most this many consecutive gated steps (default 2).
    rho
        Forgetting factor for ``search="stf"`` (default 0.95).
    unreachable
        With ``search="consistent"``, what to do when λ_max does not bring
        the post-fit residual to β v: ``"innovation"`` (default; the
        one-step innovation-matching factor, see the module docstring),
        ``"lam_max"`` (the choice of docs/spec/03-fading-memory-ekf.md §4.4; makes the UKF and CKF diverge) or
        ``"minimise"`` (the grid minimiser of the post-fit residual; costs
        ``grid`` trial updates of the batch at each such step).
    """

    beta: float = 3.0
    window: int = 5
    test: str = "window"
    hysteresis: bool = True
    search: str = "consistent"
    lam_max: float = LAM_MAX
    iterations: int = 20
    grid: int = 200
    gate: bool = True
    gate_factor: float = 10.0
    gate_max: int = 2
    rho: float = 0.95
    unreachable: str = "innovation"
    data_independent: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "beta", positive("beta", self.beta))
        object.__setattr__(self, "window", positive_int("window", self.window))
        if self.test not in TESTS:
            raise ValueError(f"test: must be one of {', '.join(TESTS)}, got {self.test!r}")
        if self.search not in SEARCHES:
            raise ValueError(f"search: must be one of {', '.join(SEARCHES)}, got {self.search!r}")
        if self.unreachable not in UNREACHABLE:
            raise ValueError(f"unreachable: must be one of {', '.join(UNREACHABLE)}, got {self.unreachable!r}")
        if not isinstance(self.hysteresis, bool):
            raise ValueError(f"hysteresis: expected true or false, got {self.hysteresis!r}")
        if not isinstance(self.gate, bool):
            raise ValueError(f"gate: expected true or false, got {self.gate!r}")
        object.__setattr__(self, "lam_max", in_range("lam_max", self.lam_max, 1.0, 1.0e300))
        object.__setattr__(self, "iterations", positive_int("iterations", self.iterations))
        if isinstance(self.grid, bool) or not isinstance(self.grid, (int, np.integer)) or self.grid < 2:
            raise ValueError(f"grid: must be an integer of at least 2, got {self.grid!r}")
        object.__setattr__(self, "gate_factor", in_range("gate_factor", self.gate_factor, 1.0, np.inf, high_open=True))
        object.__setattr__(self, "gate_max", positive_int("gate_max", self.gate_max))
        object.__setattr__(self, "rho", in_range("rho", self.rho, 0.0, 1.0, low_open=True))

    # -- strategy protocol ----------------------------------------------------
    def init(self, batch: tuple[int, ...]) -> ImprovedMemory:
        """Empty window, normal regime."""
        stf = StrongTracking(self.rho).init(batch) if self.search == "stf" else None
        return ImprovedMemory(
            window=np.zeros((*batch, self.window)),
            count=np.zeros(batch, dtype=np.int64),
            total=np.zeros(batch),
            diverging=np.zeros(batch, dtype=bool),
            gated_run=np.zeros(batch, dtype=np.int64),
            stf=stf,
        )

    def factor(self, memory: ImprovedMemory, ctx: FadingContext) -> tuple[Fade, ImprovedMemory]:
        """Divergence test, outlier gate and λ for this step."""
        valid = ctx.measured
        seen = valid.any(axis=-1)  # something measured at this step
        e = _max_abs(ctx.innovation, valid)
        e_or_0 = np.where(seen, e, 0.0)
        hqh = diag_sandwich(ctx.linearization, ctx.process_cov)
        w_prime = np.sqrt(np.maximum(_max_over(hqh, valid), 0.0))
        v = np.sqrt(_max_over(np.broadcast_to(np.diagonal(ctx.measurement_cov), valid.shape), valid))
        tau = self.beta * (w_prime + v)

        L = self.window
        was_full = memory.count >= L
        median_before = np.median(memory.window, axis=-1)
        shifted = np.concatenate([memory.window[..., 1:], e_or_0[..., None]], axis=-1)
        window = np.where(seen[..., None], shifted, memory.window)
        count = memory.count + seen
        total = memory.total + e_or_0

        diverging = np.where(seen, self._diverging(memory, window, count, total, e, tau), memory.diverging)

        gated = np.zeros(seen.shape, dtype=bool)
        if self.gate:
            gated = (
                seen
                & was_full
                & ~memory.diverging
                & (e > self.gate_factor * np.maximum(tau, median_before))
                & (memory.gated_run < self.gate_max)
            )
        gated_run = np.where(seen, np.where(gated, memory.gated_run + 1, 0), memory.gated_run)

        stf = memory.stf
        if stf is not None:
            stf = _update_moment(ctx, stf, StrongTracking(self.rho).weight)

        # A gated step only predicts (λ = 1), whatever the divergence test said.
        fade = diverging & ~gated
        lam = np.ones(seen.shape)
        if np.any(fade):
            lam = np.where(fade, self._choose(ctx, fade, v, stf), 1.0)

        info = {
            "diverging": diverging,
            "gated": gated,
            "divergence_residual": np.where(seen, e, np.nan),
            "divergence_threshold": np.where(seen, tau, np.nan),
        }
        new = ImprovedMemory(window, count, total, diverging, gated_run, stf)
        return Fade(lam, skip=gated if self.gate else None, info=info), new

    # -- divergence test ------------------------------------------------------
    def _diverging(self, memory, window, count, total, e, tau) -> np.ndarray:
        if self.test == "instant":
            return e > tau
        if self.test == "mean":
            return total / np.maximum(count, 1) > tau
        L = self.window
        med = np.median(window, axis=-1)
        x = np.arange(L, dtype=float)
        slope = np.einsum("...i,i->...", window, x - x.mean())  # sign of the least-squares slope
        high = med > tau
        enter = high & (slope >= 0.0)
        stay = memory.diverging & high if self.hysteresis else False
        return (count > L) & (enter | stay)

    # -- choosing λ -----------------------------------------------------------
    def _choose(self, ctx: FadingContext, active: np.ndarray, v: np.ndarray, stf: TraceMemory | None) -> np.ndarray:
        if self.search == "stf":
            return _trace_ratio(ctx, stf.second_moment, 1.0, self.lam_max)
        # The largest λ of every search: λ_max, or the numerical ceiling if lower.
        top = np.broadcast_to(np.minimum(self.lam_max, ctx.lam_ceiling), active.shape)
        if self.search == "minimise":
            return self._grid_search(ctx, active, None, top)
        return self._consistent(ctx, active, self.beta * v, top)

    def _log_grid(self) -> np.ndarray:
        return np.exp(np.linspace(0.0, np.log(self.lam_max), self.grid))

    def _grid_search(self, ctx: FadingContext, active: np.ndarray, target: np.ndarray | None, top: np.ndarray) -> np.ndarray:
        """Smallest grid λ with post-fit residual ≤ target (``top`` if none); or, without target, the argmin.

        The grid spans [1, λ_max]; a run's points above its ``top`` are taken at ``top``.
        """
        grid = self._log_grid()
        best_lam = top.copy()
        best_val = np.full(active.shape, np.inf)
        found = np.zeros(active.shape, dtype=bool)
        for point in grid:
            lam = np.minimum(point, top)
            g = _post_fit(ctx, np.where(active, lam, 1.0))
            if target is None:
                better = active & (g < best_val)
                best_val = np.where(better, g, best_val)
                best_lam = np.where(better, lam, best_lam)
            else:
                hit = active & ~found & (g <= target)
                best_lam = np.where(hit, lam, best_lam)
                found = found | hit
        return best_lam

    def _consistent(self, ctx: FadingContext, active: np.ndarray, target: np.ndarray, top: np.ndarray) -> np.ndarray:
        """Variant (i): smallest λ ≤ ``top`` with ‖z − h(x̂(λ))‖_max ≤ target, by bisection on log λ."""
        g_one = _post_fit(ctx, np.ones(active.shape))
        g_max = _post_fit(ctx, np.where(active, top, 1.0))
        lam = np.where(g_one <= target, 1.0, top)
        out_of_reach = active & (g_one > target) & (g_max > target)
        if np.any(out_of_reach):
            if self.unreachable == "innovation":
                lam = np.where(out_of_reach, _innovation_factor(ctx, top), lam)
            elif self.unreachable == "minimise":
                lam = np.where(out_of_reach, self._grid_search(ctx, out_of_reach, None, top), lam)
        need = active & (g_one > target) & (g_max <= target)
        if not np.any(need):
            return lam
        lo, hi = np.zeros(active.shape), np.log(top)
        g_lo = g_one
        bumpy = np.zeros(active.shape, dtype=bool)
        for _ in range(self.iterations):
            mid = 0.5 * (lo + hi)
            g = _post_fit(ctx, np.where(need, np.exp(mid), 1.0))
            above = need & (g > target)
            # Every point left of lo was above the level and every point right of
            # hi below it, so the crossing found is consistent with the samples.
            # A residual that *grows* with λ while still above the level hints
            # at a dip below it left of lo, which bisection would miss.
            bumpy |= above & (g > g_lo * (1.0 + _MONOTONE_RTOL))
            lo = np.where(above, mid, lo)
            g_lo = np.where(above, g, g_lo)
            hi = np.where(need & ~above, mid, hi)
        lam = np.where(need, np.minimum(np.exp(hi), top), lam)
        if np.any(bumpy):
            # Keep the bisection's λ unless the grid finds a smaller one that fits.
            lam = np.where(bumpy, np.minimum(lam, self._grid_search(ctx, bumpy, target, top)), lam)
        return lam


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
def _max_over(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Max over the last axis of the valid entries; 0 where none is valid."""
    return np.where(valid, values, -np.inf).max(axis=-1, initial=-np.inf).clip(min=0.0)


def _max_abs(residual: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """‖r‖_max over the valid components; NaN where none is valid."""
    m = np.where(valid, np.abs(np.where(valid, residual, 0.0)), -np.inf).max(axis=-1)
    return np.where(valid.any(axis=-1), m, np.nan)


def _innovation_factor(ctx: FadingContext, lam_max: float | np.ndarray) -> np.ndarray:
    """λ_ν = min(λ_max, max(1, tr(ν νᵀ − HQHᵀ − R) / tr(HP̄Hᵀ))) from this step's innovation alone."""
    nu = np.where(ctx.measured, ctx.innovation, 0.0)
    return _trace_ratio(ctx, nu * nu, 1.0, lam_max)


def _post_fit(ctx: FadingContext, lam: np.ndarray) -> np.ndarray:
    """‖z − h(x̂(λ))‖_max of the trial update with P⁻ = λP̄ + Q; −inf where nothing is measured."""
    mean, _ = ctx.trial_update(lam)
    zhat = ctx.measurement.h(mean, ctx.k)
    res = getattr(ctx.measurement, "residual", None)
    r = res(ctx.z, zhat) if res is not None else ctx.z - zhat
    valid = ctx.measured
    return np.where(valid, np.abs(np.where(valid, r, 0.0)), -np.inf).max(axis=-1)
