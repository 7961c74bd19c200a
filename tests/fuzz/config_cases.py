"""Fuzz cases for experiment configurations: one field of a shipped experiment changed.

The bases are experiments/*.toml shrunk to a tiny size (2 runs, a few steps, few particles) so
that an accepted case runs in well under a second.  The oracle is docs/configuration.md and
docs/cli.md: the whole file is checked before anything runs; an unknown section or key, a value
of the wrong type or an impossible value stops with one line naming the file, the line and the
field (exit 2) and nothing is written (an existing output folder is left as it was).  Each
mutation says what the docs make of it:

* ``reject``: as above, plus the impossible values of issue 16 item 10 (an unknown
  ``paper.metric``, a ``paper.at`` that is not swept, a filter's ``particles`` that the sweep
  over particles would override, ``figures.values = [nan]``, a maneuver starting before 0);
* ``same``: a change the docs say does not change results (``chunk_size``: "results do not
  depend on it"; an integer where a float is expected; a new title): every table equals the
  base's, bit for bit (timing columns aside);
* ``size``: an enormous size (issue 16 item 5: runs = 10^12, steps = 10^18, 10^6 particles): a
  clean error, or a correct result within the case's time limit; never a MemoryError traceback.

An accepted run's tables must hold no NaN, infinite or negative RMSE, NEES or NIS.
"""

from __future__ import annotations

import math
import random
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .common import ACCEPTED, CLEAN_ERROR, OVER_TIME, PARTIAL, TRACEBACK, WRONG, Outcome, bounded, classify_cli, run_cli, snapshot
from .tomlgen import dumps, edit, get

ROOT = Path(__file__).resolve().parents[2]
EXPERIMENTS = ROOT / "experiments"
NAN, INF = math.nan, math.inf

# Shrink every base: (path, value) applied when the path's parent exists.
SHRINK = [
    (("experiment", "runs"), 2),
    (("scenario", "steps"), 6),
    (("filters", "*", "particles"), 20),
    (("filters", "*", "n_iter"), 2),
    (("figures", "snapshot_steps"), [2, 4, 6]),  # within the shrunk steps
]

MUTATIONS: list[tuple[tuple, Any, str]] = [
    *[(("experiment", "runs"), v, "reject") for v in (0, -1, "2", 2.5, NAN, True)],
    *[(("experiment", "seed"), v, "reject") for v in (-1, "x", 1.5)],
    (("experiment", "kind"), "nope", "reject"),
    (("experiment", "colour"), "red", "reject"),
    (("bogus", "key"), 1, "reject"),
    (("scenario", "type"), "nope", "reject"),
    *[(("scenario", "steps"), v, "reject") for v in (0, -1, 2.5)],
    *[(("scenario", "sigma"), v, "reject") for v in (-1.0, 0.0, NAN, INF, "x")],
    *[(("scenario", "q"), v, "reject") for v in (-1.0, NAN)],
    (("scenario", "colour"), 1, "reject"),
    (("filters", 0, "type"), "nope", "reject"),
    *[(("filters", 0, "gate"), v, "reject") for v in (0.0, 1.5)],
    *[(("filters", 0, "fading"), v, "reject") for v in (0.5, NAN, 1e300)],
    (("filters", 0, "colour"), 1, "reject"),
    (("filters", 1, "name"), "=filters0", "reject"),
    (("figures", "trajectory_run"), 2, "reject"),
    (("figures", "values"), [NAN], "reject"),
    (("figures", "snapshot_steps"), [1000], "reject"),  # past the last step
    (("figures", "snapshot_value"), 12345, "reject"),  # not a swept value (as paper.at)
    (("paper", 0, "metric"), "nonsense", "reject"),
    (("paper", 0, "at"), 12345, "reject"),
    (("filters", 0, "particles"), 50, "reject-if-swept"),
    (("scenario", "maneuvers", 0, "start"), -5, "reject"),
    (("experiment", "runs"), 10**12, "size"),
    (("scenario", "steps"), 10**18, "size"),
    (("scenario", "horizon"), 10**18, "size"),
    (("filters", 0, "particles"), 10**6, "size"),
    (("experiment", "chunk_size"), 1, "same"),
    (("experiment", "title"), "another title", "same"),
    (("scenario", "sigma"), "int", "same"),
]

# Filters that take `gate` (docs/configuration.md) and the particle filters.
_GATED = ("kf", "ekf", "ukf", "ckf", "cs", "apcs", "ms", "cs-nonlinear", "singer", "imm", "imm-singer")
_PARTICLE = ("pf", "upf", "cs-pf", "ics-pf")
# Columns that measure the machine, not the filters.
_TIMING = ("time", "wall", "cost", "speed", "per_step_s", "per_s", "seconds")  # per_s: scans_per_s
_CHECKED = ("rmse", "nees", "nis", "anees", "anis")


def bases() -> list[str]:
    return sorted(p.stem for p in EXPERIMENTS.glob("*.toml"))


def _shrunk(name: str) -> dict:
    doc = tomllib.loads((EXPERIMENTS / f"{name}.toml").read_text())
    for path, value in SHRINK:
        if path[1] == "*":
            for i, f in enumerate(doc.get(path[0], [])):
                if path[2] in f:
                    doc = edit(doc, (path[0], i, path[2]), value)
        elif get(doc, path) is not None:
            doc = edit(doc, path, value)
    return doc


@dataclass
class ConfigCase:
    base: str
    path: tuple
    value: Any
    expect: str

    @property
    def name(self) -> str:
        v = repr(self.value) if isinstance(self.value, float) else self.value
        return f"{self.base}: {'.'.join(map(str, self.path))} = {v}"


def applicable(doc: dict, case: ConfigCase) -> bool:
    """Whether the mutation means something for this base (its section or key is there)."""
    p = case.path
    if p[0] == "bogus" or p in (("experiment", "colour"), ("experiment", "chunk_size"), ("experiment", "title")):
        return True
    if case.expect == "reject-if-swept":
        return get(doc, ("sweep", "parameter")) == "particles"
    if p == ("filters", 0, "particles") and case.expect == "size":
        particle = any(f.get("type") in _PARTICLE for f in doc.get("filters", []))
        return get(doc, ("sweep", "parameter")) != "particles" and particle
    if p[-1] in ("colour", "type", "gate", "fading", "name"):
        parent = get(doc, p[:-1])
        if p[-1] == "gate" and isinstance(parent, dict) and parent.get("type") not in _GATED:
            return False
        if p[-1] == "fading" and isinstance(parent, dict) and parent.get("type") not in ("kf", "ekf", "ukf", "ckf"):
            return False
        return isinstance(parent, dict)
    if p == ("figures", "trajectory_run"):
        return get(doc, ("experiment", "kind"), "montecarlo") == "montecarlo"
    if p == ("paper", 0, "at"):
        return get(doc, ("paper", 0)) is not None and get(doc, ("experiment", "kind")) == "sweep"
    if case.value == "int":  # an integer for an integral float
        v = get(doc, p)
        return isinstance(v, float) and v.is_integer()
    if p in (("figures", "values"), ("figures", "snapshot_steps")):
        return get(doc, p) is not None
    if p == ("figures", "snapshot_value"):
        return bool(get(doc, ("figures", "snapshot_steps")))
    return get(doc, p) is not None


def _resolve(doc: dict, case: ConfigCase) -> dict:
    v = case.value
    if v == "=filters0":
        v = get(doc, ("filters", 0, "name"), get(doc, ("filters", 0, "type")).upper())
        if get(doc, ("filters", 0, "name")) is None:
            doc = edit(doc, ("filters", 0, "name"), v)
    elif v == "int":
        v = get(doc, case.path)
        v = int(v)
    return edit(doc, case.path, v)


def _tables(output) -> list:
    """The tables without their timing columns, for comparison."""
    result = []
    for t in output.tables:
        keep = [i for i, c in enumerate(t.columns) if not any(k in str(c).lower() for k in _TIMING)]
        # rows about wall time (a paper's timing beside ours) measure the machine too
        rows = [tuple(_norm(r[i]) for i in keep) for r in t.rows if not any(isinstance(x, str) and "wall" in x.lower() for x in r)]
        result.append((t.name, [t.columns[i] for i in keep], rows))
    return result


def _norm(x):
    return "nan" if isinstance(x, float) and math.isnan(x) else x


def _bad_number(output) -> str | None:
    for t in output.tables:
        for ci, c in enumerate(t.columns):
            if not any(str(c).lower().startswith(k) or f"_{k}" in str(c).lower() for k in _CHECKED):
                continue
            if any(k in str(c).lower() for k in ("low", "high", "inside", "ratio", "pct", "diff", "delta", "paper")):
                continue
            for r in t.rows:
                x = r[ci]
                if isinstance(x, (int, float)) and not isinstance(x, bool) and (not math.isfinite(x) or x < 0):
                    return f"{t.name}.{c} = {x!r}"
    return None


def _run_in_process(path: Path):
    from pursuit.experiment import ConfigError, load_experiment

    def go():
        try:
            return load_experiment(path).run(progress=False)
        except ConfigError as e:
            return e

    return bounded(go)


_BASE_TABLES: dict[str, list] = {}


def _base_tables(name: str, folder: Path) -> list:
    if name not in _BASE_TABLES:
        p = folder / f"base-{name}.toml"
        p.write_text(dumps(_shrunk(name))[0])
        value, exc, over = _run_in_process(p)
        assert exc is None and not over and not isinstance(value, Exception), f"the shrunk base {name} does not run: {exc or value}"
        _BASE_TABLES[name] = _tables(value)
    return _BASE_TABLES[name]


def run_case(case: ConfigCase, folder: Path, full: bool = False) -> Outcome:
    doc = _shrunk(case.base)
    new = _resolve(doc, case)
    text, where = dumps(new)
    cfg = folder / "exp.toml"
    cfg.write_text(text)
    repro = {"files": {"exp.toml": text}, "argv": ["run", "exp.toml", "--out", "out", "--no-progress", "--no-pdf"]}

    def result(kind, why=""):
        return Outcome("config", case.name, kind, why, repro)

    value, exc, over = _run_in_process(cfg)
    if over:
        return result(OVER_TIME, "loading and running took longer than the case's limit")
    if exc is not None:
        return result(TRACEBACK, exc[-800:])
    rejected = isinstance(value, Exception)
    must_reject = case.expect == "reject" or (case.expect == "reject-if-swept")
    if rejected or full:
        # the command: one line naming file, line and field; an existing output folder untouched
        out = folder / "out"
        out.mkdir(exist_ok=True)
        (out / "previous.txt").write_text("previous results\n")
        before, siblings = snapshot(out), sorted(p.name for p in folder.iterdir())
        res = run_cli(["run", str(cfg), "--out", str(out), "--no-progress", "--no-pdf"])
        failed = classify_cli(res)
        if failed:
            return result(failed, (res.exc or res.err)[-800:])
        if res.code == 2:
            if snapshot(out) != before or sorted(p.name for p in folder.iterdir()) != siblings:
                return result(PARTIAL, "exit 2 but the output folder changed or a temporary folder was left beside it")
            lines = [ln for ln in res.err.splitlines() if ln.strip()]
            field = str(case.path[-1])
            # the line of the key; of the section's header for an unknown section; either name of a repeated one
            lines_ok = {where.get(case.path[:1] if case.path[0] == "bogus" else case.path)}
            if case.value == "=filters0":  # the name's line or the [[filters]] header of either table
                lines_ok |= {where.get(("filters", 0, "name")), where.get(("filters", 0)), where.get(("filters", 1))}
            lines_ok.discard(None)
            if len(lines) != 1 or not lines[0].startswith(f"pursuit: error: {cfg}"):
                return result(WRONG, f"a bad configuration is one line naming the file: {res.err[-400:]}")
            if must_reject and field not in lines[0] and case.path[0] != "bogus":
                return result(WRONG, f"the error does not name the field {field!r}: {lines[0]}")
            if must_reject and lines_ok and not any(f"{cfg}:{n}:" in lines[0] for n in lines_ok) and case.path[0] != "paper":
                return result(WRONG, f"the error does not name line {' or '.join(map(str, sorted(lines_ok)))}: {lines[0]}")
            if not rejected:
                return result(WRONG, "the command refused what the library accepted")
        elif rejected:
            return result(WRONG, "the library refused what the command accepted")
        elif not (out / "run.json").is_file():
            return result(PARTIAL, "exit 0 but no run.json in the output folder")
    if rejected:
        if case.expect in ("same",):
            return result(WRONG, f"a valid change was refused: {value}")
        return result(CLEAN_ERROR)
    if must_reject:
        return result(WRONG, "accepted; the docs (and issue 16 item 10) make this configuration invalid")
    bad = _bad_number(value)
    if bad:
        return result(WRONG, f"an accepted run wrote {bad}")
    if case.expect == "same" and _tables(value) != _base_tables(case.base, folder):
        return result(WRONG, "a change the docs say leaves results alone changed a table")
    return result(ACCEPTED)


def run_swapped(rng: random.Random, folder: Path) -> Outcome:
    """A track model given to ``pursuit run``."""
    other = rng.choice([ROOT / "examples" / "wsn-range.toml", ROOT / "examples" / "underwater-toa.toml"])
    out = folder / "swapped-out"
    argv = ["run", str(other), "--out", str(out), "--no-progress", "--no-pdf"]
    res = run_cli(argv)
    repro = {"files": {}, "argv": argv}
    name = f"swapped: {other.name} given to run"
    failed = classify_cli(res)
    if failed:
        return Outcome("config", name, failed, (res.exc or res.err)[-800:], repro)
    if res.code != 2 or str(other) not in res.err or out.exists():
        return Outcome("config", name, WRONG, f"exit {res.code}: {res.err[-300:]}", repro)
    return Outcome("config", name, CLEAN_ERROR, "", repro)


def generate(rng: random.Random, folder: Path, full: bool = False) -> Outcome:
    if rng.random() < 0.04:
        return run_swapped(rng, folder)
    names = bases()
    while True:
        path, value, expect = rng.choice(MUTATIONS)
        case = ConfigCase(rng.choice(names), path, value, expect)
        if applicable(_shrunk(case.base), case):
            break
    return run_case(case, folder, full)


def all_cases() -> list[ConfigCase]:
    out = []
    for b in bases():
        doc = _shrunk(b)
        out += [c for c in (ConfigCase(b, p, v, e) for p, v, e in MUTATIONS) if applicable(doc, c)]
    return out
