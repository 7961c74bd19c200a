"""``pursuit track DATA --config MODEL.toml``: a configured filter on recorded or live data.

Two modes:

* **batch** (a file): every record is read and checked first.  Any bad
  record stops the command with exit code 2 and *nothing* is written (every
  problem is listed on standard error with its line and field); with
  ``--skip-bad`` the bad records are listed, skipped, and the estimates
  written.  The output file appears whole or not at all (written to a
  temporary file beside it, then renamed; :mod:`pursuit.io.output_file`).
  An output that is the input file (through any link) is refused.
* **stream** (``-``, standard input, or ``--stream``): records are filtered
  as they arrive and each estimate is written and flushed as soon as its time
  step is complete.  A bad record stops the command with exit code 2 after
  the estimates already written, unless ``--skip-bad``.

``--multi`` (multi-target tracking of detections) is
:mod:`pursuit.io.multi`, with the same conventions.

Exit codes: 0 success, 2 bad input (model file, data, arguments), 130
interrupted (Ctrl-C stops a stream after the estimates already written), 1 an
unexpected failure.
"""

from __future__ import annotations

import argparse
import io
import os
import sys
from pathlib import Path
from typing import BinaryIO, TextIO

from .extras import Extras
from .blocks import EstimateBlock
from .lines import ChunkedLines
from .model import TrackModel, load_track_model
from .output_file import same_file, same_file_as_stream, write_whole
from .records import FORMATS, BadRecord, read_record_chunks, read_records
from .steps import OUT_OF_ORDER, Dropped
from .tracker import Estimate, block_estimates, stream_records, track_records
from .writers import OUTPUT_FORMATS, make_writer

__all__ = ["add_track_parser", "run_track"]

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130

_EXTENSIONS = {".csv": "csv", ".jsonl": "jsonl", ".ndjson": "jsonl", ".json": "jsonl"}


def add_track_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``track`` subcommand to the ``pursuit`` parser."""
    tp = sub.add_parser(
        "track",
        help="run a configured filter on recorded (CSV) or live (JSON Lines) measurements",
        description="Run the filter configured in MODEL.toml on measurements and write its estimates.",
    )
    tp.add_argument("data", help="measurements (or detections with --multi): a .csv or .jsonl file, or - for standard input (a live stream)")
    tp.add_argument(
        "-c", "--config", "--model", dest="config", required=True,
        help="MODEL.toml: motion model, sensors, prior and filter (with --multi: motion, sensor and [tracker])",
    )
    tp.add_argument(
        "--multi",
        action="store_true",
        help="multi-target tracking of unlabelled detections with the model's [tracker] (gnn or jpda): one row per confirmed track per scan",
    )
    tp.add_argument("--no-var", action="store_true", help="with --multi: leave the covariance diagonal (var_*) out of the output")
    tp.add_argument("-o", "--output", "--out", dest="output", help="estimates (or tracks) file (default: standard output)")
    tp.add_argument("--format", choices=FORMATS, help="input format (default: from the extension; jsonl for standard input)")
    tp.add_argument("--to", choices=OUTPUT_FORMATS, help="output format (default: from the output's extension, else the input format)")
    mode = tp.add_mutually_exclusive_group()
    mode.add_argument("--stream", dest="stream", action="store_true", default=None, help="filter records as they arrive and flush each estimate (default for standard input)")
    mode.add_argument("--batch", dest="stream", action="store_false", help="read everything first and write all or nothing (default for files)")
    tp.add_argument("--truth", metavar="FILE", help="truth CSV (time and state columns): print RMSE and NEES of the estimates at its times on standard error")
    tp.add_argument("--plot", metavar="FILE", help="draw the track (estimate, 2-sigma covariance ellipses, measurements, truth) into FILE (.png, .pdf or .svg)")
    tp.add_argument("--skip-bad", action="store_true", help="report bad records, skip them and go on (default: stop with exit code 2)")
    tp.add_argument(
        "--out-of-order",
        choices=OUT_OF_ORDER,
        help="records earlier than a time already reached: sort them in (batch default), drop them with a warning (stream default), "
        "or treat them as bad (the default with --multi)",
    )
    return tp


_NO_START = "no step fixed a position to start the track from (see the warnings; or give a [prior])"


class _Usage(Exception):
    """A bad combination of arguments."""


def run_track(args: argparse.Namespace, *, stdin: BinaryIO | None = None, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Run ``pursuit track`` with parsed arguments; returns the exit code.

    ``stdin``, ``stdout`` and ``stderr`` default to the process's streams
    (standard input is read as bytes).  A bad model file raises
    :class:`pursuit.experiment.ConfigError`, which the CLI reports with exit
    code 2.
    """
    stdin = stdin if stdin is not None else sys.stdin.buffer
    stdout = stdout if stdout is not None else sys.stdout
    stderr = stderr if stderr is not None else sys.stderr
    try:
        if getattr(args, "multi", False):  # cli.py sends --multi to pursuit.io.multi.run_track_multi
            raise _Usage("--multi is run by pursuit.io.multi.run_track_multi")
        if getattr(args, "no_var", False):
            raise _Usage("--no-var is an option of --multi")
        in_fmt, out_fmt, streaming, policy = _settings(args)
    except _Usage as e:
        print(f"pursuit track: error: {e}", file=stderr)
        return EXIT_BAD_INPUT
    model = load_track_model(args.config)
    source = "<stdin>" if args.data == "-" else args.data
    try:  # checked before any record is read, so a bad truth file or plot name costs no output
        extras = Extras.prepare(args, model)
    except ValueError as e:
        print(f"pursuit track: error: {e}", file=stderr)
        return EXIT_BAD_INPUT
    if args.output and (same_file(args.data, args.output) if args.data != "-" else same_file_as_stream(stdin, args.output)):
        # in a stream the output is opened while the input is read: it would truncate the recording
        print(f"pursuit track: error: {args.output}: the output is the input file {source}; choose another output", file=stderr)
        return EXIT_BAD_INPUT
    try:
        fh = stdin if args.data == "-" else open(args.data, "rb")
    except OSError as e:
        print(f"pursuit track: error: {args.data}: cannot read: {e.strerror or e}", file=stderr)
        return EXIT_BAD_INPUT
    try:
        # a stream is read in chunks of what has arrived (ChunkedLines), and filtered in blocks that end there
        lines = ChunkedLines(fh) if streaming else fh
        # a stream's last line without its newline was cut off mid-write; a file's may just lack one
        if streaming and model.prior is not None and not args.plot:
            # whole chunks at once (blocks of plain records; the same records and messages), with the wait marks
            records = read_record_chunks(lines.chunks(), in_fmt, unterminated="reject", layout=model.input, ready=lines.ready)
            ready = None
        else:
            records = extras.watch(
                read_records(lines, in_fmt, unterminated="reject" if streaming else "hint", layout=model.input)
            )
            ready = lines.ready if streaming else None
        if streaming:
            code = _stream(records, model, args, out_fmt, policy, source, stdout, stderr, extras.sink, lines, ready)
        else:
            code = _batch(records, model, args, out_fmt, policy, source, stdout, stderr, extras.sink)
        return extras.finish(stderr) if code == EXIT_OK else code
    except BrokenPipeError:
        # The reader of our output went away (``| head``): stop quietly, and point
        # standard output at /dev/null so that the interpreter's final flush
        # does not complain.
        _silence(stdout)
        return EXIT_OK
    except _OutputFailed as e:  # the output itself failed (a full disk, `> /dev/full`): one line, no traceback
        where = args.output or "standard output"
        print(f"pursuit track: error: {where}: cannot write: {e.error.strerror or e.error}", file=stderr)
        if not args.output:
            _silence(stdout)  # else the interpreter's final flush fails again
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:  # the usual way to end a live stream: no traceback
        print("pursuit track: interrupted", file=stderr)
        return EXIT_INTERRUPTED
    finally:
        if fh is not stdin:
            fh.close()


class _OutputFailed(Exception):
    """Writing the estimates failed (an OSError of the output, not of the input)."""

    def __init__(self, error: OSError) -> None:
        super().__init__(str(error))
        self.error = error


class _GuardedOutput:
    """A text stream whose write and flush errors become :class:`_OutputFailed` (a broken pipe stays itself)."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as e:
            raise _OutputFailed(e) from None

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise
        except OSError as e:
            raise _OutputFailed(e) from None


def _silence(stream: TextIO) -> None:
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)


def _settings(args) -> tuple[str, str, bool, str]:
    if args.format:
        in_fmt = args.format
    elif args.data == "-":
        in_fmt = "jsonl"
    else:
        in_fmt = _EXTENSIONS.get(Path(args.data).suffix.lower())
        if in_fmt is None:
            raise _Usage(f"{args.data}: cannot tell the format from the extension; use --format csv or --format jsonl")
    if args.to:
        out_fmt = args.to
    elif args.output and Path(args.output).suffix.lower() in _EXTENSIONS:
        out_fmt = _EXTENSIONS[Path(args.output).suffix.lower()]
    else:
        out_fmt = in_fmt
    streaming = args.data == "-" if args.stream is None else args.stream
    policy = args.out_of_order or ("drop" if streaming else "sort")
    if streaming and policy == "sort":
        raise _Usage("--out-of-order sort needs the whole input before filtering; use it without --stream (drop or error when streaming)")
    return in_fmt, out_fmt, streaming, policy


def _header_failed(stderr: TextIO, source: str, items: list, after: str = "") -> bool:
    """Report the problems of an input whose CSV header is missing or does not fit; True if it is one.

    Fatal even with --skip-bad: the reader stops at such a header, as every
    row would be misread.
    """
    if not any(isinstance(item, BadRecord) and item.field == "header" for item in items):
        return False
    for item in items:
        _report(stderr, source, item, "error")
    print(f"pursuit track: error: {source}: no usable header, so no record was read{after}", file=stderr)
    return True


def _report(stderr: TextIO, source: str, item: BadRecord | Dropped, kind: str) -> None:
    field = "time" if isinstance(item, Dropped) else item.field
    print(f"pursuit track: {kind}: {source}:{item.line}: {field}: {item.message}", file=stderr)


# --------------------------------------------------------------------------
# batch: all or nothing
# --------------------------------------------------------------------------
def _batch(records, model: TrackModel, args, out_fmt, policy, source, stdout, stderr, collected: list | None) -> int:
    result = track_records(records, model, out_of_order=policy)
    if _header_failed(stderr, source, result.problems, "; nothing written"):
        return EXIT_BAD_INPUT
    for item in result.dropped:
        _report(stderr, source, item, "warning")
    kind = "skipped" if args.skip_bad else "error"
    for item in result.problems:
        _report(stderr, source, item, kind)
    if result.problems and not args.skip_bad:
        n = len(result.problems)
        print(
            f"pursuit track: {n} bad record{'s' if n != 1 else ''} in {source}; nothing written "
            "(fix them, or use --skip-bad to skip them)",
            file=stderr,
        )
        return EXIT_BAD_INPUT
    if not result.estimates:
        what = f"all {len(result.problems)} records were bad" if result.problems else "it holds no measurement records"
        if model.prior is None and result.dropped and not result.problems:
            what = _NO_START
        print(f"pursuit track: error: {source}: nothing to track: {what}; nothing written", file=stderr)
        return EXIT_BAD_INPUT
    if collected is not None:
        collected.extend(result.estimates)
    buffer = io.StringIO()
    writer = make_writer(out_fmt, buffer, model.state_labels)
    writer.start()
    for est in result.estimates:
        writer.write(est)
    text = buffer.getvalue()
    if args.output:
        try:
            write_whole(args.output, text)
        except OSError as e:
            print(f"pursuit track: error: {args.output}: cannot write: {e.strerror or e}", file=stderr)
            return EXIT_BAD_INPUT
    else:
        guarded = _GuardedOutput(stdout)
        guarded.write(text)
        guarded.flush()
    if result.problems:
        print(f"pursuit track: skipped {len(result.problems)} bad record(s) in {source}", file=stderr)
    return EXIT_OK


# --------------------------------------------------------------------------
# stream: estimate by estimate
# --------------------------------------------------------------------------
def _stream(
    records, model: TrackModel, args, out_fmt, policy, source, stdout, stderr, collected: list | None, lines: ChunkedLines, ready
) -> int:
    if args.output:
        try:
            out = open(args.output, "w", encoding="utf-8", newline="")
        except OSError as e:
            print(f"pursuit track: error: {args.output}: cannot write: {e.strerror or e}", file=stderr)
            return EXIT_BAD_INPUT
    else:
        out = stdout
    written = skipped = unused = 0
    try:
        guarded = _GuardedOutput(out)
        writer = make_writer(out_fmt, guarded, model.state_labels)
        writer.start()
        guarded.flush()
        # every estimate written is flushed before the input is waited for: as live as a flush per row
        lines.before_wait = guarded.flush
        for event in stream_records(records, model, out_of_order=policy, stop_at_bad=not args.skip_bad, ready=ready, blocks=True):
            if isinstance(event, EstimateBlock):
                writer.write_block(event)
                if collected is not None:
                    collected.extend(block_estimates(event))
                written += len(event)
            elif isinstance(event, Estimate):
                writer.write(event)
                if collected is not None:  # only for --truth / --plot: a live stream may run for days
                    collected.append(event)
                written += 1
            elif isinstance(event, Dropped):
                _report(stderr, source, event, "warning")
                stderr.flush()
                unused += 1
            elif _header_failed(stderr, source, [event]):
                return EXIT_BAD_INPUT
            elif args.skip_bad:
                _report(stderr, source, event, "skipped")
                stderr.flush()
                skipped += 1
            else:
                _report(stderr, source, event, "error")
                print(
                    f"pursuit track: stopped at the first bad record, after {written} estimate{'s' if written != 1 else ''} "
                    "from the records before it (use --skip-bad to go on)",
                    file=stderr,
                )
                return EXIT_BAD_INPUT
    finally:
        lines.before_wait = None
        if out is stdout:
            if sys.exc_info()[1] is None:  # not already failing (a broken pipe, a full disk)
                guarded.flush()
        else:
            try:
                out.close()  # flushes what is buffered: it can fail too
            except OSError as e:
                if sys.exc_info()[1] is None:  # not already failing for another reason
                    raise _OutputFailed(e) from None
    if skipped:
        print(f"pursuit track: skipped {skipped} bad record(s) in {source}", file=stderr)
    if not written:  # the output holds only its header, written when the stream began
        what = f"all {skipped} records were bad" if skipped else "it held no measurement records"
        if model.prior is None and unused and not skipped:
            what = _NO_START
        print(f"pursuit track: error: {source}: nothing to track: {what}", file=stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK
