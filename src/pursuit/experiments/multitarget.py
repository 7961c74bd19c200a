"""The ``multitarget`` experiment kind: several multi-target trackers on one scenario, scored by GOSPA.

Sections: ``[scenario]`` (an ``mt-*`` scenario), ``[[trackers]]`` (``gnn``,
``jpda``, ``pmht``, ``epmht``, ``gmphd``, each with its per-track filter),
``[metrics]`` (GOSPA's cut-off, order and α), ``[figures]`` and
``[[claim]]``.  Every tracker sees the same truth and detections (common
random numbers, one stream per run); all runs are tracked in one batch, so
this kind does not chunk runs or use the Dask backend.

``[[claim]]``
    A claim judged by a paired interval, as in the ``maneuver`` kind
    (:func:`pursuit.experiments.maneuver.log_ratio_interval`): ``tracker``
    against ``baseline`` over the scans ``scans = [first, last]`` (1-based,
    inclusive; default all).  Each run gives one mean GOSPA per tracker over
    those scans; the verdict comes from the 95 % paired t-interval of the
    per-run log ratio ``log(GOSPA_tracker / GOSPA_baseline)``: "holds" when
    the whole interval is below 0 (the tracker's GOSPA is smaller),
    "reversed" when above, "not significant" otherwise.  The ``claims`` table
    (kind ``paper``) gives the numbers and the verdict per claim.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import registry
from ..config.build import build_scenario, resolve_section, resolve_section_list
from ..multitarget.metrics import gospa, gospa_summary, track_counts, track_switches
from ..multitarget.tracking import MultiTrackResult
from ..registry import Param, register
from ..report.mt_figures import gospa_over_time, scene
from ..rng import run_streams
from ..scenarios.multitarget import MultiTargetScenario
from ..tables import ExperimentOutput, Table
from .maneuver import log_ratio_interval, ratio_verdict
from .montecarlo import check_run_exists, run_index

__all__ = ["MultiTargetPlan", "TrackerScore", "score", "claims_table"]

SCENARIO_STREAM = 0  # the scenario's stream of each run (the trackers draw nothing)


def _positive(field_name: str, v: float) -> float:
    if not v > 0:
        raise ValueError(f"{field_name}: must be positive, got {v!r}")
    return v


def _order(field_name: str, v: float) -> float:
    if not (1.0 <= v < np.inf):
        raise ValueError(f"{field_name}: must be a finite number >= 1, got {v!r}")
    return v


def _alpha(field_name: str, v: float) -> float:
    if not 0.0 < v <= 2.0:
        raise ValueError(f"{field_name}: must lie in (0, 2], got {v!r}")
    return v


METRIC_PARAMS = (
    Param("c", "float", 10.0, "GOSPA cut-off distance (position units)", check=_positive),
    Param("p", "float", 2.0, "GOSPA order p >= 1", check=_order),
    Param("alpha", "float", 2.0, "GOSPA alpha in (0, 2]; 2 gives the localisation / missed / false parts", check=_alpha),
)


def _scan_range(field_name: str, v: Any) -> list[int]:
    if len(v) not in (0, 2) or any(float(x) != int(x) or x < 1 for x in v):
        raise ValueError(f"{field_name}: expected [first, last], two scan numbers >= 1 (or [] for all scans), got {list(v)!r}")
    if len(v) == 2 and v[0] > v[1]:
        raise ValueError(f"{field_name}: first must not exceed last, got {list(v)!r}")
    return [int(x) for x in v]


CLAIM_PARAMS = (
    Param("text", "str", "", "the claim in words"),
    Param("baseline", "str", registry.REQUIRED, "the tracker it is compared against"),
    Param("tracker", "str", registry.REQUIRED, "the tracker the claim is about"),
    Param("scans", "vector", [], "[first, last]: the scans judged (1-based, inclusive; default: all)", check=_scan_range),
)
FIGURE_PARAMS = (Param("scene_run", "int", 0, "which run's truth, detections and tracks to draw (0 .. runs-1)", check=run_index),)


@dataclass(frozen=True)
class TrackerScore:
    """One tracker's scores over the runs (arrays over runs ``(M,)`` or scans and runs ``(K, M)``)."""

    name: str
    result: MultiTrackResult
    gospa: Any  # pursuit.multitarget.metrics.Gospa, (K, M)
    summary: dict[str, Any]  # gospa_summary
    switches: np.ndarray  # (M,) track switches per run
    counts: Any  # TrackCounts, (M,)
    wall_time: float


def score(name: str, result: MultiTrackResult, truth: Any, position_indices, metrics: dict[str, float], wall_time: float) -> TrackerScore:
    """GOSPA, its parts, track switches and track counts of one tracker's result against the truth."""
    est, est_mask = result.positions(position_indices)
    tp = truth.positions(position_indices)
    tmask = truth.exists
    g = gospa(tp, tmask, est, est_mask, metrics["c"], metrics["p"], metrics["alpha"])
    switches = track_switches(tp, tmask, est, result.label, est_mask, metrics["c"], metrics["p"]).sum(axis=-1)
    counts = track_counts(tp, tmask, est, result.label, est_mask, metrics["c"], metrics["p"])
    return TrackerScore(name, result, g, gospa_summary(g), switches, counts, wall_time)


def _mean_ci(values: np.ndarray) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return float(v.mean()), float("nan")
    return float(v.mean()), float(1.96 * v.std(ddof=1) / np.sqrt(v.size))


def _em_iterations(result: Any) -> float | None:
    """Mean EM iterations per window of a PMHT-family result; None for trackers without EM."""
    it = getattr(result, "iterations", None)
    if it is None:
        return None
    it = np.asarray(it, dtype=float)
    it = it[it > 0]  # scans before a first window, or with no track, ran no EM
    return float(it.mean()) if it.size else None


def summary_table(scores: list[TrackerScore], scenario: Any, runs: int, seed: int, metrics: dict[str, float]) -> Table:
    """Mean GOSPA (with its 95 % interval over runs), its parts, switches, track counts and speed per tracker."""
    rows = []
    steps = scenario.steps
    for s in scores:
        tot = s.summary["total"]
        sw, sw_ci = _mean_ci(s.switches)
        rows.append([
            s.name, tot.mean, tot.half_width,
            s.summary["localisation"].mean, s.summary["missed"].mean, s.summary["false"].mean,
            sw, sw_ci,
            float(np.mean(s.counts.confirmed)), float(np.mean(s.counts.false)), float(np.mean(s.counts.lost)),
            float(np.mean(s.result.dropped.sum(axis=0))),
            _em_iterations(s.result),
            s.wall_time, runs * steps / s.wall_time if s.wall_time > 0 else None,
        ])
    c, p, a = metrics["c"], metrics["p"], metrics["alpha"]
    return Table(
        "summary",
        f"{scenario.name}: {runs} runs, seed {seed}; GOSPA c = {c:g}, p = {p:g}, alpha = {a:g}",
        ["tracker", "gospa", "gospa_ci95", "localisation", "missed", "false", "switches", "switches_ci95",
         "confirmed_tracks", "false_tracks", "lost_truths", "dropped_tracks", "em_iterations", "wall_time_s", "scans_per_s"],
        rows,
        notes=(
            "gospa: GOSPA per scan averaged over scans and runs (distance units), with the half-width of its 95 % "
            f"Student-t interval over the runs' time averages; localisation, missed, false: its parts in units of "
            f"distance^p, averaged over scans and runs (they add up to the mean of GOSPA^p, not of GOSPA). "
            "switches: label changes of the track assigned to a truth, per run. confirmed_tracks: distinct labels "
            "confirmed in a run; false_tracks: those assigned to no truth for more than half their life; "
            "lost_truths: truths unassigned for more than half their existence. em_iterations: mean EM iterations per "
            "window (PMHT, EPMHT; empty for the others). scans_per_s: runs x scans / wall time "
            "(all runs in one batch, one process)."
        ),
    )


def claims_table(claims: list[dict[str, Any]], gospa_total: dict[str, np.ndarray]) -> Table:
    """One verdict per ``[[claim]]`` from each tracker's per-scan GOSPA ``(K, M)`` (see the module notes)."""
    rows = []
    for c in claims:
        K = gospa_total[c["tracker"]].shape[0]
        first, last = c["scans"] or [1, K]
        if last > K:
            raise ValueError(f"claim.scans: the scenario has {K} scans, got last = {last}")
        rb = gospa_total[c["baseline"]][first - 1 : last].mean(axis=0)
        rf = gospa_total[c["tracker"]][first - 1 : last].mean(axis=0)
        # A run with a GOSPA of exactly 0 over the window (no target, no false track) has no ratio: it is
        # left out of the interval, and the runs column says how many runs the verdict rests on.
        ratio_defined = (rb > 0) & (rf > 0)
        m, lo, hi = log_ratio_interval(rb[ratio_defined], rf[ratio_defined])
        rows.append([
            c["text"] or f"{c['tracker']} has a smaller GOSPA than {c['baseline']}",
            f"{first}-{last}", c["baseline"], c["tracker"],
            float(np.median(rb)), float(np.median(rf)), float(np.exp(m)), float(np.exp(lo)), float(np.exp(hi)),
            int(ratio_defined.sum()), ratio_verdict(lo, hi),
        ])  # fmt: skip
    return Table(
        "claims",
        "Claims judged from the measured runs (paired over runs, common random numbers)",
        ["claim", "scans", "baseline", "tracker", "baseline_median_gospa", "tracker_median_gospa", "ratio", "ratio_lo95", "ratio_hi95", "runs", "verdict"],
        rows,
        notes="ratio: geometric mean over runs of GOSPA_tracker / GOSPA_baseline (each run's mean GOSPA over the judged scans), "
        "with its 95 % paired t-interval; holds: the whole interval below 1; reversed: above 1. runs: the runs it rests on "
        "(a run whose GOSPA over the judged scans is exactly 0 for either tracker has no ratio and is left out).",
        kind="paper",
    )


@dataclass
class MultiTargetPlan:
    """A validated ``multitarget`` experiment."""

    name: str
    scenario: MultiTargetScenario
    trackers: list[Any]
    metrics: dict[str, float]
    figure_opts: dict[str, Any]
    sections: dict[str, Any] = field(repr=False)
    claims: list[dict[str, Any]] = field(default_factory=list)

    def check_runs(self, runs: int) -> None:
        """Raise ``ValueError`` (naming the field) when an option refers to a run beyond ``runs``."""
        check_run_exists("figures.scene_run", self.figure_opts["scene_run"], runs)

    def run(self, *, runs: int, seed: int, progress: bool = False, chunk_size: int | None = None) -> ExperimentOutput:
        """Simulate once, track with every tracker, score and assemble tables and figures.

        ``chunk_size`` is accepted for the common interface and ignored: the
        runs are tracked in one batch.
        """
        self.check_runs(runs)
        truth, scans = self.scenario.simulate(run_streams(seed, range(runs), SCENARIO_STREAM), runs)
        pos = self.scenario.position_indices
        scores = []
        for tracker in self.trackers:
            t0 = time.perf_counter()
            result = tracker.track(scans.z, times=scans.times)
            wall = time.perf_counter() - t0
            scores.append(score(tracker.name, result, truth, pos, self.metrics, wall))
            if progress:
                print(f"  {tracker.name}: {wall:.2f} s", flush=True)
        tables = [summary_table(scores, self.scenario, runs, seed, self.metrics)]
        if self.claims:
            tables.insert(0, claims_table(self.claims, {s.name: np.asarray(s.gospa.total) for s in scores}))
        run = self.figure_opts["scene_run"]
        figs = {
            "gospa": gospa_over_time({s.name: s.summary for s in scores}, scans.times, self.metrics),
            "scene": scene(truth, scans, {s.name: s.result for s in scores}, pos, run, title_prefix=self.scenario.name),
        }
        results = {f"gospa_{s.name}": np.asarray(s.gospa.total) for s in scores}
        return ExperimentOutput(self.name, "", "", tables, figs, results=results)


_KNOWN_SECTIONS = {"scenario", "trackers", "metrics", "figures", "claim"}


def build_trackers(sections: dict[str, Any], scenario: Any) -> list[Any]:
    """Build every ``[[trackers]]`` entry against the scenario; names must be unique."""
    entries = sections.get("trackers")
    if entries is None:
        raise ValueError("trackers: required section is missing (add [[trackers]] tables)")
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError("trackers: expected one or more [[trackers]] tables")
    out = []
    for i, entry in enumerate(entries):
        where = f"trackers[{i}]"
        values = dict(entry)
        kind = values.pop("type", None)
        if kind is None:
            raise ValueError(f"{where}.type: required (gnn or jpda)")
        comp = registry.get("tracker", kind, f"{where}.type")
        out.append(comp.build(scenario=scenario, where=where, **comp.resolve(values, where)))
    names = [t.name for t in out]
    for i, n in enumerate(names):
        if names.index(n) != i:
            raise ValueError(f"trackers[{i}].name: {n!r} is used twice (give each tracker its own name)")
    return out


@register(
    "experiment",
    "multitarget",
    "Compare multi-target trackers on one scenario by GOSPA; sections [scenario], [[trackers]], [metrics], [figures], [[claim]] (paired verdicts)",
)
def _multitarget(sections: dict[str, Any], path: Path, name: str) -> MultiTargetPlan:
    for key in sections:
        if key not in _KNOWN_SECTIONS:
            raise ValueError(f"{key}: unknown section (known: experiment, {', '.join(sorted(_KNOWN_SECTIONS))})")
    scenario = build_scenario(sections, multi_target=True)
    trackers = build_trackers(sections, scenario)
    metrics = resolve_section(sections, "metrics", METRIC_PARAMS)
    figure_opts = resolve_section(sections, "figures", FIGURE_PARAMS)
    claims = resolve_claims(sections, [t.name for t in trackers], scenario.steps)
    return MultiTargetPlan(name, scenario, trackers, metrics, figure_opts, sections, claims)


def resolve_claims(sections: dict[str, Any], names: list[str], steps: int) -> list[dict[str, Any]]:
    """Check the ``[[claim]]`` tables: known tracker names, scans within the scenario's."""
    out = []
    for where, c in resolve_section_list(sections, "claim", CLAIM_PARAMS):
        for key in ("baseline", "tracker"):
            if c[key] not in names:
                raise ValueError(f"{where}.{key}: no tracker named {c[key]!r} (have {', '.join(names)})")
        if c["scans"] and c["scans"][1] > steps:
            raise ValueError(f"{where}.scans: the scenario has {steps} scans, got last = {c['scans'][1]}")
        out.append(c)
    return out
