"""Recorded and live measurements in, estimates out: the engine behind ``pursuit track``.

* :mod:`~pursuit.io.model`: MODEL.toml (motion model, sensors, prior, filter);
* :mod:`~pursuit.io.input_spec`: the model file's ``[input]`` section (CSV
  column names, the origin of ISO 8601 times, the largest believable gap);
* :mod:`~pursuit.io.records`: CSV and JSON Lines readers that turn every bad
  record into a message with its line and field, never an exception;
* :mod:`~pursuit.io.steps`: records grouped into filter steps by time, and
  the out-of-order policy;
* :mod:`~pursuit.io.tracker`: the filter advanced step by step with dt from
  the time column, refusing steps that would break it;
* :mod:`~pursuit.io.writers`: estimates as CSV or JSON Lines;
* :mod:`~pursuit.io.command`: the ``pursuit track`` subcommand;
* :mod:`~pursuit.io.detections`, :mod:`~pursuit.io.multi_model`,
  :mod:`~pursuit.io.multi_writers`, :mod:`~pursuit.io.multi`: ``pursuit track
  --multi`` (detection files, the ``[tracker]`` model file, track rows, the
  command).

Example
-------
>>> from pursuit.io import load_track_model, read_records, track_records
>>> model = load_track_model("examples/wsn-range.toml")              # doctest: +SKIP
>>> with open("examples/data/wsn-range.csv", "rb") as f:           # doctest: +SKIP
...     result = track_records(read_records(f, "csv"), model)
>>> result.estimates[-1].mean                                        # doctest: +SKIP
"""

from .model import Sensor, TrackModel, build_track_model, load_track_model
from .multi_model import MultiTrackModel, build_multi_model, load_multi_model
from .records import BadRecord, Record, check_record, read_csv, read_jsonl, read_records
from .steps import Dropped, Step, assemble_steps
from .tracker import Estimate, StepRefused, Tracker, TrackResult, stream_records, track_records
from .writers import make_writer

__all__ = [
    "Sensor",
    "TrackModel",
    "build_track_model",
    "load_track_model",
    "MultiTrackModel",
    "build_multi_model",
    "load_multi_model",
    "Record",
    "BadRecord",
    "check_record",
    "read_csv",
    "read_jsonl",
    "read_records",
    "Step",
    "Dropped",
    "assemble_steps",
    "Estimate",
    "Tracker",
    "StepRefused",
    "TrackResult",
    "track_records",
    "stream_records",
    "make_writer",
]
