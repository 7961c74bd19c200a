"""The Gaussian-mixture PHD filter (Vo & Ma 2006), batched over Monte Carlo runs.

The PHD (intensity) of the targets is a Gaussian mixture Σ_j w_j N(x; m_j, P_j)
whose weights sum to the expected number of targets.  One scan, for every
run at once (docs/spec/05-multi-target-pmht.md §4):

1. **Predict**: the weights of the last scan's components are multiplied by
   the survival probability p_S; the birth components are appended.
2. **Update**: every component is stepped by the per-component filter twice,
   as :func:`pursuit.multitarget.association.evaluate_hypotheses` does for
   GNN and JPDA (one ``step`` without a measurement, one on the flat batch of
   all component-detection pairs), so any Gaussian filter (KF, EKF, UKF, CKF)
   gives the predicted and updated components and the likelihoods without
   filter-specific code.  Weights:

   * missed: ``(1 − P_D) w_j``;
   * detection z: ``P_D w_j q_j(z) / (κ + P_D Σ_i w_i q_i(z))``, q_j(z) the
     predicted likelihood of component j, κ the clutter intensity
     (``clutter_density``, uniform clutter).

3. **Prune** components with weight ≤ ``prune`` (T = 1e-5), **merge**
   greedily from the heaviest (all components within Mahalanobis distance
   ``merge`` (U = 4) of it, measured with each candidate's own covariance,
   become one moment-matched component) and **cap** at the ``max_components``
   (J_max = 100) heaviest.
4. **Extract**: each component with weight ≥ ``extract`` (0.5) gives
   round(w) estimates at its mean.

**Births.**  Fixed births (``birth=`` a :class:`pursuit.Gaussian` with means
``(B, n)``) enter every scan with weight ``birth_rate / B`` each.  The
default is *adaptive*, measurement-driven birth (Ristic, Clark & Vo 2012),
since the built-in scenarios have no known birth locations: each detection
of scan k−1 starts a birth component for scan k, by two-point differencing
with its nearest detection of scan k−2 within ``max_speed · dt``
(``birth="two-point"``, the default; a detection without such a partner
starts nothing) or by a one-point prior with velocity spread
``velocity_sigma`` (``birth="one-point"``).  The birth mass ``birth_rate``
(expected births per scan) is shared by the detections of scan k−1 in
proportion to ``1 − a(z)``, a(z) = Σ_j of the weights z gave the
components: a detection the present components explain gives almost no
birth.  A birth component lives at the time of its detection and is
predicted to the next scan with the others.

**Labels** (for track switches) by tag propagation: each component carries
a label; a birth gets a fresh one (per run, 0, 1, 2, ..., the births of one
scan numbered in lexicographic order of their detections' positions, so
labels do not depend on the order of the detections); an updated component
keeps its parent's; a merge keeps the label of its heaviest component.
Two estimates can carry one label (a component of weight ≥ 1.5, or two
components updated from one parent).

**Loops.**  The Python loops are over scans and over the greedy merge
rounds (each a few boolean operations on the adjacency of every pair, for
all runs at once; rounds = the most groups of linked components of any
run); everything else is vectorised over runs and components, with per-run
component capacity held by weight-0 padding.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .._validation import in_range, positive, positive_int
from ..filters.gaussian import CubatureKalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter
from ..gaussian import Gaussian
from ..initiation import VELOCITY_SIGMA, one_point, two_point
from ..rng import RNGLike
from .association import evaluate_hypotheses
from .tracking import MultiTrackResult, _layout_motion, checked_scans, resolve_position

__all__ = ["GMPHDTracker", "GMPHDResult", "prune_merge", "extract_estimates", "BIRTH_MODES"]

BIRTH_MODES = ("two-point", "one-point")

# evaluate_hypotheses gates for GNN and JPDA; GM-PHD weighs every (component, detection) pair and
# never reads the gate's verdict, so the value passed is immaterial
_UNUSED_GATE = 0.99
"""The adaptive birth models (``birth=`` a string); a Gaussian gives fixed births, None none."""

_GAUSSIAN_FILTERS = (ExtendedKalmanFilter, UnscentedKalmanFilter, CubatureKalmanFilter)


@dataclass(frozen=True)
class GMPHDResult(MultiTrackResult):
    """:class:`MultiTrackResult` of the GM-PHD filter, with the mixture's totals.

    Attributes
    ----------
    expected_count
        ``(K, M)`` Σ w of the mixture after each scan's update (before
        pruning): the PHD's expected number of targets.
    components
        ``(K, M)`` components held after pruning, merging and the cap.
    """

    expected_count: np.ndarray | None = None
    components: np.ndarray | None = None


@dataclass(frozen=True)
class GMPHDTracker:
    """Gaussian-mixture PHD filter (Vo & Ma 2006) for all Monte Carlo runs at once.

    Parameters
    ----------
    filter
        The per-component filter: a KalmanFilter, ExtendedKalmanFilter,
        UnscentedKalmanFilter or CubatureKalmanFilter with its models.
    p_detect
        Detection probability P_D in (0, 1].
    clutter_density
        κ: false alarms per scan per unit volume of measurement space (> 0).
    p_survive
        Survival probability p_S in (0, 1] (keyword only, default 0.99).
    birth
        ``"two-point"`` (default), ``"one-point"`` (adaptive births from the
        last scan's detections), a :class:`pursuit.Gaussian` with means
        ``(B, n)`` (fixed births, at the time of the previous scan), or None
        (no births: only the ``initial`` components of :meth:`track`).
    birth_rate
        Expected births per scan (> 0, default 0.1): the total weight of one
        scan's birth components.
    max_speed
        Largest target speed; two-point births pair detections within
        ``max_speed · dt`` (needed by ``birth="two-point"``).
    velocity_sigma
        Velocity standard deviation of a one-point birth (default 10 m/s).
    prune
        Pruning threshold T (default 1e-5): components of weight ≤ T go.
    merge
        Merging threshold U (default 4), a squared Mahalanobis distance.
    max_components
        J_max (default 100): components kept per run after merging.
    extract
        Weight from which a component gives estimates (default 0.5).
    capacity
        L, estimate slots per run in the result (default 32); estimates
        beyond it are counted in ``dropped``.
    position
        ``position(z) -> (p, C)``: a detection's position and covariance for
        the adaptive births (default: the built-in position and
        range-bearing sensors).
    name
        Label in results (default ``GMPHD-<filter name>``).
    """

    filter: Any
    p_detect: float
    clutter_density: float
    p_survive: float = field(default=0.99, kw_only=True)
    birth: Any = field(default="two-point", kw_only=True)
    birth_rate: float = field(default=0.1, kw_only=True)
    max_speed: float | None = field(default=None, kw_only=True)
    velocity_sigma: float = field(default=VELOCITY_SIGMA, kw_only=True)
    prune: float = field(default=1e-5, kw_only=True)
    merge: float = field(default=4.0, kw_only=True)
    max_components: int = field(default=100, kw_only=True)
    extract: float = field(default=0.5, kw_only=True)
    capacity: int = field(default=32, kw_only=True)
    position: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = field(default=None, kw_only=True)
    name: str = field(default="", kw_only=True)

    def __post_init__(self) -> None:
        if not isinstance(self.filter, _GAUSSIAN_FILTERS):
            raise ValueError(
                f"filter: {type(self.filter).__name__} cannot be a GM-PHD component filter; use a KalmanFilter, "
                "ExtendedKalmanFilter, UnscentedKalmanFilter or CubatureKalmanFilter"
            )
        in_range("p_detect", self.p_detect, 0.0, 1.0, low_open=True)
        positive("clutter_density", self.clutter_density)
        in_range("p_survive", self.p_survive, 0.0, 1.0, low_open=True)
        positive("birth_rate", self.birth_rate)
        positive("velocity_sigma", self.velocity_sigma)
        in_range("prune", self.prune, 0.0, 1.0, high_open=True)
        positive("merge", self.merge)
        positive_int("max_components", self.max_components)
        in_range("extract", self.extract, 0.0, 1.0, low_open=True)
        positive_int("capacity", self.capacity)
        motion = _layout_motion(self.filter)
        if isinstance(self.birth, str):
            if self.birth not in BIRTH_MODES:
                raise ValueError(f"birth: expected one of {BIRTH_MODES}, a Gaussian or None, got {self.birth!r}")
            if motion is None or not hasattr(motion, "position_indices"):
                raise ValueError("birth: adaptive births need a motion model with position_indices")
            if self.birth == "two-point" and self.max_speed is None:
                raise ValueError("max_speed: two-point births pair detections within max_speed · dt; give it")
            object.__setattr__(self, "position", resolve_position(self.position, self.filter, motion))
        elif self.birth is not None:
            try:
                g = self.birth if isinstance(self.birth, Gaussian) else Gaussian(*self.birth)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"birth: expected 'two-point', 'one-point', None or a Gaussian ((B, n) means): {exc}") from None
            mean = np.atleast_2d(g.mean)
            if mean.ndim != 2:
                raise ValueError(f"birth: expected means of shape (B, n), got {g.mean.shape}")
            n = getattr(motion, "dim", mean.shape[1])
            if mean.shape[1] != n:
                raise ValueError(f"birth: means have {mean.shape[1]} components, the motion model's state {n}")
            object.__setattr__(self, "birth", Gaussian(mean, np.broadcast_to(g.cov, (*mean.shape, mean.shape[1])).copy()))
        if self.max_speed is not None:
            positive("max_speed", self.max_speed)
        if not self.name:
            object.__setattr__(self, "name", f"GMPHD-{getattr(self.filter, 'name', '')}")

    # ------------------------------------------------------------------
    def track(self, z: Any, *, times: Any = None, rng: RNGLike = None, initial: Any = None) -> GMPHDResult:
        """Run the GM-PHD filter over scans of detections, for all runs at once.

        Parameters
        ----------
        z
            ``(K, M, D, m)`` detections; NaN rows are padding; the order of
            rows carries no meaning.
        times
            ``(K,)`` increasing scan times (default: the motion model's dt).
        rng
            Passed to the filter's ``init``; Gaussian filters draw nothing.
        initial
            Components known before the first scan (a Gaussian with means
            ``(J0, n)`` or ``(M, J0, n)``), weight 1 each, labels 0..J0−1.

        Returns
        -------
        GMPHDResult
            The extracted estimates (every one ``confirmed``) with their labels.
        """
        z, times = checked_scans(z, times, self.filter)
        K, M, D, m = z.shape
        filt = self.filter
        motion = _layout_motion(filt)
        model_dt = getattr(motion, "dt", None)
        if isinstance(self.birth, str) and self.birth == "two-point" and times is None and model_dt is None:
            raise ValueError("times: two-point births need scan times when the motion model has no dt")
        n = int(getattr(motion, "dim", 0) or 0)
        w, mean, cov, label, next_label = _initial(initial, M, n)
        n = mean.shape[-1]

        L = self.capacity
        out_mean = np.full((K, M, L, n), np.nan)
        out_cov = np.full((K, M, L, n, n), np.nan)
        out_label = np.full((K, M, L), -1, dtype=np.int64)
        out_drop = np.zeros((K, M), dtype=np.int64)
        out_count = np.zeros((K, M))
        out_comp = np.zeros((K, M), dtype=np.int64)
        births = _no_births(M, n)
        previous: tuple[np.ndarray, np.ndarray] | None = None  # positions of scan k−1 for two-point births
        for k in range(1, K + 1):
            dt = None if times is None or k == 1 else float(times[k - 1] - times[k - 2])
            if isinstance(self.birth, Gaussian):
                births = self._fixed_births(M, next_label)
            bw, bmean, bcov, blabel = births
            next_label = next_label + (bw > 0).sum(axis=1)
            w = np.concatenate([self.p_survive * w, bw], axis=1)
            mean = np.concatenate([mean, bmean], axis=1)
            cov = np.concatenate([cov, bcov], axis=1)
            label = np.concatenate([label, blabel], axis=1)

            w, mean, cov, label, explained, out_count[k - 1] = self._update(filt, w, mean, cov, label, z[k - 1], k, dt, rng)
            w, mean, cov, label = prune_merge(w, mean, cov, label, self.prune, self.merge, self.max_components)
            out_comp[k - 1] = (w > 0).sum(axis=1)
            est_mean, est_cov, est_label, out_drop[k - 1] = extract_estimates(w, mean, cov, label, self.extract, L)
            out_mean[k - 1], out_cov[k - 1], out_label[k - 1] = est_mean, est_cov, est_label

            if isinstance(self.birth, str):
                step_dt = dt if dt is not None else model_dt  # None only at the first scan, which pairs nothing
                births, previous = self._adaptive_births(z[k - 1], explained, previous, step_dt, next_label, rng)
        return GMPHDResult(
            out_mean, out_cov, out_label, out_label >= 0, out_drop, self.name, expected_count=out_count, components=out_comp
        )

    # ------------------------------------------------------------------
    def _update(
        self,
        filt: Any,
        w: np.ndarray,
        mean: np.ndarray,
        cov: np.ndarray,
        label: np.ndarray,
        z: np.ndarray,
        k: int,
        dt: float | None,
        rng: RNGLike,
    ) -> tuple[np.ndarray, ...]:
        """Predict and update a mixture ``(M, C)`` with one scan ``(M, D, m)``.

        Returns the candidates above the pruning threshold (each component
        missed, and updated by each detection), heaviest first, as ``(M, J)``
        arrays padded with weight 0; ``a(z) (M, D)``, the weight each
        detection gave the components; and ``(M,)`` Σ w before pruning.
        """
        M, C = w.shape
        D = z.shape[1]
        alive = w > 0
        if C == 0:  # nothing to update (no component yet)
            return w, mean, cov, label, np.zeros((M, D)), np.zeros(M)
        state = filt.init(Gaussian(mean, cov), batch=(M, C), rng=rng)
        hyp = evaluate_hypotheses(filt, state, z, alive, _UNUSED_GATE, k, dt)
        paired = hyp.pair >= 0  # (M, C, D): an alive component and a real detection
        with np.errstate(divide="ignore"):
            log_num = (np.log(self.p_detect) + np.log(w))[..., None] + hyp.loglik
        log_num[~paired] = -np.inf
        top = np.max(log_num, axis=1, initial=np.log(self.clutter_density))  # (M, D), for stability
        w_pair = np.exp(log_num - top[:, None, :])  # 0 where not paired
        w_pair /= (self.clutter_density * np.exp(-top) + w_pair.sum(axis=1))[:, None, :]
        explained = w_pair.sum(axis=1)  # (M, D)

        w_miss = np.where(alive, (1.0 - self.p_detect) * w, 0.0)
        cand_w = np.concatenate([w_miss, w_pair.reshape(M, C * D)], axis=1)  # missed first, then (c, d) c-major
        total = cand_w.sum(axis=1)
        # Pruning here, before any state is copied: only the candidates above T are gathered, heaviest first
        # (a stable sort of the kept ones only: equal weights keep their candidate order).
        r, col = np.nonzero(cand_w > self.prune)
        by = np.lexsort((-cand_w[r, col], r))
        r, col = r[by], col[by]
        count = np.bincount(r, minlength=M)
        width = int(count.max(initial=0))
        slot = np.arange(r.size) - (np.cumsum(count) - count)[r]
        n = mean.shape[-1]
        out_w = np.zeros((M, width))
        out_mean = np.zeros((M, width, n))
        out_cov = np.broadcast_to(np.eye(n), (M, width, n, n)).copy()
        out_label = np.full((M, width), -1, dtype=label.dtype)
        out_w[r, slot] = cand_w[r, col]
        missed = col < C
        comp = np.where(missed, col, (col - C) // D)  # the parent component
        out_label[r, slot] = label[r, comp]
        rm, sm, cm = r[missed], slot[missed], comp[missed]
        out_mean[rm, sm] = hyp.missed.mean[rm, cm]
        out_cov[rm, sm] = np.broadcast_to(hyp.missed.cov, (M, C, n, n))[rm, cm]
        if hyp.states is not None and not missed.all():
            pair = hyp.pair[r[~missed], comp[~missed], (col[~missed] - C) % D]
            rp, sp = r[~missed], slot[~missed]
            out_mean[rp, sp] = hyp.states.mean[pair]
            out_cov[rp, sp] = np.broadcast_to(hyp.states.cov, (hyp.runs.size, n, n))[pair]
        return out_w, out_mean, out_cov, out_label, explained, total

    def _fixed_births(self, M: int, next_label: np.ndarray) -> tuple[np.ndarray, ...]:
        """The fixed birth components ``(M, B)``, weight ``birth_rate / B`` each, fresh labels."""
        g = self.birth
        B, n = g.mean.shape
        bw = np.full((M, B), self.birth_rate / B)
        label = next_label[:, None] + np.arange(B)
        return bw, np.broadcast_to(g.mean, (M, B, n)).copy(), np.broadcast_to(g.cov, (M, B, n, n)).copy(), label

    def _adaptive_births(
        self,
        z: np.ndarray,
        explained: np.ndarray,
        previous: tuple[np.ndarray, np.ndarray] | None,
        dt: float | None,
        next_label: np.ndarray,
        rng: RNGLike,
    ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, np.ndarray]]:
        """Birth components ``(M, D)`` from this scan's detections (see the module notes), and their positions."""
        M, D, _ = z.shape
        motion = _layout_motion(self.filter)
        n = motion.dim
        detected = ~np.isnan(z[..., 0])
        with np.errstate(invalid="ignore"):
            p2, C2 = self.position(np.where(detected[..., None], z, 0.0))
        d = p2.shape[-1]
        C2 = np.broadcast_to(C2, (M, D, d, d))
        p2 = np.where(detected[..., None], p2, np.nan)
        here = (p2, np.array(C2))
        unexplained = np.where(detected, np.clip(1.0 - explained, 0.0, 1.0), 0.0)
        # Σ over the sorted shares, so that the total does not depend on the order of the detections.
        total = np.sort(unexplained, axis=1).sum(axis=1)
        share = np.where(total[:, None] > 0, unexplained / np.where(total > 0, total, 1.0)[:, None], 0.0)
        if self.birth == "two-point":
            if previous is None or dt is None or previous[0].shape[1] == 0:
                return _no_births(M, n), here
            p1, C1 = previous
            dist = np.linalg.norm(p2[:, :, None, :] - p1[:, None, :, :], axis=-1)  # (M, D, D1)
            dist = np.where(dist <= self.max_speed * dt, dist, np.inf)  # NaN (padding) is out of reach too
            near = np.argmin(dist, axis=2)
            ok = detected & np.isfinite(np.take_along_axis(dist, near[..., None], axis=2)[..., 0])
            runs, dets = np.nonzero(ok)
            prior = two_point(p1[runs, near[runs, dets]], C1[runs, near[runs, dets]], p2[runs, dets], C2[runs, dets], float(dt), motion)
        else:
            ok = detected
            runs, dets = np.nonzero(ok)
            prior = one_point(p2[runs, dets], C2[runs, dets], motion, self.velocity_sigma)
        ok = ok & (share > 0)
        keep = ok[runs, dets]
        runs, dets = runs[keep], dets[keep]
        bmean = np.zeros((M, D, n))
        bcov = np.broadcast_to(np.eye(n), (M, D, n, n)).copy()
        bmean[runs, dets] = prior.mean[keep]
        bcov[runs, dets] = np.broadcast_to(prior.cov, (keep.size, n, n))[keep]
        bw = np.where(ok, self.birth_rate * share, 0.0)
        # Births in lexicographic order of position (labels and slots independent of the detection order).
        key = np.where(ok[..., None], p2, 0.0)
        order = np.lexsort([*(key[..., i] for i in range(d - 1, -1, -1)), ~ok], axis=-1)
        bw, bmean, bcov = (np.take_along_axis(a, order.reshape(M, D, *(1,) * (a.ndim - 2)), axis=1) for a in (bw, bmean, bcov))
        rank = np.arange(D)
        blabel = np.where(rank < ok.sum(axis=1)[:, None], next_label[:, None] + rank, -1)
        return (bw, bmean, bcov, blabel), here


def _no_births(M: int, n: int) -> tuple[np.ndarray, ...]:
    return np.zeros((M, 0)), np.zeros((M, 0, n)), np.zeros((M, 0, n, n)), np.zeros((M, 0), dtype=np.int64)


def _initial(initial: Any, M: int, n: int) -> tuple[np.ndarray, ...]:
    """The ``initial`` components as ``(M, J0)`` arrays, weight 1, labels 0..J0−1, and the next labels."""
    if initial is None:
        if n < 1:
            raise ValueError("initial: give initial components, or a filter whose motion model has dim")
        w, mean, cov, label = _no_births(M, n)
        return w, mean, cov, label, np.zeros(M, dtype=np.int64)
    g = initial if isinstance(initial, Gaussian) else Gaussian(*initial)
    mean = g.mean if g.mean.ndim == 3 else np.broadcast_to(g.mean, (M, *np.atleast_2d(g.mean).shape))
    if mean.ndim != 3 or mean.shape[0] != M:
        raise ValueError(f"initial: expected means of shape (J0, n) or ({M}, J0, n), got {g.mean.shape}")
    J0, n = mean.shape[1:]
    cov = np.broadcast_to(g.cov, (M, J0, n, n)).copy()
    label = np.broadcast_to(np.arange(J0), (M, J0)).copy()
    return np.ones((M, J0)), np.array(mean, dtype=float), cov, label, np.full(M, J0, dtype=np.int64)


# ----------------------------------------------------------------------
# pruning, merging, extraction
# ----------------------------------------------------------------------
def prune_merge(
    w: np.ndarray, mean: np.ndarray, cov: np.ndarray, label: np.ndarray, threshold: float = 1e-5, merge: float = 4.0, cap: int = 100
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vo & Ma's pruning and merging, for a batch of mixtures at once.

    Components of weight ≤ ``threshold`` are dropped.  Then, repeatedly,
    the heaviest remaining component j and every remaining i with
    ``(m_i − m_j)ᵀ P_i⁻¹ (m_i − m_j) ≤ merge`` become one component:
    ``w = Σ w_i``, ``m = Σ w_i m_i / w``,
    ``P = Σ w_i (P_i + (m − m_i)(m − m_i)ᵀ) / w``, with the label of j
    (the sums run over the group heaviest first).  Finally only the ``cap``
    heaviest are kept.

    Parameters
    ----------
    w, mean, cov, label
        ``(M, C)``, ``(M, C, n)``, ``(M, C, n, n)``, ``(M, C)``; weight 0
        marks an empty slot.
    threshold, merge, cap
        T, U and J_max.

    Returns
    -------
    w, mean, cov, label
        ``(M, J)`` arrays with J ≤ ``cap`` the most components of any run,
        heaviest first, padded with weight 0 (label −1).
    """
    M = w.shape[0]
    n = mean.shape[-1]
    keep = w > threshold
    width = int(keep.sum(axis=1).max(initial=0))
    # Kept components first, heaviest first: the merge order then does not depend on the input order.
    key = np.where(keep, -w, np.inf)
    if (key[:, 1:] >= key[:, :-1]).all():  # already so (the tracker's update hands them over sorted): no copy
        w, mean, cov, label = np.where(keep, w, 0.0)[:, :width], mean[:, :width], cov[:, :width], label[:, :width]
    else:
        order = np.argsort(key, axis=1, kind="stable")[:, :width]
        w = np.take_along_axis(np.where(keep, w, 0.0), order, axis=1)
        mean = np.take_along_axis(mean, order[..., None], axis=1)
        cov = np.take_along_axis(cov, order[..., None, None], axis=1)
        label = np.take_along_axis(label, order, axis=1)
    alive = w > 0
    if not alive.any():
        return np.zeros((M, 0)), np.zeros((M, 0, n)), np.zeros((M, 0, n, n)), np.zeros((M, 0), dtype=np.int64)
    A, x, y, bound = _distance_terms(alive, mean, cov)
    centre = np.full((M, width), width)  # the column of the component each one merges into (width: empty slot)
    count = alive.sum(axis=1)
    # Runs of about the same size together (a class per factor √2 above 32 components), each padded to its
    # largest only: the pairs cost the square of the padded width, and each class its own greedy rounds;
    # chunks of a class bound the memory (one chunk usually).
    size_class = np.ceil(2.0 * np.log2(np.maximum(count, _SMALL))).astype(np.int64)
    for c in np.unique(size_class[count > 0]):
        members = np.flatnonzero((size_class == c) & (count > 0))
        C = int(count[members].max())
        step = max(1, _PAIR_BUDGET // (C * C))
        for start in range(0, members.size, step):
            runs = members[start : start + step]
            live = alive[runs, :C]
            adj = _merge_pairs(live, mean[runs, :C], A[runs, :C], x[runs, :C], y[runs, :C], bound[runs, :C], merge)
            group = _greedy_groups(live, adj)
            centre[runs, :C] = np.where(group < C, group, width)
    return _moment_match(w, mean, cov, label, alive, centre, cap)


# (runs × C × C) pairs of one chunk of merge distances: 16 MB a float64 array of them (a few are alive at once)
_PAIR_BUDGET = 1 << 21
# runs of up to this many components share one size class (their padding costs less than more rounds)
_SMALL = 32


def _distance_terms(alive: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, ...]:
    """The terms of the merge distances of every pair, for :func:`_merge_pairs`.

    d²(i from j) = (m_i − m_j)ᵀ A_i (m_i − m_j) = c_i − 2 a_i·m_j + Σ_kl A_i,kl m_j,k m_j,l with
    A_i = P_i⁻¹, a_i = A_i m_i, c_i = m_iᵀ a_i: the dot product of ``x_i`` = (c_i, a_i, the
    upper triangle of A_i with the off-diagonal doubled) and ``y_j`` = (1, −2 m_j, m_j,k m_j,l),
    so that all pairs of a run are one matrix product.  The expansion cancels when ‖m‖ is large
    against the spread: its rounding error is at most about (n² + n + 2)·eps·‖A_i‖_F·(‖m_i‖ + ‖m_j‖)²;
    ``bound (M, C)`` is that with the largest ‖m_j‖ of the run.

    Returns ``A (M, C, n, n)`` (identity in empty slots), ``x``, ``y`` ``(M, C, 1 + n + n(n+1)/2)``
    and ``bound``.
    """
    M, C, n = mean.shape
    A = np.broadcast_to(np.eye(n), (M, C, n, n)).copy()
    A[alive] = _spd_inverse(cov[alive])
    a = np.einsum("mcij,mcj->mci", A, mean)
    c = np.einsum("mci,mci->mc", a, mean)
    k, l = np.triu_indices(n)
    twice = np.where(k == l, 1.0, 2.0)  # exact: a power of two
    x = np.concatenate([c[..., None], a, A[..., k, l] * twice], axis=-1)
    y = np.concatenate([np.ones((M, C, 1)), -2.0 * mean, mean[..., k] * mean[..., l]], axis=-1)
    m_norm = np.where(alive, np.sqrt(np.einsum("mci,mci->mc", mean, mean)), 0.0)
    bound = 4.0 * (n * n + n + 2) * np.finfo(float).eps * np.sqrt(np.einsum("mcij,mcij->mc", A, A))
    bound *= (m_norm + m_norm.max(axis=1, initial=0.0, keepdims=True)) ** 2
    return A, x, y, bound


def _merge_pairs(
    alive: np.ndarray, mean: np.ndarray, A: np.ndarray, x: np.ndarray, y: np.ndarray, bound: np.ndarray, merge: float
) -> np.ndarray:
    """``adj (M, C, C)``: ``adj[m, j, i]`` when i is within U of j, ``(m_i − m_j)ᵀ P_i⁻¹ (m_i − m_j) ≤ U``.

    Every pair at once from :func:`_distance_terms`, one matrix product per
    run; a distance within ``bound`` of U is computed again directly.  The
    diagonal is True (j is in its own group whatever the rounding).
    """
    C = mean.shape[1]
    d2 = np.matmul(y, np.swapaxes(x, 1, 2))  # (M, C_j, C_i)
    d2 -= merge
    adj = d2 <= 0.0  # the same as d2 ≤ U before the subtraction (x − U rounds to 0 only at x = U)
    near = np.abs(d2, out=d2) <= bound[:, None, :]
    if near.any():  # rare: coordinates far larger than the spread
        runs, js, cols = np.nonzero(near & alive[:, :, None] & alive[:, None, :])
        diff = mean[runs, cols] - mean[runs, js]
        adj[runs, js, cols] = np.einsum("ki,kij,kj->k", diff, A[runs, cols], diff) <= merge
    diag = np.arange(C)
    adj[:, diag, diag] = True
    return adj


def _spd_inverse(P: np.ndarray) -> np.ndarray:
    """Inverses ``(N, n, n)`` of symmetric positive-definite matrices, by Cholesky: ``P⁻¹ = L⁻ᵀ L⁻¹``.

    Entry by entry on contiguous ``(N,)`` vectors, a Python loop over the n²
    entries only: LAPACK's batched ``inv`` costs over a microsecond a matrix
    on stacks of tiny ones.  The result is exactly symmetric.  A matrix that
    is not positive definite in floating point (a pivot ≤ 0 or not finite)
    is inverted by ``np.linalg.inv`` instead.
    """
    N, n, _ = P.shape
    Pt = np.ascontiguousarray(np.moveaxis(P, 0, -1), dtype=float)  # (n, n, N)
    L: list[list[Any]] = [[None] * n for _ in range(n)]
    with np.errstate(invalid="ignore", divide="ignore"):
        for j in range(n):
            pivot = Pt[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), np.zeros(N))
            L[j][j] = np.sqrt(pivot)
            for i in range(j + 1, n):
                L[i][j] = (Pt[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), np.zeros(N))) / L[j][j]
        # X = L⁻¹ (lower triangular), column by column
        X: list[list[Any]] = [[None] * n for _ in range(n)]
        for j in range(n):
            X[j][j] = 1.0 / L[j][j]
            for i in range(j + 1, n):
                X[i][j] = -sum((L[i][k] * X[k][j] for k in range(j, i)), np.zeros(N)) / L[i][i]
    A = np.empty((n, n, N))
    for i in range(n):
        for j in range(i + 1):
            A[i, j] = A[j, i] = sum((X[k][i] * X[k][j] for k in range(i, n)), np.zeros(N))
    A = np.moveaxis(A, -1, 0)
    bad = ~(np.stack([L[j][j] for j in range(n)], axis=-1) > 0).all(axis=-1) | ~np.isfinite(A).all(axis=(1, 2))
    if bad.any():
        A[bad] = np.linalg.inv(P[bad])
    return A


def _greedy_groups(alive: np.ndarray, adj: np.ndarray) -> np.ndarray:
    """``(M, C)``: the column of the component each one merges into, for columns heaviest first.

    Vo & Ma's greedy rounds on the adjacency: the heaviest remaining j takes
    every remaining i with ``adj[j, i]``.  A component with no neighbour
    either way is its own group whatever the order, so the rounds run over
    the others only: as many as the busiest run has groups of them, each a
    few boolean operations over all runs at once.
    """
    M, C = alive.shape
    diag = np.arange(C)
    linked = adj & alive[:, :, None] & alive[:, None, :]
    linked[:, diag, diag] = False
    remaining = linked.any(axis=2) | linked.any(axis=1)
    centre = np.where(alive, diag, C)  # C marks an empty slot
    ar = np.arange(M)
    while remaining.any():
        j = np.argmax(remaining, axis=1)  # the first remaining is the heaviest; runs with none take no group
        group = remaining & adj[ar, j]
        centre = np.where(group, j[:, None], centre)
        remaining &= ~group
    return centre


def _moment_match(
    w: np.ndarray, mean: np.ndarray, cov: np.ndarray, label: np.ndarray, alive: np.ndarray, centre: np.ndarray, cap: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each group's moment-matched component, the label of its centre, the ``cap`` heaviest of each run."""
    M, C = w.shape
    n = mean.shape[-1]
    # The members of each group together, heaviest first (stable), groups in the order of their centres.
    perm = np.argsort(centre, axis=1, kind="stable")
    sorted_centre = np.take_along_axis(centre, perm, axis=1)
    runs, pos = np.nonzero(sorted_centre < C)
    cols = perm[runs, pos]
    group_of = sorted_centre[runs, pos]
    first = np.ones(runs.size, dtype=bool)
    first[1:] = (group_of[1:] != group_of[:-1]) | (runs[1:] != runs[:-1])
    starts = np.flatnonzero(first)
    g_run, g_centre = runs[starts], group_of[starts]
    wi, mi, Pi = w[runs, cols], mean[runs, cols], cov[runs, cols]
    total = np.add.reduceat(wi, starts)
    m = np.add.reduceat(wi[:, None] * mi, starts, axis=0) / total[:, None]
    spread = mi - m[np.cumsum(first) - 1]
    wspread = wi[:, None] * spread
    P = np.add.reduceat(wi[:, None, None] * Pi + wspread[:, :, None] * spread[:, None, :], starts, axis=0) / total[:, None, None]
    # Into (M, G) slots, groups in the order of their centres (the order of the rounds), then the J_max heaviest.
    count = np.bincount(g_run, minlength=M)
    G = int(count.max(initial=0))
    slot = np.arange(starts.size) - (np.cumsum(count) - count)[g_run]
    out_w = np.zeros((M, G))
    out_mean = np.zeros((M, G, n))
    out_cov = np.broadcast_to(np.eye(n), (M, G, n, n)).copy()
    out_label = np.full((M, G), -1, dtype=np.int64)
    out_w[g_run, slot], out_mean[g_run, slot], out_cov[g_run, slot] = total, m, P
    out_label[g_run, slot] = label[g_run, g_centre]
    J = min(cap, G)
    order = np.argsort(-out_w, axis=1, kind="stable")[:, :J]
    return (
        np.take_along_axis(out_w, order, axis=1),
        np.take_along_axis(out_mean, order[..., None], axis=1),
        np.take_along_axis(out_cov, order[..., None, None], axis=1),
        np.take_along_axis(out_label, order, axis=1),
    )


def extract_estimates(
    w: np.ndarray, mean: np.ndarray, cov: np.ndarray, label: np.ndarray, threshold: float = 0.5, capacity: int = 32
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Estimates of a batch of mixtures: round(w) copies of each component with weight ≥ ``threshold``.

    Rounding is half up (w = 1.5 gives two).  Returns ``mean (M, L, n)``,
    ``cov (M, L, n, n)`` (NaN in unused slots), ``label (M, L)`` (−1 there)
    and ``dropped (M,)``, the estimates beyond the ``capacity`` L slots, in
    the order of the components (heaviest first after :func:`prune_merge`).
    """
    M, J = w.shape
    n = mean.shape[-1]
    L = capacity
    copies = np.where(w >= threshold, np.maximum(np.floor(w + 0.5), 1.0), 0.0).astype(np.int64)
    ends = np.cumsum(copies, axis=1)  # (M, J)
    total = ends[:, -1] if J else np.zeros(M, dtype=np.int64)
    slot = np.arange(L)
    which = (ends[:, None, :] <= slot[None, :, None]).sum(axis=2)  # (M, L) component of each slot
    used = slot[None, :] < total[:, None]
    which = np.minimum(which, max(J - 1, 0))
    if J:
        est_mean = np.where(used[..., None], np.take_along_axis(mean, which[..., None], axis=1), np.nan)
        est_cov = np.where(used[..., None, None], np.take_along_axis(cov, which[..., None, None], axis=1), np.nan)
        est_label = np.where(used, np.take_along_axis(label, which, axis=1), -1)
    else:
        est_mean, est_cov = np.full((M, L, n), np.nan), np.full((M, L, n, n), np.nan)
        est_label = np.full((M, L), -1, dtype=np.int64)
    return est_mean, est_cov, est_label, np.maximum(total - L, 0)
