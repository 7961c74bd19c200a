"""The progress bar: what it is labelled with, and when it draws."""

import io
import itertools
import re
import sys
import types

import pytest

import pursuit.engine.progress as progress_mod
from pursuit.cli import main
from pursuit.engine import monte_carlo

from ..test_config import GOOD
from .helpers import SMALL, small_filters


class FakeTerminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture
def term(monkeypatch):
    """The bar's standard error as a terminal; every redraw passes the ten-a-second throttle.

    (pytest's capture sets sys.stderr again after fixtures, so the progress module's view is patched.)
    """
    t = FakeTerminal()
    monkeypatch.setattr(progress_mod, "sys", types.SimpleNamespace(stderr=t))
    clock = itertools.count()
    monkeypatch.setattr(progress_mod.time, "monotonic", lambda: float(next(clock)))
    return t


def _labels(text: str) -> list[str]:
    return [m.strip() for m in re.findall(r"\r(.*?) \[", text)]


def test_in_process_the_bar_names_the_label_and_the_filter_running(term):
    monte_carlo(SMALL, small_filters(), 4, 1, chunk_size=2, progress=True, label="demo N=30")
    labels = _labels(term.getvalue())
    assert labels[0] == "demo N=30 EKF"
    assert {"demo N=30 EKF", "demo N=30 CKF"} <= set(labels)  # each filter named while it runs
    assert labels[-1] == "demo N=30"  # done
    assert all(lbl.startswith("demo N=30") for lbl in labels)


def test_without_a_label_the_bar_shows_the_scenario(term):
    monte_carlo(SMALL, small_filters()[:1], 2, 1, progress=True)
    assert _labels(term.getvalue())[-1] == SMALL.name


SWEEP = """
[experiment]
name = "tiny"
kind = "sweep"
runs = 2

[scenario]
type = "ungm"
steps = 5

[[filters]]
type = "pf"
name = "PF"

[[filters]]
type = "ekf"

[sweep]
parameter = "particles"
label = "N"
values = [20, 40]
"""


def test_a_sweep_labels_bars_by_experiment_value_and_filter(tmp_path, term):
    from pursuit.experiment import load_experiment

    p = tmp_path / "tiny.toml"
    p.write_text(SWEEP)
    load_experiment(p).run(progress=True)
    labels = set(_labels(term.getvalue()))
    # every bar of `reproduce p1-ungm` was labelled `ungm`
    assert {"tiny N=20 PF", "tiny N=20 EKF", "tiny N=40 PF", "tiny N=20", "tiny N=40"} <= labels, labels


def test_the_cli_prints_an_experiments_header_before_its_bars(tmp_path, term, monkeypatch):
    monkeypatch.setattr(sys, "stdout", term)  # one stream, so the order is what a terminal shows
    p = tmp_path / "exp.toml"
    p.write_text(GOOD)
    assert main(["run", str(p), "--out", str(tmp_path / "out"), "--no-pdf"]) == 0
    text = term.getvalue()
    header, bar = text.index("== exp: "), text.index("\r")
    assert header < bar, text[:300]
