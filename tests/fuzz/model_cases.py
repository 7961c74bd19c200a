"""Fuzz cases for ``pursuit track`` model files: one field of a shipped model changed.

The oracle is docs/track.md's "The model file": every key is checked before anything runs and a
mistake is one line naming the file, the line and the field, exit 2, nothing written.  Each
mutation says what the docs make of it:

* ``reject``: an unknown section or key, a value of the wrong type, an impossible value (a
  non-positive or non-finite noise, ndim outside 1..3, a gate outside (0, 1), a prior of the
  wrong size or not positive definite) and, per issue 16 item 10, magnitudes no physical model
  has (sigma = 1e200 or 1e-300, q = 1e308, a prior mean of 1e308, a fading factor of 1e300),
  which must be blamed on the model file, not on every record of the data;
* ``accept``: a model the docs allow (no ``[prior]``: the track starts from the measurements):
  exit 0 and finite estimates;
* ``same``: another spelling of the same model (an integer for a float, a covariance's diagonal
  written as a matrix, a track name): the estimates must be the base model's, bit for bit;
* ``either``: an extreme but legal model (a prior covariance of 1e20·I): a clean error or
  finite estimates, never NaN and never a traceback.
"""

from __future__ import annotations

import math
import random
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .common import ACCEPTED, CLEAN_ERROR, PARTIAL, WRONG, Outcome, classify_cli, run_cli
from .tomlgen import DELETE, RawValue, dumps, edit, get

ROOT = Path(__file__).resolve().parents[2]
BASES = {
    "wsn-range": (ROOT / "examples" / "wsn-range.toml", ROOT / "examples" / "data" / "wsn-range.csv"),
    "underwater-toa": (ROOT / "examples" / "underwater-toa.toml", ROOT / "examples" / "data" / "underwater-toa.csv"),
}
NAN, INF = math.nan, math.inf

S = ("sensors", 0)
# (path, value, expectation); a path into [[sensors]] uses sensor 0.
MUTATIONS: list[tuple[tuple, Any, str]] = [
    *[(("motion", "type"), v, "reject") for v in ("xx", 3, "")],
    *[(("motion", "ndim"), v, "reject") for v in (0, 4, 2.5, "2", True)],
    *[(("motion", "q"), v, "reject") for v in (-1.0, NAN, INF, "a", [1.0], 1e308)],
    (("motion", "noise"), "brown", "reject"),
    *[(("motion", "dt"), v, "reject") for v in (0.0, -1.0, NAN, INF)],
    *[((*S, "sigma"), v, "reject") for v in (0.0, -1.0, NAN, INF, 1e200, 1e-300, "1")],
    *[((*S, "position"), v, "reject") for v in ([0.0], [0.0, 0.0, 0.0], ["a", 0.0], [NAN, 0.0], [INF, 0.0])],
    ((*S, "type"), "sonar", "reject"),
    ((*S, "id"), "", "reject"),
    ((*S, "valid"), [5.0, 1.0], "reject"),
    ((*S, "valid"), [NAN, 1.0], "reject"),
    ((*S, "valid"), [1.0], "reject"),
    ((*S, "colour"), "red", "reject"),
    *[(("prior", "mean"), v, "reject") for v in ("short", "nan", "inf", "huge")],
    *[(("prior", "cov"), v, "reject") for v in (-4.0, NAN, [[1.0, 2.0], [3.0, 4.0]], "notpd", [4.0, -0.25, 4.0, 0.25])],
    *[(("prior", "time"), v, "reject") for v in (NAN, INF, "0")],
    (("filter", "type"), "nope", "reject"),
    *[(("filter", "gate"), v, "reject") for v in (0.0, 1.0, 1.5, -0.1, NAN)],
    *[(("filter", "fading"), v, "reject") for v in (1e300, 0.5, NAN)],
    (("filter", "colour"), 1, "reject"),
    *[(("track", "seed"), v, "reject") for v in (-1, 1.5, "x")],
    (("extra", "key"), 1, "reject"),
    *[((sec,), DELETE, "reject") for sec in ("motion", "sensors", "filter")],
    (("prior",), DELETE, "accept"),  # optional: the track starts from the measurements
    (("sensors", 1, "id"), "dup", "reject"),  # the id of sensor 0: two sensors of one name
    (("prior", "cov"), 1e20, "either"),
    (("motion", "q"), 1e6, "either"),
    (("prior", "cov"), "matrix", "same"),
    (("prior", "mean"), "ints", "same"),
    ((*S, "sigma"), "int", "same"),
    (("track", "name"), "renamed", "same"),
]


@dataclass
class ModelCase:
    base: str
    path: tuple
    value: Any
    expect: str

    @property
    def name(self) -> str:
        v = self.value if not isinstance(self.value, float) else repr(self.value)
        return f"{self.base}: {'.'.join(map(str, self.path))} = {v if self.value is not DELETE else '(removed)'}"


def _resolve(doc: dict, case: ModelCase) -> dict:
    """The edited document; symbolic values are made from the base's own."""
    v = case.value
    mean = get(doc, ("prior", "mean"))
    cov = get(doc, ("prior", "cov"))
    if case.path == ("prior", "mean") and isinstance(v, str):
        v = {"short": mean[:-1], "nan": [NAN, *mean[1:]], "inf": [*mean[:-1], INF], "huge": [1e308, *mean[1:]],
             "ints": [int(x) if float(x).is_integer() else x for x in mean]}[v]
        if case.value == "ints" and v == mean:
            v = [x + 0 for x in mean]
    elif case.path == ("prior", "cov") and isinstance(v, str):
        n = len(mean)
        if v == "matrix":
            v = [[float(cov[i]) if i == j else 0.0 for j in range(n)] for i in range(n)]
        else:  # symmetric with a negative eigenvalue
            v = [[1.0 if i == j else (2.0 if abs(i - j) == 1 else 0.0) for j in range(n)] for i in range(n)]
    elif case.path[-1] == "sigma" and v == "int":
        v = get(doc, case.path)
        v = int(v) if float(v).is_integer() else v
    elif case.path == ("sensors", 1, "id"):
        v = get(doc, ("sensors", 0, "id"))
    elif case.path[-1] == "position" and isinstance(v, list) and v and v[0] == INF:
        v = [RawValue("1e400"), 0.0]
    return edit(doc, case.path, v)


def _base_estimates(base: str, folder: Path, cache: dict) -> str:
    if base not in cache:
        model, data = BASES[base]
        res = run_cli(["track", str(data), "-c", str(model)])
        assert res.code == 0, f"the shipped model {model} does not run: {res.err}"
        cache[base] = res.out
    return cache[base]


def run_case(case: ModelCase, folder: Path, cache: dict) -> Outcome:
    model_path, data = BASES[case.base]
    doc = tomllib.loads(model_path.read_text())
    if get(doc, case.path[:-1]) is None and case.path[0] == "sensors":
        return Outcome("model", case.name, ACCEPTED, "not applicable")
    new = _resolve(doc, case)
    text, where = dumps(new)
    model = folder / "model.toml"
    model.write_text(text)
    out = folder / "estimates.csv"
    out.write_text("previous output\n")
    argv = ["track", str(data), "-c", str(model), "-o", str(out)]
    res = run_cli(argv)
    repro = {"files": {"model.toml": text}, "argv": ["track", str(data.relative_to(ROOT)), "-c", "model.toml", "-o", "estimates.csv"]}

    def result(kind, why=""):
        return Outcome("model", case.name, kind, why, repro)

    failed = classify_cli(res)
    if failed:
        return result(failed, (res.exc or res.err)[-800:])
    written = out.read_text()
    if res.code == 2 and written != "previous output\n":
        return result(PARTIAL, "exit 2 but the existing output file was changed")
    if case.expect == "reject" or (case.expect == "either" and res.code == 2):
        if res.code != 2:
            return result(WRONG, "accepted; the docs (and issue 16 item 10) make this model invalid")
        lines = [ln for ln in res.err.splitlines() if ln.strip()]
        field = str(case.path[-1]) if case.value is not DELETE else str(case.path[0])
        line = where.get(case.path[:1] if case.path[0] == "extra" else case.path)  # a section: its header's line
        if len(lines) != 1:
            return result(WRONG, f"a bad model is one line, got {len(lines)}: {res.err[-400:]}")
        if str(model) not in lines[0]:
            return result(WRONG, f"the error does not name the model file (blamed elsewhere): {lines[0]}")
        if field not in lines[0] and case.path[0] != "extra":
            return result(WRONG, f"the error does not name the field {field!r}: {lines[0]}")
        if line is not None and f"{model}:{line}:" not in lines[0] and case.expect == "reject":
            return result(WRONG, f"the error does not name line {line}: {lines[0]}")
        return result(CLEAN_ERROR)
    if res.code != 0:
        return result(WRONG, f"a valid model was refused: {res.err[-400:]}")
    rows = [r.split(",") for r in written.splitlines()[1:]]
    for r in rows:
        nums = [float(x) for x in r[:9]]
        if not all(math.isfinite(x) for x in nums) or any(x <= 0 for x in nums[5:9]):
            return result(WRONG, f"non-finite estimate or non-positive variance written: {','.join(r)}")
        init = "init" in r[11].split(";")  # a track started from the measurements: nothing filtered, no NIS
        if int(r[10]) > 0 and not init and not (math.isfinite(float(r[9] or "nan")) and float(r[9]) >= 0):
            return result(WRONG, f"NaN or negative NIS written: {','.join(r)}")
    if case.expect == "same" and written != _base_estimates(case.base, folder, cache):
        return result(WRONG, "the same model written another way gave other estimates")
    return result(ACCEPTED)


def run_swapped(rng: random.Random, folder: Path) -> Outcome:
    """A file of another kind given as the model: an experiment, a data file."""
    other = rng.choice([ROOT / "experiments" / "wsn-gaussian.toml", ROOT / "examples" / "data" / "wsn-range.csv"])
    data = BASES["wsn-range"][1]
    argv = ["track", str(data), "-c", str(other)]
    res = run_cli(argv)
    repro = {"files": {}, "argv": argv}
    name = f"swapped: {other.name} as the model"
    failed = classify_cli(res)
    if failed:
        return Outcome("model", name, failed, (res.exc or res.err)[-800:], repro)
    if res.code != 2 or str(other) not in res.err or res.out:
        return Outcome("model", name, WRONG, f"exit {res.code}: {res.err[-300:]}", repro)
    return Outcome("model", name, CLEAN_ERROR, "", repro)


def generate(rng: random.Random, folder: Path, cache: dict) -> Outcome:
    if rng.random() < 0.05:
        return run_swapped(rng, folder)
    path, value, expect = rng.choice(MUTATIONS)
    return run_case(ModelCase(rng.choice(sorted(BASES)), path, value, expect), folder, cache)


def all_cases() -> list[ModelCase]:
    """Every mutation on every base model (the exhaustive pass of ``--all``)."""
    return [ModelCase(b, p, v, e) for b in sorted(BASES) for p, v, e in MUTATIONS]

