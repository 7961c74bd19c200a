"""The command line, end to end (in process and as a real subprocess)."""

import json
import re
import subprocess
import sys
import textwrap

import pytest

from pursuit.cli import main

from .test_config import GOOD


@pytest.fixture
def config(tmp_path):
    p = tmp_path / "exp.toml"
    p.write_text(GOOD)
    return p


def test_run_writes_table_csv_json_and_figures(tmp_path, config, capsys):
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "EKF" in printed and "UKF" in printed and "rmse_position" in printed
    assert (out / "summary.csv").read_text().startswith("filter,")
    side = json.loads((out / "run.json").read_text())
    assert side["seed"] == 1 and side["runs"] == 3
    assert side["config"]["scenario"]["type"] == "wsn-range"
    assert {"numpy", "scipy", "matplotlib", "pursuit", "python"} <= set(side["versions"])
    for fig in ("rmse_position", "rmse_velocity", "trajectory"):
        assert (out / "figures" / f"{fig}.png").stat().st_size > 1000
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]  # no temporary left behind


def test_overrides_and_pdf(tmp_path, config):
    out = tmp_path / "o"
    assert main(["run", str(config), "--out", str(out), "--runs", "2", "--seed", "9", "--pdf", "--no-progress"]) == 0
    side = json.loads((out / "run.json").read_text())
    assert side["runs"] == 2 and side["seed"] == 9
    assert (out / "figures" / "trajectory.pdf").exists()


@pytest.mark.parametrize(
    "args,msg",
    [
        (["--runs", "0"], "--runs: must be at least 1"),
        (["--seed", "-1"], "--seed: must be a non-negative integer"),
    ],
)
def test_bad_overrides_exit_2_and_write_nothing(tmp_path, config, capsys, args, msg):
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), *args]) == 2
    assert msg in capsys.readouterr().err
    assert not out.exists()


def test_bad_config_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text(GOOD.replace("sigma = 1.0", "sigma = -1.0"))
    out = tmp_path / "out"
    assert main(["run", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0] == f"pursuit: error: {p}:8: scenario.sigma: must be positive, got -1.0"
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [p]


def test_reproduce_by_name_and_unknown_name(tmp_path, capsys):
    assert main(["reproduce", "wsn-gaussian", "--runs", "2", "--out", str(tmp_path), "--no-progress"]) == 0
    assert (tmp_path / "wsn-gaussian" / "summary.csv").exists()
    assert main(["reproduce", "no-such-thing", "--out", str(tmp_path)]) == 2
    assert "no experiment named" in capsys.readouterr().err


def test_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for word in ("ekf", "ukf", "ckf", "kf", "wsn-range", "cv-position", "wsn-gaussian", "constant", "range-bearing"):
        assert word in out
    assert main(["list", "filters", "-v"]) == 0
    assert "alpha (float) = 1.0" in capsys.readouterr().out


def test_console_script_runs_as_a_subprocess(tmp_path, config):
    proc = subprocess.run(
        [sys.executable, "-m", "pursuit.cli", "run", str(config), "--out", str(tmp_path / "o"), "--runs", "2"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no progress bar when stderr is not a terminal
    bad = tmp_path / "bad.toml"
    bad.write_text(textwrap.dedent(GOOD).replace("[[filters]]", "[[filterz]]", 1))
    proc = subprocess.run([sys.executable, "-m", "pursuit.cli", "run", str(bad)], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert proc.returncode == 2
    assert "filterz: unknown section" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "value,extra,msg",
    [
        ("99", [], "figures.trajectory_run: run 99 does not exist with 3 runs (runs are numbered 0..2)"),
        ("-3", [], "figures.trajectory_run: must be a non-negative integer (runs are numbered from 0), got -3"),
        ("2", ["--runs", "2"], "figures.trajectory_run: run 2 does not exist with 2 runs (runs are numbered 0..1)"),
    ],
)
def test_impossible_trajectory_run_exits_2_at_its_line_and_writes_nothing(tmp_path, capsys, value, extra, msg):
    p = tmp_path / "exp.toml"
    p.write_text(GOOD + f"\n[figures]\ntrajectory_run = {value}\n")
    line = p.read_text().splitlines().index(f"trajectory_run = {value}") + 1
    out = tmp_path / "out"
    assert main(["run", str(p), "--out", str(out), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"pursuit: error: {p}:{line}: {msg}"]
    assert list(tmp_path.iterdir()) == [p]  # nothing written, not even a temporary folder


def test_trajectory_run_is_kept_whole_in_summary_mode(tmp_path):
    from pursuit.engine.backends import engine_options
    from pursuit.experiment import load_experiment

    p = tmp_path / "exp.toml"
    p.write_text(GOOD.replace("runs = 3", "runs = 6") + "\n[figures]\ntrajectory_run = 4\n")
    exp = load_experiment(p)
    with engine_options(store="summary", keep_runs=1):
        out = exp.run()
    result = out.result
    assert result.store == "summary" and result.stored().runs == 5  # runs 0..4 kept, not just 1
    assert "run 4" in out.figures["trajectory"].get_axes()[0].get_title()


def test_impossible_sweep_run_is_refused_at_load(tmp_path):
    from pursuit.experiment import ConfigError, load_experiment

    from .experiments.test_sweep import SMALL

    p = tmp_path / "sweep.toml"
    p.write_text(SMALL.replace("[figures]\n", "[figures]\nrun = 6\n"))
    with pytest.raises(ConfigError, match=r"sweep.toml:\d+: figures.run: run 6 does not exist with 6 runs"):
        load_experiment(p)
    p.write_text(SMALL.replace("[figures]\n", "[figures]\nrun = -1\n"))
    with pytest.raises(ConfigError, match=r"figures.run: must be a non-negative integer"):
        load_experiment(p)


def test_version_bare_command_and_python_dash_m(capsys):
    import pursuit

    for flag in ("--version", "-V"):
        with pytest.raises(SystemExit) as e:
            main([flag])
        assert e.value.code == 0
        assert capsys.readouterr().out.strip() == f"pursuit {pursuit.__version__}"
    assert main([]) == 0  # a bare `pursuit` lists the commands instead of complaining
    out = capsys.readouterr().out
    assert out.startswith("usage: pursuit") and all(c in out for c in ("list", "run", "reproduce", "report", "track"))
    done = subprocess.run([sys.executable, "-m", "pursuit", "--version"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == f"pursuit {pursuit.__version__}"


def test_a_track_model_given_to_run_and_an_experiment_given_to_track_say_which_command_they_belong_to(capsys):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    model, experiment = root / "examples" / "wsn-range.toml", root / "experiments" / "p2-toa.toml"
    assert main(["run", str(model)]) == 2
    assert f"this is a `pursuit track` model file, not an experiment: run it as pursuit track DATA --config {model}" in capsys.readouterr().err
    assert main(["track", str(root / "examples" / "data" / "wsn-range.csv"), "-c", str(experiment)]) == 2
    assert f"this is an experiment file, not a `pursuit track` model file: run it as pursuit run {experiment}" in capsys.readouterr().err


LONG = GOOD.replace("steps = 5", "steps = 100")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="lists processes through /proc")
@pytest.mark.parametrize(
    "sig, group, code, line",
    [
        ("SIGINT", True, 130, "pursuit: interrupted"),  # Ctrl-C in a terminal: the whole process group
        ("SIGTERM", False, 143, "pursuit: stopped by SIGTERM"),  # kill PID
        ("SIGHUP", False, 129, "pursuit: stopped by SIGHUP"),  # the terminal closed
    ],
)
def test_a_signal_ends_a_run_with_workers_cleanly(tmp_path, sig, group, code, line):
    """One line, exit 128 + signal, no traceback, no worker / forkserver / resource tracker left, no temp folder."""
    import os
    import signal
    import time

    from .engine.helpers import end_session, session_pids, wait_until

    if signal.getsignal(getattr(signal, sig)) is signal.SIG_IGN:
        # Under nohup the command inherits SIGHUP ignored and rightly keeps ignoring it (docs/cli.md).
        pytest.skip(f"{sig} is ignored in this process (nohup?), so the command ignores it too")
    config = tmp_path / "exp.toml"
    config.write_text(LONG)
    out = tmp_path / "out"
    err = tmp_path / "stderr.txt"
    # If the command hangs, SIGUSR1 makes it print every thread's stack into the failure message.
    diag = tmp_path / "diag"
    diag.mkdir()
    (diag / "sitecustomize.py").write_text("import faulthandler, signal\nfaulthandler.register(signal.SIGUSR1, all_threads=True)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(diag), os.environ.get("PYTHONPATH")])))
    with err.open("wb") as fh:  # a file, not a pipe: a leftover process holding it must not hang the test
        proc = subprocess.Popen(
            [sys.executable, "-m", "pursuit", "run", str(config), "--out", str(out / "exp"), "--runs", "200000",
             "--chunk-size", "500", "--workers", "2", "--no-progress"],
            stdout=subprocess.DEVNULL, stderr=fh, start_new_session=True, env=env,
        )
    try:
        # main, resource tracker, forkserver and 2 workers
        assert wait_until(lambda: len(session_pids(proc.pid)) >= 5, 120), err.read_text()
        (os.killpg if group else os.kill)(proc.pid, getattr(signal, sig))
        try:
            returned = proc.wait(30)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, signal.SIGUSR1)
            time.sleep(2)
            pytest.fail(f"pursuit did not end within 30 s of {sig}; its threads:\n{err.read_text()}")
        assert returned == code, err.read_text()
        assert wait_until(lambda: not session_pids(proc.pid), 20), f"still alive: {session_pids(proc.pid)}"
    finally:
        end_session(proc)
    assert err.read_text() == line + "\n"
    assert not out.exists() or list(out.iterdir()) == []


def test_workers_that_keep_dying_are_one_line_and_exit_3(tmp_path, config, capsys, monkeypatch):
    """Every worker dies (as when the system kills them): one warning line per restart, then one error line."""
    import dataclasses

    from pursuit.experiment import load_experiment

    from .engine.helpers import KillsItsWorker

    exp = load_experiment(config)
    exp = dataclasses.replace(exp, plan=dataclasses.replace(exp.plan, scenario=KillsItsWorker(exp.plan.scenario)))
    monkeypatch.setattr("pursuit.experiment.load_experiment", lambda path: exp)  # cli imports it when it runs
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--workers", "2", "--no-progress"]) == 3
    err = capsys.readouterr().err.splitlines()
    assert err == [
        *(f"pursuit: warning: a worker process died; computing 1 chunk(s) again (restart {i} of at most 3)" for i in (1, 2, 3)),
        "pursuit: error: local worker processes died 4 times (at most 3 restarts); 1 chunk(s) left uncomputed",
    ]
    assert not out.exists()


@pytest.mark.parametrize(
    "raised, code, line",
    [("KeyboardInterrupt", 130, "pursuit: interrupted"), ("SIGTERM", 143, "pursuit: stopped by SIGTERM")],
)
def test_a_signal_while_writing_is_one_line_and_leaves_no_temp_folder(tmp_path, config, capsys, monkeypatch, raised, code, line):
    """The signal arrives while the output folder is written: one line, 128 + signal, nothing left behind,
    and the signal handlers are the caller's again afterwards."""
    import signal

    from pursuit import cli
    from pursuit.report import html

    def interrupted(*a, **k):
        raise KeyboardInterrupt if raised == "KeyboardInterrupt" else cli.Terminated(signal.SIGTERM)

    monkeypatch.setattr(html, "write_report", interrupted)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out / "exp"), "--no-progress", "--no-pdf"]) == code
    assert capsys.readouterr().err == line + "\n"
    assert list(out.iterdir()) == []
    assert {s: signal.getsignal(s) for s in before} == before


def test_a_signal_ignored_at_start_stays_ignored(tmp_path, config, monkeypatch):
    """`nohup pursuit run ...` ignores SIGHUP: the command must not start reacting to it."""
    import signal

    from pursuit.report import html

    seen = {}
    real = html.write_report

    def spy(folder):
        seen.update({s: signal.getsignal(s) for s in (signal.SIGHUP, signal.SIGTERM)})
        return real(folder)

    monkeypatch.setattr(html, "write_report", spy)
    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        assert main(["run", str(config), "--out", str(tmp_path / "o"), "--no-progress", "--no-pdf"]) == 0
    finally:
        signal.signal(signal.SIGHUP, previous)
    assert seen[signal.SIGHUP] is signal.SIG_IGN
    assert seen[signal.SIGTERM] not in (signal.SIG_IGN, signal.SIG_DFL)  # handled while the command runs


@pytest.mark.parametrize(
    "args,env,msg",
    [
        (["--runs", "1000000000000"], {}, r"exp.toml:\d+: runs: 1000000000000 runs need about [\d.e+]+ TiB of memory"),
        (["--runs", "100000000", "--store", "full"], {"PURSUIT_MEMORY_LIMIT": "1G"}, r"exp.toml:\d+: runs: 100000000 "
         r"runs need about [\d.]+ GiB of memory to keep every run's arrays, 1.0 GiB available; use store summary "
         r"\(--store summary\) or at most about \d+ runs$"),
    ],
)
def test_what_cannot_fit_in_memory_is_one_line_and_exit_2(tmp_path, config, capsys, monkeypatch, args, env, msg):
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    out = tmp_path / "out"
    assert main(["run", str(config), "--out", str(out), "--no-progress", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pursuit: error: ")
    assert re.search(msg, err), err
    assert not out.exists()  # refused before anything ran or was written


def test_output_is_light_unless_full_data_is_asked_for(tmp_path):
    import csv

    p = tmp_path / "exp.toml"
    p.write_text(GOOD.replace("runs = 3", "runs = 6"))
    assert main(["run", str(p), "--no-progress", "--no-pdf", "--keep-runs", "2", "-o", str(tmp_path / "light")]) == 0
    assert main(["run", str(p), "--no-progress", "--no-pdf", "--keep-runs", "2", "--full-data", "-o", str(tmp_path / "full")]) == 0
    runs = {}
    for kind in ("light", "full"):
        with (tmp_path / kind / "errors.csv").open() as fh:
            runs[kind] = sorted({int(r["run"]) for r in csv.DictReader(fh)})
    assert runs == {"light": [0, 1], "full": [0, 1, 2, 3, 4, 5]}
    assert (tmp_path / "light" / "per_step.csv").read_bytes() == (tmp_path / "full" / "per_step.csv").read_bytes()


# --------------------------------------------------------------------------
# found in review
# --------------------------------------------------------------------------
def test_full_data_on_summary_results_says_what_was_saved(tmp_path, config):
    # --store summary keeps only the first runs whatever --full-data says: the folder must not claim "full"
    out = tmp_path / "sf"
    args = ["run", str(config), "--no-progress", "--no-pdf", "--store", "summary", "--keep-runs", "1", "--full-data", "-o", str(out)]
    assert main(args) == 0
    assert pursuit_load(out).sidecar["data"] == "light: per-step summaries of every run, runs 0..0 kept whole"
    none_kept = tmp_path / "none"
    assert main(["run", str(config), "--no-progress", "--no-pdf", "--keep-runs", "0", "-o", str(none_kept)]) == 0
    assert pursuit_load(none_kept).sidecar["data"] == "light: per-step summaries of every run, no run kept whole"


def test_a_bad_memory_limit_is_one_line_and_exit_2(config, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PURSUIT_MEMORY_LIMIT", "abc")
    assert main(["run", str(config), "--no-progress", "-o", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == "pursuit: error: $PURSUIT_MEMORY_LIMIT: expected a positive size such as 8G or 500M, got 'abc'\n"


def test_the_output_folder_may_be_the_working_directory(config, tmp_path, monkeypatch):
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    assert main(["run", str(config), "--no-progress", "--no-pdf", "-o", "."]) == 0  # was: ValueError, '.' has an empty name
    assert (here / "run.json").exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def pursuit_load(folder):
    import pursuit

    return pursuit.load(folder)
