"""CLI: --workers, --scheduler checks, pursuit report, reproduce all with its index."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import pursuit
from pursuit.cli import main
from pursuit.experiment import list_experiments

EXPERIMENT = Path(__file__).resolve().parents[1] / "experiments" / "wsn-gaussian.toml"


def _run(tmp_path, name, *extra):
    out = tmp_path / name
    assert main(["run", str(EXPERIMENT), "--runs", "8", "--chunk-size", "3", "--no-progress", "--no-pdf", "-o", str(out), *extra]) == 0
    return out


def test_workers_give_the_serial_files(tmp_path):
    serial = _run(tmp_path, "serial")
    two = _run(tmp_path, "two", "--workers", "2")
    summ = _run(tmp_path, "summ", "--workers", "2", "--store", "summary", "--keep-runs", "2")
    for name in ("per_step.csv",):
        assert (serial / name).read_text() == (two / name).read_text() == (summ / name).read_text()
    drop_wall = lambda t: [r[:-2] for r in t["rows"]]  # noqa: E731  (wall time, runs columns last)
    tables = [json.loads((d / "run.json").read_text())["tables"]["summary"] for d in (serial, two, summ)]
    assert drop_wall(tables[0]) == drop_wall(tables[1]) == drop_wall(tables[2])
    assert json.loads((two / "run.json").read_text())["engine"]["backend"] == {"backend": "processes", "workers": 2}
    assert pursuit.load(summ).result.store == "summary"
    assert (serial / "errors.csv").read_text() == (two / "errors.csv").read_text()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--workers", "0"], "--workers: must be at least 1"),
        (["--scheduler", "127.0.0.1:8786"], "tcp://HOST:PORT"),
        (["--keep-runs", "-1"], "--keep-runs"),
    ],
)
def test_bad_engine_arguments_exit_2(tmp_path, capsys, args, message):
    assert main(["run", str(EXPERIMENT), "--runs", "2", "-o", str(tmp_path / "x"), *args]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_workers_and_scheduler_exclude_each_other(tmp_path):
    with pytest.raises(SystemExit):
        main(["run", str(EXPERIMENT), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"])


def test_report_rebuilds_from_saved_results(tmp_path, capsys):
    out = _run(tmp_path, "one")
    original = (out / "report.html").read_text()
    (out / "report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert (out / "report.html").read_text() == original


def test_report_errors(tmp_path, capsys):
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "no such folder" in capsys.readouterr().err
    assert main(["report", str(tmp_path)]) == 2
    assert "not a pursuit output folder" in capsys.readouterr().err


@pytest.mark.slow
def test_reproduce_all_writes_an_index(tmp_path, capsys):
    root = tmp_path / "results"
    assert main(["reproduce", "all", "--runs", "2", "--no-progress", "--no-pdf", "-o", str(root)]) == 0
    names = list_experiments()
    index = (root / "index.html").read_text()
    for name in names:
        assert f'href="{name}/report.html"' in index
        assert (root / name / "report.html").is_file()
    (root / "index.html").unlink()
    assert main(["report", str(root)]) == 0
    assert (root / "index.html").read_text() == index


def test_workers_auto_and_bad_words(tmp_path, capsys):
    out = _run(tmp_path, "auto", "--workers", "auto")
    assert json.loads((out / "run.json").read_text())["engine"]["backend"]["workers"] >= 1
    with pytest.raises(SystemExit) as e:
        main(["run", str(EXPERIMENT), "--workers", "many", "-o", str(tmp_path / "x")])
    assert e.value.code == 2
    assert "argument --workers: expected a whole number or 'auto', got 'many'" in capsys.readouterr().err


def _comparable(folder: Path) -> dict[str, list[list[str]]]:
    """Every CSV of an output folder, less the columns that are timings."""
    out = {}
    for path in sorted(folder.glob("*.csv")):
        rows = [line.split(",") for line in path.read_text().splitlines()]
        keep = [j for j, name in enumerate(rows[0]) if "wall" not in name and "per_s" not in name]
        out[path.name] = [[r[j] for j in keep if j < len(r)] for r in rows]
    return out


def _no_wall_times(meta: np.ndarray) -> dict:
    doc = json.loads(str(meta))
    for f in doc.get("filters", []):
        f.pop("wall_time", None)
    return doc


def test_reproduce_side_by_side_writes_the_serial_files(tmp_path, capsys):
    from pursuit import cli
    from pursuit.experiment import find_experiment, load_experiment

    names = ["wsn-gaussian", "p4-maneuver"]
    for name in names:
        assert main(["reproduce", name, "--runs", "3", "--no-progress", "--no-pdf", "-o", str(tmp_path / "serial")]) == 0
    exps = [load_experiment(find_experiment(n)) for n in names]
    args = cli._parser().parse_args(["reproduce", "all", "--runs", "3", "--no-pdf", "--workers", "2"])
    args.argv = ["reproduce", "all"]
    capsys.readouterr()
    cli._reproduce_side_by_side(exps, tmp_path / "side", args)
    printed = capsys.readouterr().out
    for name in names:
        assert f"== {name}:" in printed
        serial, side = tmp_path / "serial" / name, tmp_path / "side" / name
        assert _comparable(serial) and _comparable(serial) == _comparable(side)
        for npz in (serial / "results").glob("*.npz"):
            a, b = np.load(npz), np.load(side / "results" / npz.name)
            assert a.files == b.files
            for key in a.files:  # the same bits, but the filters' wall times in meta
                if key == "meta":
                    assert _no_wall_times(a[key]) == _no_wall_times(b[key])
                else:
                    assert a[key].dtype == b[key].dtype and a[key].tobytes() == b[key].tobytes()
        engine = json.loads((side / "run.json").read_text())["engine"]
        assert engine["backend"] == {"backend": "serial", "workers": 1} and engine["experiments_side_by_side"] == 2
