"""The imm-cv filter (an IMM per track over a CV state), [[claim]] verdicts of the multitarget kind, mt-maneuver."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pursuit import registry
from pursuit.config.build import build_filter
from pursuit.experiment import ConfigError, load_experiment
from pursuit.experiments.maneuver import log_ratio_interval
from pursuit.experiments.multitarget import claims_table
from pursuit.filters import ExtendedKalmanFilter
from pursuit.filters.imm import InteractingMultipleModel
from pursuit.models.maneuver import ConstantTurn
from pursuit.models.motion import ConstantVelocity
from pursuit.multitarget import GNNTracker, JPDATracker, track_scans
from pursuit.rng import run_streams

ROOT = Path(__file__).resolve().parents[2]


def _scenario(name: str, **kw):
    comp = registry.get("scenario", name)
    return comp.build(where="scenario", **comp.resolve(kw, "scenario"))


# --------------------------------------------------------------------------
# imm-cv
# --------------------------------------------------------------------------
def test_imm_cv_builds_cv_and_turn_modes_on_the_scenarios_state():
    sc = _scenario("mt-maneuvering")
    table = {"type": "imm-cv", "modes": [{}, {"omega": 0.05, "q": 2.0}, {"q": 100.0}], "transition": 0.9, "initial_probs": [0.8, 0.1, 0.1]}
    imm = build_filter(table, sc, "trackers[0].filter")
    assert isinstance(imm, InteractingMultipleModel) and imm.modes == 3
    assert all(isinstance(f, ExtendedKalmanFilter) and f.measurement is sc.measurement for f in imm.filters)
    cv, ct, loud = (f.motion for f in imm.filters)
    assert cv == ConstantVelocity(ndim=2, dt=sc.dt, q=sc.motion.q)  # q defaults to the scenario's
    assert ct == ConstantTurn(omega=0.05, q=2.0, ndim=2, dt=sc.dt)
    assert loud.q == 100.0 and isinstance(loud, ConstantVelocity)
    np.testing.assert_allclose(imm.transition, [[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]])
    np.testing.assert_allclose(imm.initial_probs, [0.8, 0.1, 0.1])
    # the turning mode's transition rotates the velocity by omega * dt
    F = np.asarray(ct.transition_matrix(None))
    v = F @ np.array([0.0, 100.0, 0.0, 0.0])
    assert np.arctan2(v[3], v[1]) == pytest.approx(0.05 * sc.dt, rel=1e-12)


def test_gnn_with_a_one_mode_imm_cv_is_gnn_with_the_ekf():
    """An IMM with one mode (the scenario's CV) is that mode's EKF: the tracks agree to rounding."""
    sc = _scenario("mt-maneuvering")
    truth, scans = sc.simulate(run_streams(4, range(2), 0), 2)
    z = scans.z[:30]
    out = []
    for table in ({"type": "ekf"}, {"type": "imm-cv", "modes": [{}]}):
        filt = build_filter(table, sc, "f")
        for cls in (GNNTracker, JPDATracker):
            tracker = cls(filt, sc.p_detect, sc.clutter_density, max_speed=sc.max_speed)
            out.append(track_scans(tracker, z, times=scans.times[:30]))
    for a, b in ((out[0], out[2]), (out[1], out[3])):
        np.testing.assert_array_equal(a.label, b.label)
        np.testing.assert_allclose(np.nan_to_num(b.mean), np.nan_to_num(a.mean), rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize(
    "table, message",
    [
        ({"modes": []}, "f.modes: expected a list of mode tables"),
        ({"modes": {"q": 1.0}}, "f.modes: expected a list of mode tables"),
        ({"modes": [{"q": 1.0}, {"rate": 0.1}]}, "f.modes[1].rate: unknown key for a mode"),
        ({"modes": [{"q": -1.0}]}, "f.modes[0].q: must be a non-negative"),
        ({"modes": [{"omega": "fast"}]}, "f.modes[0].omega: expected a finite number"),
        ({"modes": [{"q": True}]}, "f.modes[0].q: expected a finite number"),
        ({"transition": 1.5}, "f.transition: a staying probability must lie in [0, 1]"),
        ({"transition": "high"}, "f.transition: expected a staying probability or a matrix"),
        ({"initial_probs": [1.0, 0.0]}, "f.initial_probs: expected 3"),
        ({"mode_filter": "pf"}, "f.mode_filter: must be one of"),
        ({"mode_filter": "kf"}, "f.mode_filter: KalmanFilter needs a linear measurement model"),
        ({"gate": 1.5}, "f.gate: must lie in (0, 1)"),
        ({"speed": 3}, "f.speed: unknown key for filter 'imm-cv'"),
    ],
)
def test_imm_cv_refuses_bad_fields_naming_them(table, message):
    sc = _scenario("mt-maneuvering")
    with pytest.raises(ValueError) as info:
        build_filter({"type": "imm-cv", **table}, sc, "f")
    assert message in str(info.value)


def test_imm_cv_needs_a_constant_velocity_scenario():
    with pytest.raises(ValueError, match=r"filters\[0\]\.type: imm-cv needs a scenario with a constant-velocity motion model"):
        build_filter({"type": "imm-cv"}, _scenario("maneuver-3d"), "filters[0]")
    one_d = _scenario("cv-position", ndim=1)  # a 1-D CV: CV modes are fine, a turn is not
    with pytest.raises(ValueError, match=r"filters\[0\]\.modes\[1\]\.omega: a turn needs a 2-D or 3-D state"):
        build_filter({"type": "imm-cv", "modes": [{}, {"omega": 0.1}]}, one_d, "filters[0]")
    assert build_filter({"type": "imm-cv", "modes": [{}, {"q": 10.0}]}, one_d, "filters[0]").modes == 2


def test_pmht_refuses_an_imm_naming_the_filter():
    # PMHT's smoother needs one linear motion model (its multiple-model form is mmpmht, over noise levels)
    sc = _scenario("mt-maneuvering")
    with pytest.raises(ValueError, match=r"trackers\[0\]\.filter: PMHTTracker needs a linear motion model"):
        registry.get("tracker", "pmht").build(
            scenario=sc, where="trackers[0]", **registry.get("tracker", "pmht").resolve({"filter": {"type": "imm-cv"}}, "trackers[0]")
        )


# --------------------------------------------------------------------------
# [[claim]] verdicts
# --------------------------------------------------------------------------
def _gospa_pair(ratio: float, runs: int = 30, scans: int = 12, seed: int = 5) -> dict[str, np.ndarray]:
    """Per-scan GOSPA (K, M) of a baseline and of a tracker ``ratio`` times it, with per-run noise (fixed seed)."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(20.0, 60.0, (scans, runs))
    other = base * ratio * np.exp(rng.normal(0.0, 0.05, runs))  # a paired, run-level spread of 5 %
    return {"B": base, "T": other}


def _claim(**kw):
    return {"text": "", "baseline": "B", "tracker": "T", "scans": [], **kw}


@pytest.mark.parametrize("ratio, verdict", [(0.8, "holds"), (1.25, "reversed"), (1.0, "not significant")])
def test_claim_verdict_follows_the_paired_interval(ratio, verdict):
    g = _gospa_pair(ratio)
    t = claims_table([_claim()], g)
    row = dict(zip(t.columns, t.rows[0]))
    assert row["verdict"] == verdict
    # the numbers are the maneuver kind's paired log-ratio interval of the per-run mean GOSPA
    m, lo, hi = log_ratio_interval(g["B"].mean(axis=0), g["T"].mean(axis=0))
    assert (row["ratio"], row["ratio_lo95"], row["ratio_hi95"]) == pytest.approx((np.exp(m), np.exp(lo), np.exp(hi)), rel=1e-12)
    assert t.kind == "paper"


def test_claim_verdict_flips_when_the_judged_scans_do():
    """The tracker is better on scans 1-6 and worse on 7-12: the verdict follows the scans judged."""
    g = _gospa_pair(1.0)
    g["T"] = g["T"].copy()
    g["T"][:6] *= 0.7
    g["T"][6:] *= 1.4
    t = claims_table([_claim(scans=[1, 6]), _claim(scans=[7, 12]), _claim(baseline="T", tracker="B", scans=[1, 6])], g)
    assert [r[-1] for r in t.rows] == ["holds", "reversed", "reversed"]
    assert [r[1] for r in t.rows] == ["1-6", "7-12", "1-6"]


def test_a_run_with_zero_gospa_in_the_window_is_left_out_and_counted():
    """No target and no false track over the judged scans: GOSPA 0, no ratio; the table says so, no warning."""
    g = _gospa_pair(0.8)
    g["B"] = g["B"].copy()
    g["B"][:, 3] = 0.0
    t = claims_table([_claim()], g)
    row = dict(zip(t.columns, t.rows[0]))
    assert row["runs"] == 29 and row["verdict"] == "holds"
    keep = np.arange(30) != 3
    m, _, _ = log_ratio_interval(g["B"].mean(axis=0)[keep], g["T"].mean(axis=0)[keep])
    assert row["ratio"] == pytest.approx(np.exp(m), rel=1e-12)


CLAIMED = """
[experiment]
kind = "multitarget"
runs = 2
seed = 3

[scenario]
type = "mt-crossing"
steps = 8

[[trackers]]
name = "G"
type = "gnn"

[[trackers]]
name = "J"
type = "jpda"

[[claim]]
baseline = "G"
tracker = "J"
scans = [2, 8]
"""


@pytest.mark.parametrize(
    "edit, message",
    [
        (('tracker = "J"', 'tracker = "X"'), "claim[0].tracker: no tracker named 'X' (have G, J)"),
        (('baseline = "G"', 'baseline = "Y"'), "claim[0].baseline: no tracker named 'Y'"),
        (("scans = [2, 8]", "scans = [2, 9]"), "claim[0].scans: the scenario has 8 scans, got last = 9"),
        (("scans = [2, 8]", "scans = [5, 2]"), "claim[0].scans: first must not exceed last"),
        (("scans = [2, 8]", "scans = [0, 2]"), "claim[0].scans: expected [first, last]"),
        (("scans = [2, 8]", "scans = [2, 3, 4]"), "claim[0].scans: expected [first, last]"),
        (("scans = [2, 8]", 'steps = "all"'), "claim[0].steps: unknown key"),
        (('baseline = "G"\n', ""), "claim[0].baseline: required"),
    ],
)
def test_bad_claims_fail_naming_the_field(tmp_path, edit, message):
    path = tmp_path / "mt.toml"
    path.write_text(CLAIMED.replace(*edit, 1))
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert message in str(info.value)


def test_claims_table_comes_first_and_judges_the_experiments_numbers(tmp_path):
    path = tmp_path / "mt.toml"
    path.write_text(CLAIMED.replace("runs = 2", "runs = 6"))
    out = load_experiment(path).plan.run(runs=6, seed=3)
    claims, summary = out.tables[0], out.tables[1]
    assert claims.name == "claims" and summary.name == "summary"
    assert len(claims.rows) == 1 and claims.rows[0][-1] in ("holds", "reversed", "not significant")
    g = {n: out.results[f"gospa_{n}"] for n in ("G", "J")}
    m, lo, hi = log_ratio_interval(g["G"][1:8].mean(axis=0), g["J"][1:8].mean(axis=0))
    assert claims.rows[0][6] == pytest.approx(np.exp(m), rel=1e-12)


# --------------------------------------------------------------------------
# the experiment file
# --------------------------------------------------------------------------
def test_mt_maneuver_loads_and_runs_tiny():
    exp = load_experiment(ROOT / "experiments" / "mt-maneuver.toml")
    names = [t.name for t in exp.plan.trackers]
    assert names == ["GNN-EKF", "JPDA-EKF", "GNN-IMM", "JPDA-IMM", "PMHT", "EPMHT", "MM-PMHT", "MM-PMHT-CT"]
    assert exp.plan.trackers[7].turn_rates == (0.0, 0.05, -0.05, 0.0)
    assert isinstance(exp.plan.trackers[3].filter, InteractingMultipleModel)
    out = exp.plan.run(runs=2, seed=1)
    claims = out.tables[0]
    assert claims.name == "claims" and len(claims.rows) == 5
    assert {r[3] for r in claims.rows} == {"EPMHT", "JPDA-IMM", "MM-PMHT", "MM-PMHT-CT"}
    assert all(r[-1] in ("holds", "reversed", "not significant") for r in claims.rows)
    assert set(out.figures) == {"gospa", "scene"}


@pytest.mark.parametrize(
    "edit, message",
    [
        (("noise_scales = [1.0, 50.0]", "noise_scales = [1.0, -50.0]"), "trackers[1].noise_scales: expected a non-empty sequence of positive numbers"),
        (("noise_scales = [1.0, 50.0]", "noise_scales = []"), "trackers[1].noise_scales"),
        (("noise_scales = [1.0, 50.0]", 'noise_scales = "high"'), "trackers[1].noise_scales: expected a list of numbers"),
        (("stay = 0.9", "stay = 1.5"), "trackers[1].stay"),
    ],
)
def test_mmpmht_from_a_config_and_its_refusals(tmp_path, edit, message):
    text = CLAIMED.replace('name = "J"\ntype = "jpda"', 'name = "J"\ntype = "mmpmht"\nnoise_scales = [1.0, 50.0]\nstay = 0.9')
    path = tmp_path / "mt.toml"
    path.write_text(text)
    tr = load_experiment(path).plan.trackers[1]
    assert tr.noise_scales == (1.0, 50.0) and tr.stay == 0.9
    path.write_text(text.replace(*edit, 1))
    with pytest.raises(ConfigError) as info:
        load_experiment(path)
    assert message in str(info.value)


def test_imm_cv_default_modes_take_the_scenarios_q():
    sc = _scenario("cv-position")  # q = 0.01 there, not 1
    imm = build_filter({"type": "imm-cv"}, sc, "f")
    assert [f.motion.q for f in imm.filters] == [sc.motion.q] * 3
    assert [getattr(f.motion, "omega", 0.0) for f in imm.filters] == [0.0, 0.05, -0.05]
    # a turn needs the discrete white-noise acceleration of ConstantTurn: Williams' CV is continuous
    with pytest.raises(ValueError, match=r"f\.modes\[1\]\.omega: a turning mode has discrete white-noise acceleration only"):
        build_filter({"type": "imm-cv"}, _scenario("mt-williams"), "f")
