"""The fuzz oracles against the examples docs/track.md gives, and the TOML writer round trip."""

from __future__ import annotations

import math
import tomllib

import pytest

from .config_cases import EXPERIMENTS
from .tomlgen import dumps
from .track_cases import csv_line_oracle, jsonl_line_oracle


@pytest.mark.parametrize("line", ["6.0,A1,inf", "11.0,A5,1.0", "17.0,A1", "25.0,A1,100.8.938", "1.0,A1,４１.5", "1.0,A1,1_000",
                                  "1.0,A1,0x10", "1.0,A1,1e999", "0.0,A1,1.0", "1.0,A1,2e9", "1.0,A1,1.0,2.0"])
def test_csv_lines_the_docs_call_bad(line):
    assert csv_line_oracle(line) == "bad"


def test_csv_lines_the_docs_read():
    assert csv_line_oracle("1.0,A1,41.53052761423319") == (1.0, "A1", (41.53052761423319,))
    t, s, (v,) = csv_line_oracle("2.5,A2,")
    assert (t, s) == (2.5, "A2") and math.isnan(v)
    assert csv_line_oracle("# a comment") is None and csv_line_oracle("") is None


@pytest.mark.parametrize(
    "line",
    [
        '{"time": 1.0, "sensor": "A1", "value": 1.0, "time": 2.0}',
        '{"time": 1.0, "sensor": "A1", "value": Infinity}',
        '{"time": 1.0, "sensor": "A1", "value": ４１.5}',
        '{"time": 1.0, "sensor": "A1", "value": 1.0, "note": 1}',
        '{"sensor": "A1", "value": 1.0}',
        '{"time": 1.0, "sensor": "A1", "value": [1.0, 2.0]}',
        "[1.0]",
    ],
)
def test_jsonl_lines_the_docs_call_bad(line):
    assert jsonl_line_oracle(line) == "bad"


def test_jsonl_lines_the_docs_read():
    assert jsonl_line_oracle('{"time": 7.0}') == ("predict", 7.0)
    assert jsonl_line_oracle('{"time": 2.0, "sensor": "A1", "values": [12.5]}') == (2.0, "A1", (12.5,))
    assert math.isnan(jsonl_line_oracle('{"time": 2.0, "sensor": "A1", "value": null}')[2][0])


@pytest.mark.parametrize("path", sorted(EXPERIMENTS.glob("*.toml")), ids=lambda p: p.stem)
def test_the_toml_writer_round_trips_every_experiment(path):
    doc = tomllib.loads(path.read_text())
    text, where = dumps(doc)
    assert tomllib.loads(text) == doc
    assert text.splitlines()[where[("experiment", "runs")] - 1].startswith("runs = ")
