"""The ``maneuver`` experiment kind: per-axis RMSE of maneuvering-target filters (paper P4).

Sections: ``[scenario]`` (a scenario with ``[p, v, a]`` per axis, e.g.
``maneuver-3d`` or ``bearings``), ``[[filters]]``, optional ``[figures]``,
``[claims]`` (P4's claims), ``[[variants]]`` and ``[[claim]]``.

``[[variants]]``
    Scenario variants: a ``label`` and any ``[scenario]`` keys to override.
    The comparison runs once per variant (same seed, filters rebuilt for
    each), and every table, figure and result is suffixed with the variant's
    label (``rmse-weak-2D``).
``[[claim]]``
    A claim judged by a paired interval: ``filter`` against ``baseline`` on
    the ``steps`` (all, maneuvering, quiet) of one ``variant``, for one
    ``component`` (position, velocity, acceleration, all axes together).
    Each run gives one RMSE per filter over those steps; the verdict comes
    from the 95 % paired t-interval of the per-run log ratio
    ``log(RMSE_filter / RMSE_baseline)`` (geometric-mean ratio; a log keeps
    a few diverged runs from deciding it): "holds" when the whole interval
    is below 0 (the filter is more accurate), "reversed" when above, "not
    significant" otherwise.  The ``claims`` table (kind ``paper``) gives the
    numbers and the verdict per claim.

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
    With ``[[claim]]`` tables instead: one verdict line per claim.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from ..config.build import build_filters, build_scenario, resolve_section, resolve_section_list
from ..engine.montecarlo import monte_carlo
from .. import registry
from ..registry import Param, register
from ..report.figures import consistency_over_time
from ..report.maneuver import Segment, detection_rates, mode_probabilities, rmse_panels
from ..results import MonteCarloResult
from ..tables import ExperimentOutput, Table

__all__ = ["ManeuverPlan", "log_ratio_interval", "ratio_verdict"]

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

CLAIM_ENTRY_PARAMS = (
    Param("text", "str", "", "the claim in words"),
    Param("variant", "str", "", "the scenario variant (label) it is judged on; default: the only scenario"),
    Param("baseline", "str", registry.REQUIRED, "the filter it is compared against"),
    Param("filter", "str", registry.REQUIRED, "the filter the claim is about"),
    Param("steps", "str", "all", "steps judged: all, maneuvering (any axis maneuvers) or quiet", choices=("all", "maneuvering", "quiet")),
    Param("component", "str", "position", "error judged (all axes together)", choices=("position", "velocity", "acceleration")),
)
_KNOWN_SECTIONS = {"scenario", "filters", "figures", "claims", "variants", "claim"}
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
        p = float(stats.chi2.sf(getattr(f, "threshold", np.nan), getattr(f, "detection_dof", 1)))
        rate = fired / n_q if n_q else float("nan")
        lo, hi = (stats.binom.ppf([0.025, 0.975], n_q, rate) / n_q) if n_q else (np.nan, np.nan)
        on_rate = float(det[np.broadcast_to(onset[:, None, :], det.shape)].mean()) if onset.any() else float("nan")
        rows.append([f.name, p, rate, float(lo), float(hi), n_q, on_rate])
    return Table(
        "detections",
        f"Maneuver detector: rate on settled non-maneuvering steps (>= {SETTLE_STEPS} steps after a maneuver) and at onsets",
        ["filter", "configured_p", "quiet_rate", "quiet_rate_lo95", "quiet_rate_hi95", "quiet_trials", "onset_rate"],
        rows,
        notes="configured_p = P{chi2(m) > M}, m the dimension of the residual tested (1 per axis; 2 for azimuth and elevation); "
        "the detector is exact only when the nominal model matches the target.",
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


def log_ratio_interval(rb: np.ndarray, rf: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95 % paired t-interval of log(rf / rb) over runs."""
    d = np.log(rf) - np.log(rb)
    d = d[np.isfinite(d)]
    if d.size < 2:
        return float("nan"), float("nan"), float("nan")
    half = float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size))
    m = float(d.mean())
    return m, m - half, m + half


def ratio_verdict(lo: float, hi: float) -> str:
    """The verdict on "the filter's error is smaller" from the 95 % interval of log(error ratio)."""
    return "holds" if hi < 0 else ("reversed" if lo > 0 else "not significant")


def paired_claims_table(claims: list[dict[str, Any]], measured: dict[str, tuple[MonteCarloResult, np.ndarray]]) -> Table:
    """One verdict per ``[[claim]]``: paired 95 % interval of the per-run RMSE log ratio (see the module notes)."""
    rows = []
    for c in claims:
        result, maneuvering = measured[c["variant"]]
        K, A = maneuvering.shape
        any_axis = maneuvering.any(axis=1)
        pick = {"all": np.ones(K, bool), "maneuvering": any_axis, "quiet": ~any_axis}[c["steps"]]
        cells = np.broadcast_to(pick[:, None], (K, A))
        off = {"position": 0, "velocity": 1, "acceleration": 2}[c["component"]]
        idx = [p + off for p in result.position_indices]
        rb = _per_run_rmse(result, c["baseline"], idx, cells)
        rf = _per_run_rmse(result, c["filter"], idx, cells)
        m, lo, hi = log_ratio_interval(rb, rf)
        verdict = ratio_verdict(lo, hi)
        rows.append(
            [
                c["text"] or f"{c['filter']} more accurate than {c['baseline']}",
                c["variant"],
                c["steps"],
                c["component"],
                c["baseline"],
                c["filter"],
                float(np.median(rb)),
                float(np.median(rf)),
                float(np.exp(m)),
                float(np.exp(lo)),
                float(np.exp(hi)),
                verdict,
            ]
        )
    return Table(
        "claims",
        "Claims judged from the measured runs (paired over runs, common random numbers)",
        [
            "claim",
            "variant",
            "steps",
            "component",
            "baseline",
            "filter",
            "baseline_median_rmse",
            "filter_median_rmse",
            "ratio",
            "ratio_lo95",
            "ratio_hi95",
            "verdict",
        ],
        rows,
        notes="ratio: geometric mean over runs of RMSE_filter / RMSE_baseline (each run's RMSE over the judged steps, all axes), "
        "with its 95 % paired t-interval; holds: the whole interval below 1; reversed: above 1.",
        kind="paper",
    )


def _slug(label: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in label).strip("-") or "variant"


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
    variants: list[dict[str, Any]] = field(default_factory=list)
    claim_list: list[dict[str, Any]] = field(default_factory=list)

    def _variant(self, variant: dict[str, Any]) -> tuple[Any, list[Any]]:
        sections = dict(self.sections)
        table = dict(sections["scenario"])
        table.update({k: v for k, v in variant.items() if k != "label"})
        sections["scenario"] = table
        scenario = build_scenario(sections)
        return scenario, build_filters(sections, scenario)

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Run the comparison (once per variant) and assemble tables and figures."""
        if not self.variants:
            out, result, maneuvering = self._run_one(self.scenario, self.filters, self.claims, runs, seed, progress, chunk_size)
            if self.claim_list:
                out.tables.append(paired_claims_table(self.claim_list, {"": (result, maneuvering)}))
            return out
        tables: list[Table] = []
        figs: dict[str, Any] = {}
        results: dict[str, Any] = {}
        sidecar: dict[str, Any] = {}
        measured: dict[str, tuple[MonteCarloResult, np.ndarray]] = {}
        for variant in self.variants:
            label, slug = variant["label"], _slug(variant["label"])
            scenario, filters = self._variant(variant)
            out, result, maneuvering = self._run_one(scenario, filters, None, runs, seed, progress, chunk_size)
            measured[label] = (result, maneuvering)
            for t in out.tables:
                tables.append(replace(t, name=f"{t.name}-{slug}", title=f"[{label}] {t.title}"))
            figs.update({f"{key}-{slug}": fig for key, fig in out.figures.items()})
            results[f"result-{slug}"] = result
            sidecar[label] = out.sidecar
        if self.claim_list:
            tables.insert(0, paired_claims_table(self.claim_list, measured))
        return ExperimentOutput(self.name, "", "", tables, figs, results=results, sidecar={"variants": sidecar})

    def _run_one(self, scenario, filters, claims, runs, seed, progress, chunk_size) -> tuple[ExperimentOutput, MonteCarloResult, np.ndarray]:
        result = monte_carlo(
            scenario, filters, runs, seed, chunk_size=chunk_size, progress=progress, config=self.sections,
            store="full",  # per-axis errors, detections and mode probabilities need every run's arrays
            label=self.name,
        )
        axes = _axes(scenario)
        maneuvering = _maneuvering(scenario, result)
        a_star, t_star, jump = _strongest_onset(result)
        if self.figure_opts["zoom_at"] is not None:
            t_star = self.figure_opts["zoom_at"]
        tables = [rmse_table(result, axes), segment_table(result, scenario, a_star, axes[a_star])]
        det = detection_table(result, filters, maneuvering)
        if det is not None:
            tables.append(det)
        names = result.filter_names
        if claims is not None and claims["baseline"] in names and claims["adaptive"] in names:
            tables.append(claims_table(result, scenario, claims["baseline"], claims["adaptive"], maneuvering))

        segs = _segments(scenario)
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
        labels = {f.name: [getattr(g, "name", "") for g in f.filters] for f in filters if hasattr(f, "transition")}
        modes = mode_probabilities(result, segs, labels)
        if modes is not None:
            figs["mode_probabilities"] = modes
        p = {f.name: float(stats.chi2.sf(f.threshold, getattr(f, "detection_dof", 1))) for f in filters if hasattr(f, "threshold")}
        rates = detection_rates(result, axes, segs, p)
        if rates is not None:
            figs["detections"] = rates
        consistency = consistency_over_time(result)
        if consistency is not None:
            figs["consistency"] = consistency
        sidecar = {"strongest_maneuver": {"axis": axes[a_star], "time_s": t_star, "jump_m_s2": jump}}
        out = ExperimentOutput(self.name, "", "", tables, figs, results={"result": result}, sidecar=sidecar)
        return out, result, maneuvering


@register(
    "experiment",
    "maneuver",
    "Maneuvering-target comparison with per-axis RMSE, maneuver segments and the claims of Fang & Yang's paper; "
    "sections [scenario], [[filters]], [figures], [claims], [[variants]], [[claim]] (paired verdicts)",
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
    variants = _resolve_variants(sections)
    plan = ManeuverPlan(name, scenario, filters, figure_opts, claims, sections, variants)
    names_of = {"": [f.name for f in filters]}
    for v in variants:
        try:
            names_of[v["label"]] = [f.name for f in plan._variant(v)[1]]
        except ValueError as e:
            raise ValueError(f"variants[{variants.index(v)}]: {e}") from None
    plan.claim_list = _resolve_claim_list(sections, names_of, bool(variants))
    if claims is not None and variants:
        raise ValueError("claims: P4's [claims] table needs a single scenario; with [[variants]] use [[claim]] tables")
    return plan


def _resolve_variants(sections: dict[str, Any]) -> list[dict[str, Any]]:
    variants = sections.get("variants", [])
    if not isinstance(variants, list) or not all(isinstance(v, dict) for v in variants):
        raise ValueError("variants: expected [[variants]] tables")
    for i, v in enumerate(variants):
        if not isinstance(v.get("label"), str) or not v["label"]:
            raise ValueError(f"variants[{i}].label: required (a short name for the scenario variant)")
    labels = [v["label"] for v in variants]
    if len(set(labels)) != len(labels):
        raise ValueError("variants: labels must be unique")
    if len({_slug(lbl) for lbl in labels}) != len(labels):
        raise ValueError("variants: labels must differ in their letters and digits (they name the tables)")
    return variants


def _resolve_claim_list(sections: dict[str, Any], names_of: dict[str, list[str]], has_variants: bool) -> list[dict[str, Any]]:
    out = []
    for where, c in resolve_section_list(sections, "claim", CLAIM_ENTRY_PARAMS):
        if has_variants and c["variant"] not in names_of or c["variant"] == "" and has_variants:
            known = ", ".join(k for k in names_of if k)
            raise ValueError(f"{where}.variant: no variant {c['variant']!r} (have {known})")
        if not has_variants and c["variant"]:
            raise ValueError(f"{where}.variant: the experiment has no [[variants]]")
        names = names_of[c["variant"]]
        for key in ("baseline", "filter"):
            if c[key] not in names:
                raise ValueError(f"{where}.{key}: no filter named {c[key]!r} (have {', '.join(names)})")
        out.append(c)
    return out
