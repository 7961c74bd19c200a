"""The ``maneuver`` experiment kind: per-axis RMSE of maneuvering-target filters (paper P4).

Sections: ``[scenario]`` (a scenario with ``[p, v, a]`` per axis, e.g.
``maneuver-3d``), ``[[filters]]``, optional ``[figures]`` and ``[claims]``.

Tables:

``rmse``
    Per filter and axis, the position, velocity and acceleration RMSE
    averaged over time: mean over k of sqrt(mean over runs of e²) — P4's
    "mean of RMSE" (its Table 2, whose values are missing).
``segments``
    The same on each schedule segment of the most strongly maneuvering axis.
``detections``
    For filters with a maneuver detector: how often it fired on settled
    non-maneuvering steps (beside the configured false-alarm rate) and in
    the two steps after each maneuver onset.
``claims`` (kind ``paper``)
    P4's qualitative claims beside what we measured, for the filters named
    in ``[claims]`` (default CS and APCS).  P4 prints no usable numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from ..config.build import build_filters, build_scenario, resolve_section
from ..engine.montecarlo import monte_carlo
from ..registry import Param, register
from ..report.figures import consistency_over_time
from ..report.maneuver import Segment, detection_rates, mode_probabilities, rmse_panels
from ..results import MonteCarloResult
from ..tables import ExperimentOutput, Table

__all__ = ["ManeuverPlan"]

FIGURE_PARAMS = (
    Param("zoom_at", "float", None, "onset time of the zoomed maneuver, s (default: the largest jump of the true acceleration)"),
    Param("zoom_before", "float", 5.0, "seconds shown before the onset in the zoom"),
    Param("zoom_after", "float", 15.0, "seconds shown after the onset in the zoom"),
    Param("log_rmse", "bool", False, "logarithmic RMSE axes"),
)
CLAIM_PARAMS = (
    Param("baseline", "str", "CS", "filter the paper compares against (standard CS)"),
    Param("adaptive", "str", "APCS", "the paper's filter (parameter-adaptive CS)"),
)
SETTLE_STEPS = 10
"""Steps after a maneuver (or the start) before a quiet step counts as settled for the false-alarm rate."""

_KNOWN_SECTIONS = {"scenario", "filters", "figures", "claims"}
PAPER_NOTE = (
    "Paper P4 (Fang & Yang 2016) gives no usable numbers: its Table 2 (mean RMSE) and Table 1 (maneuver schedule) "
    "are missing, so the schedule is the invented one of docs/spec/04-adaptive-cs-model.md §3 and only the qualitative claims "
    "can be compared. z: paired z statistic over runs of the per-run RMSE difference (baseline - adaptive)."
)


# --------------------------------------------------------------------------
# layout helpers
# --------------------------------------------------------------------------
def _axes(scenario: Any) -> str:
    axes = getattr(scenario, "axes", None)
    return axes if axes else "xyz"[: len(scenario.position_indices)]


def _axis_indices(result: MonteCarloResult, a: int) -> tuple[int, int, int]:
    p = result.position_indices[a]
    return p, p + 1, p + 2


def _segments(scenario: Any) -> list[Segment]:
    out = []
    for m in getattr(scenario, "maneuvers", ()):
        turn = m.kind == "turn"
        value = m.rate if turn else m.accel
        if value == 0.0:
            continue
        out.append(Segment(m.start - scenario.dt, m.stop, m.axes, m.label().rsplit(" ", 2)[0], float(np.sign(value)), turn))
    return out


def _maneuvering(scenario: Any, result: MonteCarloResult) -> np.ndarray:
    """``(K, A)`` bool mask of maneuvering steps per axis (from the schedule, else from the true acceleration)."""
    if callable(getattr(scenario, "maneuvering", None)):
        return np.asarray(scenario.maneuvering(), dtype=bool)
    acc = result.truth[:, 0, [p + 2 for p in result.position_indices]]
    return acc != 0.0


def _strongest_onset(result: MonteCarloResult) -> tuple[int, float, float]:
    """Axis, time and size of the largest jump of the true acceleration."""
    acc = result.truth[:, 0, [p + 2 for p in result.position_indices]]  # same truth in every run
    jumps = np.abs(np.diff(acc, axis=0))
    if not jumps.size or jumps.max() == 0:
        return 0, float(result.times[0]), 0.0
    k, a = np.unravel_index(int(np.argmax(jumps)), jumps.shape)
    return int(a), float(result.times[k + 1]), float(jumps[k, a])


def _per_run_rmse(result: MonteCarloResult, name: str, idx: list[int], cells: np.ndarray) -> np.ndarray:
    """Each run's RMSE over the (step, axis) cells where ``cells`` (K, A) is True, for state indices ``idx`` (one per axis)."""
    e = result.filters[name].estimates[..., idx] - result.truth[..., idx]  # (K, M, A)
    w = np.broadcast_to(cells[:, None, :], e.shape)
    return np.sqrt((e * e * w).sum(axis=(0, 2)) / max(int(cells.sum()), 1))


def _mean_rmse(result: MonteCarloResult, name: str, idx: int, steps: np.ndarray) -> float:
    return float(np.mean(result.rmse_per_step(name, (idx,))[steps])) if steps.any() else float("nan")


# --------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------
def rmse_table(result: MonteCarloResult, axes: str) -> Table:
    """Time-averaged per-step RMSE per filter and axis."""
    rows = []
    everything = np.ones(result.steps, dtype=bool)
    for name in result.filter_names:
        diverged = (result.divergence(name) or {}).get("diverged")
        for a, axis in enumerate(axes):
            rows.append([name, axis, *(_mean_rmse(result, name, i, everything) for i in _axis_indices(result, a)), diverged])
    return Table(
        "rmse",
        f"{result.scenario}: RMSE averaged over time (mean over steps of the RMSE over {result.runs} runs), seed {result.seed}",
        ["filter", "axis", "position_m", "velocity_m_s", "acceleration_m_s2", "diverged"],
        rows,
        notes="diverged: the filter's runs flagged diverged (docs/concepts.md, diverged runs), whose errors are in the RMSE.",
    )


def _axis_segments(scenario: Any, axis: str, times: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The schedule of one axis cut into labelled spans of filter steps, quiet spans included."""
    spans = sorted((m.start, m.stop, m.label()) for m in getattr(scenario, "maneuvers", ()) if axis in m.axes)
    out, t0 = [], times[0]
    for start, stop, label in spans:
        quiet = (times >= t0) & (times < start)
        if quiet.any():
            out.append((f"{axis} no maneuver {times[quiet][0]:g}-{times[quiet][-1]:g} s", quiet))
        on = (times >= start) & (times <= stop)
        if on.any():
            out.append((label, on))
        t0 = max(t0, stop + 1e-9)
    rest = times >= t0
    if rest.any():
        out.append((f"{axis} no maneuver {times[rest][0]:g}-{times[rest][-1]:g} s", rest))
    return out


def segment_table(result: MonteCarloResult, scenario: Any, a: int, axis: str) -> Table:
    """Time-averaged RMSE on each segment of one axis."""
    rows = []
    idx = _axis_indices(result, a)
    for label, steps in _axis_segments(scenario, axis, result.times):
        for name in result.filter_names:
            rows.append([label, name, *(_mean_rmse(result, name, i, steps) for i in idx)])
    return Table(
        "segments",
        f"{axis} axis (strongest maneuver): RMSE averaged over each segment's steps",
        ["segment", "filter", "position_m", "velocity_m_s", "acceleration_m_s2"],
        rows,
    )


def _settled_quiet(maneuvering: np.ndarray) -> np.ndarray:
    """Quiet steps at least SETTLE_STEPS after the start and after the axis's last maneuver step."""
    K, A = maneuvering.shape
    out = np.zeros_like(maneuvering)
    for a in range(A):
        last = -np.inf
        for k in range(K):
            if maneuvering[k, a]:
                last = k
            out[k, a] = (not maneuvering[k, a]) and k >= SETTLE_STEPS and k - last > SETTLE_STEPS
    return out


def detection_table(result: MonteCarloResult, filters: list[Any], maneuvering: np.ndarray) -> Table | None:
    """False-alarm and onset detection rates of filters with a maneuver detector."""
    names = [f.name for f in filters if "maneuver" in result.filters[f.name].info]
    if not names:
        return None
    settled = _settled_quiet(maneuvering)
    onset = np.zeros_like(maneuvering)
    starts = maneuvering & ~np.vstack([np.zeros((1, maneuvering.shape[1]), bool), maneuvering[:-1]])
    onset |= starts
    onset[1:] |= starts[:-1]
    rows = []
    for f in filters:
        if f.name not in names:
            continue
        det = result.filters[f.name].info["maneuver"]  # (K, M, A)
        n_q = int(settled.sum()) * result.runs
        fired = int(det[np.broadcast_to(settled[:, None, :], det.shape)].sum())
        p = float(stats.chi2.sf(getattr(f, "threshold", np.nan), 1))
        rate = fired / n_q if n_q else float("nan")
        lo, hi = (stats.binom.ppf([0.025, 0.975], n_q, rate) / n_q) if n_q else (np.nan, np.nan)
        on_rate = float(det[np.broadcast_to(onset[:, None, :], det.shape)].mean()) if onset.any() else float("nan")
        rows.append([f.name, p, rate, float(lo), float(hi), n_q, on_rate])
    return Table(
        "detections",
        f"Maneuver detector: rate on settled non-maneuvering steps (>= {SETTLE_STEPS} steps after a maneuver) and at onsets",
        ["filter", "configured_p", "quiet_rate", "quiet_rate_lo95", "quiet_rate_hi95", "quiet_trials", "onset_rate"],
        rows,
        notes="configured_p = P{chi2(1) > M}; the detector is exact only when the nominal model matches the target.",
    )


def _paired(result: MonteCarloResult, base: str, adapt: str, idx: list[int], cells: np.ndarray) -> tuple[float, float, float]:
    rb = _per_run_rmse(result, base, idx, cells)
    ra = _per_run_rmse(result, adapt, idx, cells)
    d = rb - ra
    se = d.std(ddof=1) / np.sqrt(d.size) if d.size > 1 else np.nan
    return float(rb.mean()), float(ra.mean()), float(d.mean() / se) if se and np.isfinite(se) and se > 0 else float("nan")


def claims_table(result: MonteCarloResult, scenario: Any, base: str, adapt: str, maneuvering: np.ndarray) -> Table:
    """P4's qualitative claims beside our measurements."""
    quiet = ~maneuvering
    comps = [("position", 0, "m"), ("velocity", 1, "m/s"), ("acceleration", 2, "m/s²")]
    rows = []
    pos = [p for p in result.position_indices]
    first = min((m.start for m in getattr(scenario, "maneuvers", ())), default=np.inf)
    before = np.broadcast_to((result.times < first)[:, None], maneuvering.shape)
    b0, a0, z0 = _paired(result, base, adapt, pos, before)
    b, a, z = _paired(result, base, adapt, pos, quiet)
    rows.append(
        [
            "Without maneuvers both filters track well",
            "qualitative (Table 2 missing)",
            f"position RMSE before the first maneuver: {base} {b0:.3g} m, {adapt} {a0:.3g} m (z = {z0:.1f}); "
            f"on all non-maneuvering steps, recovery included: {base} {b:.3g} m, {adapt} {a:.3g} m (z = {z:.1f})",
        ]
    )
    for comp, off, unit in comps:
        idx = [p + off for p in pos]
        b, a, z = _paired(result, base, adapt, idx, maneuvering)
        verdict = "holds" if z > 3 else ("reversed" if z < -3 else "not significant")
        rows.append(
            [
                f"Under strong maneuvers {adapt} has lower {comp} RMSE than {base}",
                "qualitative (Table 2 missing)",
                f"maneuvering steps: {base} {b:.3g} {unit}, {adapt} {a:.3g} {unit}, ratio {a / b:.3f}, z = {z:.1f}: {verdict}",
            ]
        )
    # gap against maneuver strength, per acceleration segment
    gaps = []
    axes = _axes(scenario)
    for m in getattr(scenario, "maneuvers", ()):
        if m.kind != "accel" or m.accel == 0.0:
            continue
        ai = axes.index(m.axis)
        cells = np.zeros_like(maneuvering)
        cells[:, ai] = (result.times >= m.start) & (result.times <= m.stop)
        if not cells.any():
            continue
        b, a, _ = _paired(result, base, adapt, pos, cells)
        gaps.append((abs(m.accel), 1.0 - a / b, m.label()))
    if len(gaps) >= 3:
        rho = stats.spearmanr([g[0] for g in gaps], [g[1] for g in gaps]).statistic
        detail = "; ".join(f"|a| {g[0]:g}: {100 * g[1]:+.0f} %" for g in sorted(gaps))
        measured = f"position RMSE reduction by segment: {detail}; Spearman rho = {rho:.2f} over {len(gaps)} segments"
    else:
        measured = "too few acceleration segments to tell"
    rows.append(["The stronger the maneuver, the larger the gap", "qualitative", measured])
    return Table("claims", f"Paper P4's claims ({adapt} vs {base}) beside what we measured", ["claim", "paper", "measured"], rows, notes=PAPER_NOTE, kind="paper")


# --------------------------------------------------------------------------
# the plan
# --------------------------------------------------------------------------
@dataclass
class ManeuverPlan:
    """A validated ``maneuver`` experiment."""

    name: str
    scenario: Any
    filters: list[Any]
    figure_opts: dict[str, Any]
    claims: dict[str, Any] | None
    sections: dict[str, Any] = field(repr=False)

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Run the comparison and assemble tables and figures."""
        result = monte_carlo(
            self.scenario, self.filters, runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
            store="full",  # per-axis errors, detections and mode probabilities need every run's arrays
            label=self.name,
        )
        axes = _axes(self.scenario)
        maneuvering = _maneuvering(self.scenario, result)
        a_star, t_star, jump = _strongest_onset(result)
        if self.figure_opts["zoom_at"] is not None:
            t_star = self.figure_opts["zoom_at"]
        tables = [rmse_table(result, axes), segment_table(result, self.scenario, a_star, axes[a_star])]
        det = detection_table(result, self.filters, maneuvering)
        if det is not None:
            tables.append(det)
        names = result.filter_names
        if self.claims is not None and self.claims["baseline"] in names and self.claims["adaptive"] in names:
            tables.append(claims_table(result, self.scenario, self.claims["baseline"], self.claims["adaptive"], maneuvering))

        segs = _segments(self.scenario)
        log = self.figure_opts["log_rmse"]
        figs: dict[str, Any] = {}
        for a, axis in enumerate(axes):
            figs[f"rmse_{axis}"] = rmse_panels(result, axis, _axis_indices(result, a), segs, log=log)
        window = (t_star - self.figure_opts["zoom_before"], t_star + self.figure_opts["zoom_after"])
        figs["rmse_zoom"] = rmse_panels(
            result,
            axes[a_star],
            _axis_indices(result, a_star),
            segs,
            window=window,
            log=log,
            title=f"Zoom on the strongest maneuver: {axes[a_star]} axis at t = {t_star:g} s (acceleration jump {jump:g} m/s²)",
        )
        labels = {f.name: [getattr(g, "name", "") for g in f.filters] for f in self.filters if hasattr(f, "transition")}
        modes = mode_probabilities(result, segs, labels)
        if modes is not None:
            figs["mode_probabilities"] = modes
        p = {f.name: float(stats.chi2.sf(f.threshold, 1)) for f in self.filters if hasattr(f, "threshold")}
        rates = detection_rates(result, axes, segs, p)
        if rates is not None:
            figs["detections"] = rates
        consistency = consistency_over_time(result)
        if consistency is not None:
            figs["consistency"] = consistency
        sidecar = {"strongest_maneuver": {"axis": axes[a_star], "time_s": t_star, "jump_m_s2": jump}}
        return ExperimentOutput(self.name, "", "", tables, figs, results={"result": result}, sidecar=sidecar)


@register(
    "experiment",
    "maneuver",
    "Maneuvering-target comparison with per-axis RMSE, maneuver segments and the claims of Fang & Yang's paper; "
    "sections [scenario], [[filters]], [figures], [claims]",
)
def _maneuver(sections: dict[str, Any], path: Path, name: str) -> ManeuverPlan:
    for key in sections:
        if key not in _KNOWN_SECTIONS:
            raise ValueError(f"{key}: unknown section (known: experiment, {', '.join(sorted(_KNOWN_SECTIONS))})")
    scenario = build_scenario(sections)
    for attr in ("position_indices", "velocity_indices"):
        if not getattr(scenario, attr, None):
            raise ValueError(f"scenario.type: the maneuver experiment needs a scenario with {attr}")
    idx = scenario.position_indices
    if any(tuple(range(p, p + 3)) != (p, scenario.velocity_indices[i], p + 2) for i, p in enumerate(idx)):
        raise ValueError("scenario.type: the maneuver experiment needs a [p, v, a] state per axis")
    filters = build_filters(sections, scenario)
    figure_opts = resolve_section(sections, "figures", FIGURE_PARAMS)
    claims = resolve_section(sections, "claims", CLAIM_PARAMS) if "claims" in sections else None
    if claims is not None:
        names = [f.name for f in filters]
        for key in ("baseline", "adaptive"):
            if claims[key] not in names:
                raise ValueError(f"claims.{key}: no filter named {claims[key]!r} (have {', '.join(names)})")
    return ManeuverPlan(name, scenario, filters, figure_opts, claims, sections)
