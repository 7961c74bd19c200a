"""Fuzz cases for ``pursuit track`` inputs: CSV and JSON Lines records, in batch and in stream.

The oracle is written from docs/track.md, not from the readers:

* a record is good when its time is an ASCII-digit number, finite and after the prior's time
  (0 in examples/wsn-range.toml), its sensor is one of A1..A4, and its one value is an
  ASCII-digit number inside the default ``valid`` range [-1e9, 1e9], or missing (empty, ``nan``,
  JSON ``null``/``NaN``); a second record of one sensor at one time is bad;
* batch: records are sorted by time (stably); any bad record without ``--skip-bad`` is exit 2
  with every bad line named and nothing written (an existing output left as it was);
* stream: records are taken in order, an older one is dropped with a warning, the first bad one
  stops the command after the estimates of the records before it; a last line without its
  newline is an incomplete record;
* whatever is written equals what the same command writes for a clean file holding only the
  records the oracle kept (the reference run), so a value read differently from its text, a
  record silently dropped or kept, shows as a difference.
"""

from __future__ import annotations

import json
import math
import os
import random
import re
from dataclasses import dataclass
from pathlib import Path

from .common import ACCEPTED, CLEAN_ERROR, PARTIAL, WRONG, Outcome, classify_cli, run_cli

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "wsn-range.toml"
SENSORS = ("A1", "A2", "A3", "A4")
VALID = 1e9  # the default `valid` range is [-1e9, 1e9]
PRIOR_TIME = 0.0  # [prior] time of examples/wsn-range.toml
# docs/track.md "Gaps": the default max_gap of a discrete-noise cv model is (4·10¹⁸/q)^(1/4) s; q = 0.01 here.
MAX_GAP = (4e18 / 0.01) ** 0.25

# A number as docs/track.md reads it: ASCII digits, optional sign, point and exponent.
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")

GOOD_TIMES = [f"{t / 10:.1f}" for t in range(1, 300)]
ODD_TIMES = ["", "nan", "inf", "-inf", "1e999", "0", "-3", "t", "１.5", "1_0", "0x10", "1.2.3", "1e15", "1e300", "+2.5", ".5", "5."]
GOOD_VALUES = None  # drawn per case
ODD_VALUES = ["", "nan", "NaN", "inf", "-Infinity", "1e999", "-1e400", "abc", "1.2.3", "0x1F", "1_0", "--1", "1e", "e5", "４１.5",
              "1e12", "-5e9", "1e300", "1.7976931348623157e308", "1e-300", "0", "-0.0", " 12.5 ", "1e9", "-1e9", "1000000001"]
ODD_SENSORS = ["", "A5", "a1", "B", " A2 ", "A1;A2", "Ａ1"]


def _number(text: str) -> float | None:
    """The finite value ``text`` says, or None when it is not a number docs/track.md reads."""
    text = text.strip()
    if not _NUMBER.fullmatch(text):
        return None
    v = float(text)
    return v if math.isfinite(v) else None


def csv_line_oracle(text: str, valid: float = VALID):
    """None (ignored), "bad", or (time, sensor, values) for one CSV line (values within ±``valid``)."""
    if not text.strip() or text.lstrip().startswith("#"):
        return None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) < 3:
        return "bad"
    t = _number(parts[0])
    if t is None or t <= 0.0 or parts[1] not in SENSORS:
        return "bad"
    values = []
    for v in parts[2:]:
        if v == "" or v.lower() == "nan":
            values.append(math.nan)
            continue
        x = _number(v)
        if x is None or abs(x) > valid:
            return "bad"
        values.append(x)
    return "bad" if len(values) != 1 else (t, parts[1], tuple(values))


def _json_number(v, missing_ok: bool):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return math.nan if missing_ok else "bad"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "bad"
    try:
        f = float(v)
    except OverflowError:
        return "bad"
    return f if math.isfinite(f) else "bad"


def jsonl_line_oracle(text: str, valid: float = VALID):
    """"bad", ("predict", T) or (time, sensor, values) for one JSON Lines line (values within ±``valid``)."""
    pairs_seen = []

    def hook(pairs):
        pairs_seen.append([k for k, _ in pairs])
        return dict(pairs)

    if re.search(r"[^\x00-\x7f]", re.sub(r'"(?:[^"\\]|\\.)*"', "", text)):
        return "bad"  # a non-ASCII character outside strings: not JSON (full-width digits)
    try:
        obj = json.loads(text, object_pairs_hook=hook)
    except ValueError:
        return "bad"
    if not isinstance(obj, dict) or any(len(keys) != len(set(keys)) for keys in pairs_seen):
        return "bad"
    if set(obj) - {"time", "sensor", "value", "values"} or "time" not in obj or ("value" in obj and "values" in obj):
        return "bad"
    t = _json_number(obj["time"], False)
    if t == "bad" or t <= 0.0:
        return "bad"
    has_value = "value" in obj or "values" in obj
    if "sensor" not in obj or obj["sensor"] is None:
        return "bad" if has_value else ("predict", t)
    s = obj["sensor"]
    if not isinstance(s, str) or s.strip() not in SENSORS or not has_value:
        return "bad"
    raw = obj.get("value", obj.get("values"))
    items = raw if isinstance(raw, list) else [raw]
    vals = [_json_number(v, True) for v in items]
    if len(vals) != 1 or "bad" in vals or (not math.isnan(vals[0]) and abs(vals[0]) > valid):
        return "bad"
    return (t, s.strip(), tuple(vals))


# --------------------------------------------------------------------------
# generators
# --------------------------------------------------------------------------
def _good_value(rng: random.Random) -> str:
    return repr(rng.uniform(1.0, 140.0))


def _csv_line(rng: random.Random, t: str) -> str:
    kind = rng.choices(["record", "odd-value", "odd-time", "odd-sensor", "short", "long", "garbage", "comment", "blank"],
                       weights=[10, 3, 2, 2, 1, 1, 1, 1, 1])[0]
    s = rng.choice(SENSORS)
    v = _good_value(rng)
    if kind == "odd-value":
        v = rng.choice(ODD_VALUES)
    elif kind == "odd-time":
        t = rng.choice(ODD_TIMES)
    elif kind == "odd-sensor":
        s = rng.choice(ODD_SENSORS)
    if kind == "short":
        return rng.choice([t, f"{t},{s}"])
    if kind == "long":
        return f"{t},{s},{v},{_good_value(rng)}"
    if kind == "garbage":
        return "".join(rng.choice('ab1.,;e+-"\t\x00 ') for _ in range(rng.randint(1, 12))).replace('"', "")
    if kind == "comment":
        return "# note, 1, 2"
    if kind == "blank":
        return ""
    return f"{t},{s},{v}"


def _jsonl_line(rng: random.Random, t: str) -> str:
    kind = rng.choices(["record", "odd-value", "odd-time", "odd-sensor", "predict", "values", "list", "extra-key", "dup-key",
                        "no-time", "both", "broken", "not-object"], weights=[10, 3, 2, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1])[0]
    s = rng.choice(SENSORS)
    v = _good_value(rng)
    odd_json_values = ["null", "NaN", "Infinity", "-Infinity", "1e999", "1e400", "\"12.5\"", "true", "[]", "[1.0, 2.0]", "{}",
                       "1e300", "-5e9", "1e12", "１２", "0x10", "1_0", "12.5.1", str(10**400), "0"]
    if kind == "odd-value":
        v = rng.choice(odd_json_values)
    elif kind == "odd-time":
        t = rng.choice(["null", "NaN", "Infinity", "1e999", "\"3.0\"", "0", "-1", "true", "1e15", "1e300", "１.5", str(10**400)])
    elif kind == "odd-sensor":
        s = rng.choice(ODD_SENSORS)
    if kind == "predict":
        return f'{{"time": {t}}}'
    if kind == "values":
        return f'{{"time": {t}, "sensor": "{s}", "values": [{v}]}}'
    if kind == "list":
        return f'{{"time": {t}, "sensor": "{s}", "value": [{v}, {_good_value(rng)}]}}'
    if kind == "extra-key":
        return f'{{"time": {t}, "sensor": "{s}", "value": {v}, "{rng.choice(["note", "Time", "sensorid"])}": 1}}'
    if kind == "dup-key":
        key = rng.choice(["time", "sensor", "value"])
        dup = {"time": f'"{key}": {t}', "sensor": f'"{key}": "{s}"', "value": f'"{key}": {_good_value(rng)}'}[key]
        return f'{{"time": {t}, "sensor": "{s}", "value": {v}, {dup}}}'
    if kind == "no-time":
        return f'{{"sensor": "{s}", "value": {v}}}'
    if kind == "both":
        return f'{{"time": {t}, "sensor": "{s}", "value": {v}, "values": {v}}}'
    if kind == "broken":
        return rng.choice(['{"time": 1.0, "sensor": "A1", "value": 3', "{time: 1}", "[1, 2", '{"time": 1.0,}', "garbage", "\x00"])
    if kind == "not-object":
        return rng.choice(["[1.0, \"A1\", 3.0]", "12", "\"text\"", "null"])
    return f'{{"time": {t}, "sensor": "{s}", "value": {v}}}'


@dataclass
class TrackCase:
    name: str
    fmt: str  # "csv" or "jsonl"
    lines: list[str]
    final_newline: bool
    stream: bool
    skip_bad: bool
    to_file: bool  # -o OUT (an existing file) rather than standard output
    header: str = "time,sensor,value"
    valid: float = VALID  # every sensor's `valid` range is [-valid, valid]


def make_case(rng: random.Random) -> TrackCase:
    fmt = rng.choice(["csv", "jsonl"])
    n = rng.randint(0, 14)
    times = sorted(rng.sample(GOOD_TIMES, n)) if n else []
    if rng.random() < 0.5:  # out of order, sometimes several sensors at one time
        rng.shuffle(times)
    times = [t if rng.random() < 0.8 or not times else rng.choice(times) for t in times]
    make = _csv_line if fmt == "csv" else _jsonl_line
    lines = [make(rng, t) for t in times]
    stream = rng.random() < 0.4
    case = TrackCase(
        name=f"{fmt} {'stream' if stream else 'batch'}",
        fmt=fmt,
        lines=lines,
        final_newline=rng.random() < 0.85,
        stream=stream,
        skip_bad=rng.random() < 0.5,
        to_file=not stream and rng.random() < 0.6,
        header=rng.choice(["time,sensor,value", "time,sensor,values", "\ufefftime,sensor,value"]),
    )
    if rng.random() < 0.15:  # sensors that accept any finite value: 1e300 reaches the filter
        case.valid = 1.7976931348623157e308
    if fmt == "jsonl":  # JSON Lines has no blank or comment lines in docs/track.md: keep every line a record
        case.lines = [ln for ln in case.lines if ln.strip()]
    return case


def _text(case: TrackCase, lines: list[str]) -> str:
    body = ([case.header] if case.fmt == "csv" else []) + lines
    text = "\n".join(body)
    return text + "\n" if (case.final_newline or not lines) and body else text


def expected(case: TrackCase):
    """(bad line numbers the command must name, the kept lines in the order filtered, must fail)."""
    first = 2 if case.fmt == "csv" else 1
    oracle = csv_line_oracle if case.fmt == "csv" else jsonl_line_oracle
    verdicts = []
    for i, line in enumerate(case.lines):
        v = oracle(line, case.valid)
        if case.stream and i == len(case.lines) - 1 and not case.final_newline and v is not None:
            v = "bad"  # a stream's record is complete only at its newline
        verdicts.append((first + i, line, v))
    if not case.stream:
        keyed = [(ln, line, v) for ln, line, v in verdicts if v not in (None, "bad")]
        keyed.sort(key=lambda p: p[2][1] if p[2][0] == "predict" else p[2][0])
        seen, bad = set(), {ln for ln, _, v in verdicts if v == "bad"}
        kept, reached = [], PRIOR_TIME
        for ln, line, v in keyed:
            t = v[1] if v[0] == "predict" else v[0]
            if v[0] != "predict" and (v[0], v[1]) in seen:
                bad.add(ln)
                continue
            if t - reached > MAX_GAP:  # a corrupt clock, not a pause; the time reached stays
                bad.add(ln)
                continue
            reached = t
            if v[0] != "predict":
                seen.add((v[0], v[1]))
            kept.append(line)
        return bad, kept
    bad, kept, current, sensors = set(), [], -math.inf, set()
    for ln, line, v in verdicts:
        if v is None:
            continue
        if v == "bad":
            bad.add(ln)
            if not case.skip_bad:
                break
            continue
        t = v[1] if v[0] == "predict" else v[0]
        if t < current:
            continue  # dropped with a warning
        if t - (current if current > -math.inf else PRIOR_TIME) > MAX_GAP:
            bad.add(ln)  # more than max_gap after the time reached, which stays
            if not case.skip_bad:
                break
            continue
        if t > current:
            current, sensors = t, set()
        if v[0] != "predict":
            if v[1] in sensors:
                bad.add(ln)
                if not case.skip_bad:
                    break
                continue
            sensors.add(v[1])
        kept.append(line)
    return bad, kept


def _model(valid: float, folder: Path) -> Path:
    """The example model, or a copy in ``folder`` whose sensors accept values up to ±``valid`` (issue 16 item 8: 1e300)."""
    if valid == VALID:
        return MODEL
    path = folder / "wide.toml"
    path.write_text(MODEL.read_text().replace("sigma = 1.0", f"sigma = 1.0\nvalid = [{-valid!r}, {valid!r}]"))
    return path


def _argv(case: TrackCase, data: str, out: Path | None, model: Path = MODEL) -> list[str]:
    argv = ["track", data, "-c", str(model), "--format", case.fmt, "--to", "csv"]
    argv += ["--stream"] if case.stream else ["--batch"]
    argv += ["--skip-bad"] if case.skip_bad else []
    argv += ["-o", str(out)] if out is not None else []
    return argv


def _invoke(case: TrackCase, text: str, folder: Path, stem: str):
    data = folder / f"{stem}.{case.fmt}"
    data.write_text(text, encoding="utf-8")
    out = folder / f"{stem}-out.csv" if case.to_file else None
    if out is not None:
        out.write_text("previous output\n")
    if case.stream:
        res = run_cli(_argv(case, "-", out, _model(case.valid, folder)), stdin=text.encode("utf-8"))
    else:
        res = run_cli(_argv(case, str(data), out, _model(case.valid, folder)))
    written = (out.read_text() if out.exists() else None) if out is not None else res.out
    return res, written, data


def run_case(case: TrackCase, folder: Path) -> Outcome:
    text = _text(case, case.lines)
    res, written, data = _invoke(case, text, folder, "data")
    source = "<stdin>" if case.stream else str(data)
    shown = "-" if case.stream else f"data.{case.fmt}"
    repro = {"files": {f"data.{case.fmt}": text}, "argv": _argv(case, shown, None, _model(case.valid, folder))}
    if case.valid != VALID:
        repro["files"]["wide.toml"] = (folder / "wide.toml").read_text()

    def result(kind, why=""):
        return Outcome("track", case.name, kind, why, repro)

    failed = classify_cli(res)
    if failed:
        return result(failed, (res.exc or res.err)[-800:])
    bad, kept = expected(case)
    for line in res.err.splitlines():
        if not line.startswith("pursuit track:"):
            return result(WRONG, f"stderr line not from pursuit track: {line!r}")
    named_bad = {int(m) for m in re.findall(r"(?:error|skipped): " + re.escape(source) + r":(\d+): ", res.err)}
    refused = {int(m) for m in re.findall(r"(?:error|skipped): " + re.escape(source) + r":(\d+): \w+: rejected at time", res.err)}
    if case.stream and not case.skip_bad and refused:
        # A refused step is the stream's first bad record: it stops there, and later lines go unread.
        first = min(refused)
        if not named_bad - refused <= bad or {b for b in bad if b < first} - named_bad:
            return result(WRONG, f"bad lines named {sorted(named_bad - refused)} with a step refused at line {first}, "
                                 f"the docs make {sorted(bad)} bad")
    elif named_bad - refused != bad:
        return result(WRONG, f"bad lines named {sorted(named_bad - refused)}, the docs make {sorted(bad)} bad")
    # The reference: the same command on a clean file of the kept records alone.
    ref_case = TrackCase(case.name, case.fmt, kept, True, case.stream, case.skip_bad, case.to_file, "time,sensor,value", case.valid)
    ref, ref_written, _ = _invoke(ref_case, _text(ref_case, kept), folder, "clean")
    if classify_cli(ref):
        return result(classify_cli(ref), "the clean reference run failed: " + (ref.exc or ref.err)[-600:])
    must_fail = bool(bad) and not case.skip_bad
    want_code = 2 if must_fail else ref.code
    if res.code != want_code:
        return result(WRONG, f"exit code {res.code}, the docs say {want_code}; stderr: {res.err[-400:]}")
    if res.code == 2:
        if case.stream:
            if written != ref_written:
                return result(PARTIAL if written and ref_written and written.startswith(ref_written) else WRONG,
                              "a stream stopped by a bad record wrote other estimates than those of the records before it")
            return result(CLEAN_ERROR)
        if case.to_file and written != "previous output\n":
            return result(PARTIAL, "after exit 2 the existing output file was changed")
        if not case.to_file and written:
            return result(PARTIAL, "after exit 2 in batch, estimates were written to standard output")
        return result(CLEAN_ERROR)
    if written != ref_written:
        return result(WRONG, "the estimates differ from those of the clean file of the good records alone")
    rows = [r.split(",") for r in (written or "").splitlines()[1:]]
    for r in rows:
        nums = [float(x) for x in r[:9]]
        if not all(math.isfinite(x) for x in nums) or any(x <= 0 for x in nums[5:9]):
            return result(WRONG, f"a non-finite estimate or a non-positive variance was written: {r}")
        nis, dof = float(r[9]) if r[9] else math.nan, int(r[10])
        if dof > 0 and not (math.isfinite(nis) and nis >= 0):  # a step that measured nothing has no NIS
            return result(WRONG, f"a NaN or negative NIS was written: {r}")
        if dof == 0 and "predict" not in r[11].split(";"):
            return result(WRONG, f"a step that measured nothing is not flagged predict: {r}")
    return result(ACCEPTED)


# --------------------------------------------------------------------------
# fixed cases: the output onto its own input (issue item 1)
# --------------------------------------------------------------------------
def run_self_output(rng: random.Random, folder: Path) -> Outcome:
    data = folder / "self.csv"
    text = "time,sensor,value\n1.0,A1,41.5\n2.0,A2,98.3\n"
    data.write_text(text)
    how = rng.choice(["same name", "symlink", "hardlink", "./ prefix"])
    if how == "same name":
        out = str(data)
    elif how == "./ prefix":
        out = os.path.join(str(folder), ".", "self.csv")
    else:
        link = folder / f"self-{how}.csv"
        if link.exists() or link.is_symlink():
            link.unlink()
        (os.symlink if how == "symlink" else os.link)(data, link)
        out = str(link)
    argv = ["track", str(data), "-c", str(MODEL), "-o", out]
    res = run_cli(argv)
    repro = {"files": {"data.csv": text}, "argv": argv}
    name = f"-o onto its input ({how})"
    failed = classify_cli(res)
    if failed:
        return Outcome("track", name, failed, (res.exc or res.err)[-800:], repro)
    if data.read_text() != text:
        return Outcome("track", name, PARTIAL, "the input was changed", repro)
    if res.code != 2 or "the output is the input file" not in res.err:
        return Outcome("track", name, WRONG, f"exit {res.code}: {res.err[-300:]}", repro)
    return Outcome("track", name, CLEAN_ERROR, "", repro)


def run_output_through_link(rng: random.Random, folder: Path) -> Outcome:
    """``-o`` a symbolic link (issue 16 item 3): written through to its target, still a link; left alone on error."""
    good = rng.random() < 0.5
    text = "time,sensor,value\n1.0,A1,41.5\n2.0,A2,98.3\n" + ("" if good else "3.0,A9,1.0\n")
    data = folder / "data.csv"
    data.write_text(text)
    target, link = folder / "target.csv", folder / "link.csv"
    target.write_text("previous output\n")
    os.symlink(target, link)
    argv = ["track", str(data), "-c", str(MODEL), "-o", str(link)]
    res = run_cli(argv)
    repro = {"files": {"data.csv": text}, "argv": ["track", "data.csv", "-c", str(MODEL), "-o", "link.csv"]}
    name = f"-o through a symbolic link ({'good' if good else 'bad'} data)"
    failed = classify_cli(res)
    if failed:
        return Outcome("track", name, failed, (res.exc or res.err)[-800:], repro)
    if not link.is_symlink() or os.readlink(link) != str(target):
        return Outcome("track", name, WRONG if good else PARTIAL, "the link was replaced", repro)
    if not good:
        if res.code != 2 or target.read_text() != "previous output\n":
            return Outcome("track", name, PARTIAL if target.read_text() != "previous output\n" else WRONG, f"exit {res.code}", repro)
        return Outcome("track", name, CLEAN_ERROR, "", repro)
    ref = run_cli(["track", str(data), "-c", str(MODEL)])
    if res.code != 0 or target.read_text() != ref.out:
        return Outcome("track", name, WRONG, f"exit {res.code}; the target does not hold the estimates", repro)
    return Outcome("track", name, ACCEPTED, "", repro)


def generate(rng: random.Random, folder: Path) -> Outcome:
    """One seeded track case, run and judged."""
    r = rng.random()
    if r < 0.05:
        return run_self_output(rng, folder)
    if r < 0.08:
        return run_output_through_link(rng, folder)
    return run_case(make_case(rng), folder)
