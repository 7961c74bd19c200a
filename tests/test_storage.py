"""Results on disk: exact round trips, the tidy tables, pursuit.load."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import pursuit
from pursuit.engine import monte_carlo
from pursuit.report.output import write_output
from pursuit.storage import load_result, save_result, write_errors_csv, write_per_step_csv
from pursuit.tables import ExperimentOutput, Table

from .engine.helpers import SMALL, assert_same_result, small_filters

RUNS, SEED = 9, 4


@pytest.fixture(scope="module")
def full():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED, config={"note": "x"})


@pytest.fixture(scope="module")
def summary():
    return monte_carlo(SMALL, small_filters(), RUNS, SEED, store="summary", keep_runs=2, chunk_size=4)


@pytest.mark.parametrize("which", ["full", "summary"])
def test_result_round_trip_is_exact(which, full, summary, tmp_path):
    result = {"full": full, "summary": summary}[which]
    back = load_result(save_result(result, tmp_path / "r.npz"))
    assert back.store == which and back.runs == RUNS
    assert_same_result(result, back)
    assert [r["wall_time_s"] for r in back.summary()] == [r["wall_time_s"] for r in result.summary()]
    if which == "summary":
        assert_same_result(result.stored(), back.stored())


def test_load_result_rejects_other_files(tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(ValueError, match="not a pursuit result"):
        load_result(bad)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="junk.npz"):
        load_result(tmp_path / "junk.npz")


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_errors_csv_is_tidy_and_exact(full, tmp_path):
    n = write_errors_csv(tmp_path / "e.csv", "exp", {"result": full})
    rows = _rows(tmp_path / "e.csv")
    assert n == len(rows) == len(full.filters) * RUNS * full.steps
    assert list(rows[0])[:6] == ["experiment", "result", "filter", "run", "step", "time"]
    for row in rows[:: 37]:
        f, run, step = row["filter"], int(row["run"]), int(row["step"])
        e = full.filters[f].estimates[step - 1, run] - full.truth[step - 1, run]
        assert float(row["err_x"]) == e[0] and float(row["err_vy"]) == e[3]
        assert float(row["err_position"]) == np.sqrt(e[0] ** 2 + e[2] ** 2)
        assert float(row["nees"]) == full.nees(f)[step - 1, run]
        assert float(row["nis"]) == full.filters[f].info["nis"][step - 1, run]


def test_errors_csv_of_a_summary_lists_only_kept_runs(summary, tmp_path):
    write_errors_csv(tmp_path / "e.csv", "exp", {"result": summary})
    runs = {int(r["run"]) for r in _rows(tmp_path / "e.csv")}
    assert runs == {0, 1}


def test_per_step_csv_equals_the_summaries(full, summary, tmp_path):
    write_per_step_csv(tmp_path / "a.csv", "exp", {"result": full})
    write_per_step_csv(tmp_path / "b.csv", "exp", {"result": summary})
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
    rows = [r for r in _rows(tmp_path / "a.csv") if r["filter"] == "EKF"]
    assert [float(r["rmse_position"]) for r in rows] == full.rmse_per_step("EKF").tolist()
    assert [float(r["anis"]) for r in rows] == full.anis("EKF").tolist()


def _output(result) -> ExperimentOutput:
    from pursuit.experiments.montecarlo import standard_figures, summary_table

    return ExperimentOutput(
        "demo", "Demo", "A demo.", [summary_table(result)], standard_figures(result, SMALL, {}), results={"result": result}
    )


def test_load_gives_back_the_result_object(full, tmp_path):
    out = write_output(_output(full), tmp_path / "demo")
    loaded = pursuit.load(out)
    assert loaded.name == "demo" and loaded.title == "Demo"
    assert_same_result(full, loaded.result)
    assert loaded.tables[0].rows == _output(full).tables[0].rows
    assert all(p.is_file() for p in loaded.figures.values())
    assert {p.suffix for p in (out / "figures").iterdir()} == {".png", ".pdf"}
    for name in ("summary.csv", "errors.csv", "per_step.csv", "run.json", "report.html", "results/result.npz"):
        assert (out / name).is_file(), name


def test_load_handles_several_and_other_results(full, tmp_path):
    out = _output(full)
    out.results = {"a b": full, "curve": np.arange(3.0), "meta": {"k": [1, 2]}, "obj": object()}
    folder = write_output(out, tmp_path / "multi")
    loaded = pursuit.load(folder)
    assert set(loaded.results) == {"a b", "curve", "meta"}
    assert np.array_equal(loaded.results["curve"], np.arange(3.0))
    assert loaded.results["meta"] == {"k": [1, 2]}
    assert loaded.sidecar["results"]["obj"]["file"] is None
    with pytest.raises(ValueError, match="3 results"):
        loaded.result


def test_load_errors_name_the_problem(full, tmp_path):
    with pytest.raises(ValueError, match="no run.json"):
        pursuit.load(tmp_path)
    folder = write_output(_output(full), tmp_path / "demo")
    (folder / "results" / "result.npz").unlink()
    with pytest.raises(ValueError, match="result.npz: listed in run.json but missing"):
        pursuit.load(folder)


def test_write_output_is_all_or_nothing(full, tmp_path):
    class Broken:
        def savefig(self, *a, **k):
            raise RuntimeError("disk full")

    out = _output(full)
    out.figures = {"bad": Broken()}
    with pytest.raises(RuntimeError, match="disk full"):
        write_output(out, tmp_path / "x")
    assert list(tmp_path.iterdir()) == []


def test_paper_tables_keep_their_kind(full, tmp_path):
    out = _output(full)
    out.tables.append(Table("paper_vs_measured", "P", ["filter", "paper", "measured"], [["EKF", 1.0, 0.9]], "n", "paper"))
    loaded = pursuit.load(write_output(out, tmp_path / "p"))
    assert [t.kind for t in loaded.tables] == ["result", "paper"]
    assert loaded.tables[1].notes == "n"


_KILLED_WRITER = r"""
import os, sys, time
from pursuit.report.output import write_output
from pursuit.tables import ExperimentOutput, Table

class Blocks:
    def savefig(self, path, **kw):
        open(sys.argv[2], "w").write(str(os.getpid()))
        time.sleep(120)  # the test SIGKILLs this process meanwhile

out = ExperimentOutput("demo", "Demo", "", [Table("summary", "S", ["a"], [[1.0]])], {"f": Blocks()})
write_output(out, sys.argv[1], formats=("png",))
"""


def test_a_killed_writers_temp_folder_is_removed_by_the_next_write(tmp_path):
    """SIGKILL a process in the middle of write_output: the next write of that folder removes its temp folder."""
    import os
    import signal
    import subprocess
    import sys
    import time

    marker = tmp_path / "writing.pid"
    root = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(pursuit.__file__).parents[1]), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(root / "demo"), str(marker)], env=env)
    try:
        deadline = time.monotonic() + 120  # a loaded machine may take a while to import
        while not (marker.exists() and marker.read_text()):
            assert proc.poll() is None and time.monotonic() < deadline, "the writer did not reach its figures"
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    left = [p.name for p in root.iterdir()]
    assert len(left) == 1 and left[0].startswith(".demo.")  # what the killed writer left
    out = ExperimentOutput("demo", "Demo", "", [Table("summary", "S", ["a"], [[2.0]])], {})
    write_output(out, root / "demo", formats=("png",))
    assert [p.name for p in root.iterdir()] == ["demo"]


@pytest.mark.parametrize("atomic", [True, False], ids=["exchange", "two-renames"])
def test_write_output_interrupted_between_the_renames_keeps_an_output(tmp_path, monkeypatch, atomic):
    """Ctrl-C at the moment the new folder is moved in: DIR is still there, old or new, and nothing else is."""
    from pursuit import output_folder

    if not atomic:
        monkeypatch.setattr(output_folder, "_exchange", lambda a, b: False)
    first = ExperimentOutput("demo", "Demo", "", [Table("summary", "S", ["a"], [[1.0]])], {})
    second = ExperimentOutput("demo", "Demo", "", [Table("summary", "S", ["a"], [[2.0]])], {})
    target = write_output(first, tmp_path / "demo", formats=("png",))
    real = Path.rename

    def rename(self, dest):
        if Path(dest) == target and self.name.startswith(".demo.") and "old" not in self.name:
            raise KeyboardInterrupt  # the new folder moved in (moving the old one back is allowed)
        return real(self, dest)

    monkeypatch.setattr(Path, "rename", rename)
    try:
        write_output(second, target, formats=("png",))
    except KeyboardInterrupt:
        pass
    assert [p.name for p in tmp_path.iterdir()] == ["demo"]
    assert pursuit.load(target).tables[0].rows in ([[1.0]], [[2.0]])


def test_output_is_light_by_default_and_full_one_option_away(full, tmp_path):
    light = write_output(_output(full), tmp_path / "light", keep_runs=3, formats=("png",))
    heavy = write_output(_output(full), tmp_path / "heavy", keep_runs=3, formats=("png",), full_data=True)
    runs_in = lambda folder: sorted({int(r["run"]) for r in _rows(folder / "errors.csv")})  # noqa: E731
    assert runs_in(light) == [0, 1, 2] and runs_in(heavy) == list(range(RUNS))
    # every run still counts in the per-step summaries: the same bytes either way
    assert (light / "per_step.csv").read_bytes() == (heavy / "per_step.csv").read_bytes()
    assert (light / "summary.csv").read_bytes() == (heavy / "summary.csv").read_bytes()
    back = pursuit.load(light).result
    assert back.store == "summary" and back.runs == RUNS and back.stored().runs == 3
    assert back.summary() == full.summary()
    assert_same_result(full.summarised(3).stored(), back.stored())
    assert pursuit.load(heavy).result.store == "full"
    size = lambda folder: sum(p.stat().st_size for p in folder.rglob("*") if p.suffix in (".csv", ".npz"))  # noqa: E731
    assert size(light) < 0.6 * size(heavy)
    assert "light" in pursuit.load(light).sidecar["data"] and pursuit.load(heavy).sidecar["data"] == "full"
    assert "saved data" in (light / "report.html").read_text()


def test_every_csv_is_written_by_the_one_writer(tmp_path):
    import re

    import pursuit
    from pursuit.tables import write_csv

    src = Path(pursuit.__file__).parent
    writers = sorted(
        p.relative_to(src).as_posix() for p in src.rglob("*.py") if re.search(r"csv\.(writer|DictWriter)\(", p.read_text(encoding="utf-8"))
    )
    assert writers == ["tables.py"]
    # floats as their shortest round-tripping text whatever their type, None as empty, the rest as is
    n = write_csv(tmp_path / "t.csv", ["a", "b", "c"], iter([[0.1, np.float64(1 / 3), None], [1, "x,y", True]]))
    assert n == 2
    assert (tmp_path / "t.csv").read_bytes().decode() == 'a,b,c\r\n0.1,0.3333333333333333,\r\n1,"x,y",True\r\n'
