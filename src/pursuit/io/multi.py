"""``pursuit track --multi DETECTIONS --config MODEL.toml``: multi-target tracking of recorded detections.

The detections (CSV or JSON Lines, :mod:`pursuit.io.detections`: time,
optional sensor, the sensor's value columns, no target label) are tracked by
the ``[tracker]`` of the model file (:mod:`pursuit.io.multi_model`), and the
confirmed tracks written one row per track per scan
(:mod:`pursuit.io.multi_writers`).  The conventions of ``pursuit track``:

* **batch** (a file, the default): every record is read and checked first,
  then :func:`pursuit.multitarget.track_scans` runs once over all scans
  (M = 1 run).  A bad record stops the command with exit code 2 and *nothing*
  is written; the output appears whole or not at all
  (:func:`pursuit.io.output_file.write_whole`).
* **stream** (``-`` for standard input, or ``--stream``): scans are tracked
  as they complete (a scan is complete when a record with a later time
  arrives, or the input ends) by :func:`pursuit.multitarget.track_stream`,
  in memory that does not grow with the input, and each scan's rows are
  written and flushed at once.  The output file is created with the first
  scan's rows: a bad record before that leaves no file; one after it stops
  the command with exit code 2, keeping the rows of the scans before it.
  Stream and batch write the same bytes.

Times must not decrease (default ``--out-of-order error``: a detection file
out of time order more likely has a broken clock or was put together wrongly
than late records; ``sort`` and ``drop`` as for ``pursuit track``).

Exit codes: 0 success (also when no track was confirmed: a note on standard
error says so), 2 bad input (model file, detections, arguments, an output
that cannot be written), 130 interrupted.
"""

from __future__ import annotations

import argparse
import io
import sys
from typing import BinaryIO, Iterable, Iterator, TextIO

import numpy as np

from ..multitarget.detections import pad_scans
from ..multitarget.tracking import track_scans, track_stream
from .command import (
    EXIT_BAD_INPUT,
    EXIT_INTERRUPTED,
    EXIT_OK,
    _GuardedOutput,
    _header_failed,
    _OutputFailed,
    _report,
    _settings,
    _silence,
    _Usage,
)
from .detections import DetectionScan, group_scans, read_detection_records
from .multi_model import MultiTrackModel, load_multi_model
from .multi_writers import TrackRowWriter, scan_rows
from .output_file import same_file, same_file_as_stream, write_whole
from .records import BadRecord, Record
from .steps import Dropped, sort_records

__all__ = ["run_track_multi", "detection_events"]

_NAME = "pursuit track --multi"


class _StopAtBad(Exception):
    """A bad record in a stream without --skip-bad."""

    def __init__(self, item: BadRecord):
        super().__init__(str(item))
        self.item = item


def detection_events(
    lines: Iterable[bytes], fmt: str, model: MultiTrackModel, *, out_of_order: str = "error", unterminated: str = "hint"
) -> Iterator[DetectionScan | BadRecord | Dropped]:
    """Scans of detections for ``model``, with every problem as a :class:`~pursuit.io.records.BadRecord`; never raises.

    Beyond the checks of :func:`pursuit.io.detections.read_detection_records`
    and :func:`~pursuit.io.detections.group_scans`: a record of a sensor
    other than the model's is bad (``sensor``), and so is one more than
    ``[input] max_gap`` after the last time reached (``time``).
    ``out_of_order="sort"`` reads the whole input first.
    """
    spec = model.input
    records: Iterable[Record | BadRecord] = read_detection_records(
        lines, fmt, model.values, time_column=spec.time_column, sensor_column=spec.sensor_column, unterminated=unterminated
    )
    if out_of_order == "sort":
        records = sort_records(records)
    grouping = "error" if out_of_order == "sort" else out_of_order
    yield from group_scans(_checked(records, model), out_of_order=grouping, dim=len(model.values))


def _checked(records: Iterable[Record | BadRecord], model: MultiTrackModel) -> Iterator[Record | BadRecord]:
    spec, sid = model.input, model.sensor.id
    reached: float | None = None
    for item in records:
        if isinstance(item, Record):
            if item.sensor is not None and item.sensor != sid:
                item = BadRecord(item.line, spec.sensor_column, f"unknown sensor {item.sensor!r} (the model's sensor is {sid!r})")
            elif reached is not None and item.time - reached > spec.max_gap:
                item = BadRecord(
                    item.line,
                    spec.time_column,
                    f"{item.time!r} is {item.time - reached:g} s after the last time reached ({reached!r}), beyond input.max_gap = "
                    f"{spec.max_gap:g} s: a broken clock? (raise [input] max_gap if the gap is real)",
                )
            else:
                reached = item.time if reached is None else max(reached, item.time)
        yield item


def run_track_multi(
    args: argparse.Namespace, *, stdin: BinaryIO | None = None, stdout: TextIO | None = None, stderr: TextIO | None = None
) -> int:
    """Run ``pursuit track --multi`` with parsed arguments; returns the exit code.

    A bad model file raises :class:`pursuit.experiment.ConfigError`, which
    the CLI reports with exit code 2.
    """
    stdin = stdin if stdin is not None else sys.stdin.buffer
    stdout = stdout if stdout is not None else sys.stdout
    stderr = stderr if stderr is not None else sys.stderr
    try:
        for flag, value in (("--truth", args.truth), ("--plot", args.plot)):
            if value:
                raise _Usage(f"{flag} is not available with --multi (it scores and draws one track)")
        if args.out_of_order is None:
            args = argparse.Namespace(**{**vars(args), "out_of_order": "error"})
        in_fmt, out_fmt, streaming, policy = _settings(args)
    except _Usage as e:
        print(f"{_NAME}: error: {e}", file=stderr)
        return EXIT_BAD_INPUT
    model = load_multi_model(args.config)
    source = "<stdin>" if args.data == "-" else args.data
    if args.output and (same_file(args.data, args.output) if args.data != "-" else same_file_as_stream(stdin, args.output)):
        print(f"{_NAME}: error: {args.output}: the output is the input file {source}; choose another output", file=stderr)
        return EXIT_BAD_INPUT
    try:
        fh = stdin if args.data == "-" else open(args.data, "rb")
    except OSError as e:
        print(f"{_NAME}: error: {args.data}: cannot read: {e.strerror or e}", file=stderr)
        return EXIT_BAD_INPUT
    variances = not getattr(args, "no_var", False)
    try:
        lines = iter(fh.readline, b"") if streaming else fh
        events = detection_events(lines, in_fmt, model, out_of_order=policy, unterminated="reject" if streaming else "hint")
        run = _stream if streaming else _batch
        return run(events, model, args, out_fmt, variances, source, stdout, stderr)
    except BrokenPipeError:
        _silence(stdout)
        return EXIT_OK
    except _OutputFailed as e:
        where = args.output or "standard output"
        print(f"{_NAME}: error: {where}: cannot write: {e.error.strerror or e.error}", file=stderr)
        if not args.output:
            _silence(stdout)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"{_NAME}: interrupted", file=stderr)
        return EXIT_INTERRUPTED
    finally:
        if fh is not stdin:
            fh.close()


def _rng(model: MultiTrackModel) -> np.random.Generator:
    return np.random.default_rng(model.seed)  # Gaussian per-track filters draw nothing; kept for any that would


def _no_track_note(stderr: TextIO, source: str, scans: int) -> None:
    print(f"{_NAME}: note: {source}: no track was confirmed in {scans} scan{'s' if scans != 1 else ''}", file=stderr)


# --------------------------------------------------------------------------
# batch: all or nothing
# --------------------------------------------------------------------------
def _batch(events, model: MultiTrackModel, args, out_fmt, variances, source, stdout, stderr) -> int:
    items = list(events)
    if _header_failed(stderr, source, items, "; nothing written"):
        return EXIT_BAD_INPUT
    bad = sorted((e for e in items if isinstance(e, BadRecord)), key=lambda b: b.line)
    for item in items:
        if isinstance(item, Dropped):
            _report(stderr, source, item, "warning")
    for item in bad:
        _report(stderr, source, item, "skipped" if args.skip_bad else "error")
    if bad and not args.skip_bad:
        if len(bad) > 1:
            print(f"{_NAME}: {len(bad)} bad records in {source}; nothing written (fix them, or use --skip-bad to skip them)", file=stderr)
        return EXIT_BAD_INPUT
    scans = [e for e in items if isinstance(e, DetectionScan)]
    if not scans:
        what = f"all {len(bad)} records were bad" if bad else "it holds no detection records"
        print(f"{_NAME}: error: {source}: nothing to track: {what}; nothing written", file=stderr)
        return EXIT_BAD_INPUT
    data = pad_scans([[s.z] for s in scans], [s.time for s in scans], dim=len(model.values))
    result = track_scans(model.tracker, data.z, times=data.times, rng=_rng(model))
    buffer = io.StringIO()
    writer = TrackRowWriter(out_fmt, buffer, model.state_labels, variances=variances)
    writer.start()
    for k, scan in enumerate(scans):
        writer.write_scan(scan.time, scan_rows(result.mean[k, 0], result.cov[k, 0], result.label[k, 0], result.confirmed[k, 0]))
    if args.output:
        try:
            write_whole(args.output, buffer.getvalue())
        except OSError as e:
            print(f"{_NAME}: error: {args.output}: cannot write: {e.strerror or e}", file=stderr)
            return EXIT_BAD_INPUT
    else:
        guarded = _GuardedOutput(stdout)
        guarded.write(buffer.getvalue())
        guarded.flush()
    if bad:
        print(f"{_NAME}: skipped {len(bad)} bad record(s) in {source}", file=stderr)
    if not result.confirmed.any():
        _no_track_note(stderr, source, len(scans))
    return EXIT_OK


# --------------------------------------------------------------------------
# stream: scan by scan
# --------------------------------------------------------------------------
class _LazyFile:
    """A text file opened at its first write: a stream that stops before any row leaves no file."""

    def __init__(self, path: str):
        self.path = path
        self.file: TextIO | None = None

    def write(self, text: str) -> int:
        if self.file is None:
            self.file = open(self.path, "w", encoding="utf-8", newline="")
        return self.file.write(text)

    def flush(self) -> None:
        if self.file is not None:
            self.file.flush()

    def close(self) -> None:
        if self.file is not None:
            self.file.close()


def _stream(events, model: MultiTrackModel, args, out_fmt, variances, source, stdout, stderr) -> int:
    counts = {"scans": 0, "skipped": 0}

    def scans() -> Iterator[tuple[float, np.ndarray]]:
        for event in events:
            if isinstance(event, DetectionScan):
                counts["scans"] += 1
                yield event.time, event.z[None]  # one run: (1, n, m), no padding
            elif isinstance(event, Dropped):
                _report(stderr, source, event, "warning")
                stderr.flush()
            elif event.field == "header" or not args.skip_bad:
                raise _StopAtBad(event)
            else:
                _report(stderr, source, event, "skipped")
                stderr.flush()
                counts["skipped"] += 1

    out = _LazyFile(args.output) if args.output else stdout
    written = confirmed = 0
    try:
        guarded = _GuardedOutput(out)
        writer = TrackRowWriter(out_fmt, guarded, model.state_labels, variances=variances, flush_each=True)
        for tracks in track_stream(model.tracker, scans(), rng=_rng(model)):
            rows = scan_rows(tracks.mean[0], tracks.cov[0], tracks.label[0], tracks.confirmed[0])
            writer.write_scan(tracks.time, rows)
            written += 1
            confirmed += len(rows)
    except _StopAtBad as e:
        if _header_failed(stderr, source, [e.item]):
            return EXIT_BAD_INPUT
        _report(stderr, source, e.item, "error")
        print(
            f"{_NAME}: stopped at the first bad record, after {written} scan{'s' if written != 1 else ''} "
            "tracked from the records before it (use --skip-bad to go on)",
            file=stderr,
        )
        return EXIT_BAD_INPUT
    finally:
        if out is not stdout:
            try:
                out.close()
            except OSError as e:
                if sys.exc_info()[1] is None:
                    raise _OutputFailed(e) from None
    if counts["skipped"]:
        print(f"{_NAME}: skipped {counts['skipped']} bad record(s) in {source}", file=stderr)
    if not counts["scans"]:
        what = f"all {counts['skipped']} records were bad" if counts["skipped"] else "it held no detection records"
        print(f"{_NAME}: error: {source}: nothing to track: {what}", file=stderr)
        return EXIT_BAD_INPUT
    if not confirmed:
        _no_track_note(stderr, source, counts["scans"])
    return EXIT_OK
