"""The multitarget experiment kind, the mt-* scenario and tracker registrations, mt-crossing and mt-williams."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from pursuit import registry
from pursuit.cli import main
from pursuit.experiment import ConfigError, load_experiment
from pursuit.experiments.multitarget import score
from pursuit.multitarget import GNNTracker, JPDATracker, gospa, track_scans
from pursuit.rng import run_streams
from pursuit.scenarios.multitarget import crossing

BASE = """
[experiment]
kind = "multitarget"
runs = 4
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

[metrics]
c = 5.0
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "mt.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_mt_crossing_reproduces_with_table_and_figures(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["reproduce", "mt-crossing", "--runs", "5", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "GNN-KF" in printed and "JPDA-KF" in printed and "gospa" in printed
    folder = out / "mt-crossing"
    with (folder / "summary.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r["tracker"] for r in rows] == ["GNN-KF", "JPDA-KF", "PMHT", "EPMHT", "GM-PHD"]
    # the EM trackers report their iterations per window, within max_iter; the others leave it empty
    em = {r["tracker"]: r["em_iterations"] for r in rows}
    assert em["GNN-KF"] == em["GM-PHD"] == ""
    assert 1 <= float(em["PMHT"]) <= 20 and 1 <= float(em["EPMHT"]) <= 20
    for r in rows:
        # GOSPA with c = 5, p = 2, alpha = 2 is at most c * sqrt(n / 2) for n objects (here 2 truths and a few tracks)
        assert 0 < float(r["gospa"]) < 5 * np.sqrt(8)
        # the parts are in units of distance^2: their sum is the mean of GOSPA^2, at least (mean GOSPA)^2 (Jensen)
        parts = float(r["localisation"]) + float(r["missed"]) + float(r["false"])
        assert parts >= float(r["gospa"]) ** 2 - 1e-9
    for fig in ("gospa", "scene"):
        assert (folder / "figures" / f"{fig}.png").exists(), fig
    assert (folder / "results" / "gospa_GNN-KF.npy").exists()


def test_the_table_is_what_the_library_computes(tmp_path):
    """The experiment's numbers equal calling the scenario, the trackers and the metrics by hand."""
    plan = load_experiment(_write(tmp_path, BASE))
    out = plan.plan.run(runs=4, seed=3)
    sc = crossing(steps=8)
    truth, scans = sc.simulate(run_streams(3, range(4), 0), 4)
    table = {row[0]: dict(zip(out.tables[0].columns, row)) for row in out.tables[0].rows}
    for cls, name in ((GNNTracker, "G"), (JPDATracker, "J")):
        from pursuit.filters import KalmanFilter

        tracker = cls(KalmanFilter(sc.motion, sc.measurement), sc.p_detect, sc.clutter_density, max_speed=sc.max_speed)
        res = track_scans(tracker, scans.z, times=scans.times)
        est, mask = res.positions(sc.position_indices)
        g = gospa(truth.positions(sc.position_indices), truth.exists, est, mask, 5.0)
        assert table[name]["gospa"] == pytest.approx(float(g.total.mean()), rel=1e-12)
        s = score(name, res, truth, sc.position_indices, {"c": 5.0, "p": 2.0, "alpha": 2.0}, 1.0)
        assert table[name]["switches"] == pytest.approx(float(s.switches.mean()))


def test_same_seed_same_table(tmp_path):
    plan = load_experiment(_write(tmp_path, BASE)).plan
    a, b = plan.run(runs=3, seed=9).tables[0], plan.run(runs=3, seed=9).tables[0]
    keep = [i for i, c in enumerate(a.columns) if c not in ("wall_time_s", "scans_per_s")]
    assert [[r[i] for i in keep] for r in a.rows] == [[r[i] for i in keep] for r in b.rows]


@pytest.mark.parametrize(
    "edit, message",
    [
        (('type = "mt-crossing"', 'type = "cv-position"'), "scenario.type: the multitarget kind needs a multi-target scenario"),
        (('type = "gnn"', 'type = "mht"'), "trackers[0].type: unknown tracker 'mht'"),
        (('name = "J"', 'name = "G"'), "trackers[1].name: 'G' is used twice"),
        (("c = 5.0", "c = -1.0"), "metrics.c: must be positive"),
        (("c = 5.0", "c = 5.0\nalpha = 3.0"), "metrics.alpha: must lie in (0, 2]"),
        (('type = "jpda"', 'type = "jpda"\nconfirm = [3, 2]'), "trackers[1].confirm: M must not exceed N"),
        (('type = "jpda"', 'type = "jpda"\np_detect = 1.5'), "trackers[1].p_detect: must lie in (0, 1]"),
        (('type = "gnn"', 'type = "gnn"\nfilter = {type = "pf"}'), "trackers[0].filter"),
        (("steps = 8", "steps = 8\nclutter_rate = -2.0"), "scenario.clutter_rate"),
        (("[metrics]", "[filters]"), "filters: unknown section"),
        (('type = "jpda"', 'type = "gmphd"\nbirth = "fixed"'), "trackers[1].birth: must be one of"),
        (('type = "jpda"', 'type = "pmht"\nbatch = 0'), "trackers[1].batch"),
        (('type = "jpda"', 'type = "epmht"\nstay = 1.5'), "trackers[1].stay"),
    ],
)
def test_bad_configs_fail_naming_the_field(tmp_path, edit, message):
    with pytest.raises(ConfigError) as info:
        load_experiment(_write(tmp_path, BASE.replace(*edit, 1)))
    assert message in str(info.value)


def test_a_single_target_kind_refuses_a_multi_target_scenario(tmp_path):
    text = '[experiment]\nruns = 2\n[scenario]\ntype = "mt-williams"\n[[filters]]\ntype = "kf"\n'
    with pytest.raises(ConfigError) as info:
        load_experiment(_write(tmp_path, text))
    assert "scenario.type: 'mt-williams' is a multi-target scenario" in str(info.value)


def test_trackers_are_listed():
    names = {c.name for c in registry.components("tracker")}
    assert {"gnn", "jpda"} <= names
    scen = {c.name for c in registry.components("scenario")}
    assert {"mt-crossing", "mt-williams", "mt-maneuvering"} <= scen


def test_mt_maneuvering_runs_with_an_ekf_per_track(tmp_path):
    text = BASE.replace('type = "mt-crossing"\nsteps = 8', 'type = "mt-maneuvering"').replace(
        'type = "gnn"', 'type = "gnn"\nfilter = {type = "ekf"}'
    ).replace('type = "jpda"', 'type = "jpda"\nfilter = {type = "ekf"}').replace("c = 5.0", "c = 500.0")
    out = load_experiment(_write(tmp_path, text)).plan.run(runs=2, seed=1)
    rows = out.tables[0].rows
    assert len(rows) == 2 and all(np.isfinite(r[1]) for r in rows)
