"""``pursuit track --truth FILE``: estimates scored against a truth file (RMSE, NEES).

A truth file is a CSV with the header ``time`` and then some of the model's
state labels (``x,vx,y,vy``, or only ``x,y``, in any order), one row per
time::

    time,x,vx,y,vy
    1.0,10.48,0.47,40.80,0.81

Blank lines and lines starting with ``#`` are ignored.  An estimate is
scored against the row whose time equals its own (within 1e-9 s);
estimates without such a row are counted and left out.  Scored are the
state components the file has: RMSE per kind (position, velocity,
acceleration), and the NEES on those components (χ² with as many degrees
of freedom on a consistent filter), with its χ² bounds.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import metrics
from .._chi2 import chi2_ppf

__all__ = ["Truth", "TruthError", "TruthScore", "read_truth", "score", "format_score"]

_NUMBER = re.compile(r"^[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$")
TIME_TOLERANCE = 1e-9
"""Seconds within which a truth row's time matches an estimate's."""


class TruthError(ValueError):
    """A truth file that cannot be used; the message names the file, the line and the field."""


@dataclass(frozen=True)
class Truth:
    """A read truth file.

    Attributes
    ----------
    times
        ``(K,)`` increasing times, s.
    states
        ``(K, c)`` true values of the columns.
    labels
        The ``c`` state labels of the columns.
    indices
        Their indices in the model's state.
    path
        Where it came from.
    """

    times: np.ndarray
    states: np.ndarray
    labels: tuple[str, ...]
    indices: tuple[int, ...]
    path: str


def read_truth(path: str | Path, state_labels: Sequence[str]) -> Truth:
    """Read and check a truth CSV against the model's state labels.

    Raises
    ------
    TruthError
        For an unreadable file, a missing or bad header (an unknown or
        repeated column, no ``time``), a row with the wrong number of fields,
        a value that is not a finite number, or a time given twice.
    """
    name = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise TruthError(f"{name}: cannot read: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        raise TruthError(f"{name}:{line}: record: not UTF-8 text") from None
    header: list[str] | None = None
    times: list[float] = []
    rows: list[list[float]] = []
    seen: dict[float, int] = {}
    for lineno, fields in _rows(text, name):
        if header is None:
            header = [f.strip() for f in fields]
            _check_header(header, state_labels, name, lineno)
            continue
        if len(fields) != len(header):
            raise TruthError(f"{name}:{lineno}: record: expected {len(header)} fields ({','.join(header)}), got {len(fields)}")
        values = [_number(f, name, lineno, col) for f, col in zip(fields, header)]
        t = values[0]
        if t in seen:
            raise TruthError(f"{name}:{lineno}: time: {t!r} is already given on line {seen[t]}")
        seen[t] = lineno
        times.append(t)
        rows.append(values[1:])
    if header is None:
        raise TruthError(f"{name}: header: missing: the file is empty (expected time and state columns, e.g. time,x,vx,y,vy)")
    if not rows:
        raise TruthError(f"{name}: record: no truth rows after the header")
    order = np.argsort(times, kind="stable")
    labels = tuple(header[1:])
    return Truth(
        times=np.asarray(times)[order],
        states=np.asarray(rows, dtype=float)[order],
        labels=labels,
        indices=tuple(list(state_labels).index(c) for c in labels),
        path=name,
    )


def _rows(text: str, name: str):
    for lineno, line in enumerate(io.StringIO(text, newline=None), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        try:
            fields = next(csv.reader([stripped], strict=True))
        except csv.Error as e:
            raise TruthError(f"{name}:{lineno}: record: {e}") from None
        yield lineno, fields


def _check_header(header: list[str], state_labels: Sequence[str], name: str, lineno: int) -> None:
    known = ", ".join(state_labels)
    if header[0] != "time":
        raise TruthError(f"{name}:{lineno}: header: the first column must be time, got {header[0]!r} (then state columns: {known})")
    if len(header) < 2:
        raise TruthError(f"{name}:{lineno}: header: no state columns after time (the model's: {known})")
    for col in header[1:]:
        if col not in state_labels:
            raise TruthError(f"{name}:{lineno}: header: {col!r} is not a state component of the model (known: {known})")
    dup = [c for c in header if header.count(c) > 1]
    if dup:
        raise TruthError(f"{name}:{lineno}: header: column {dup[0]!r} is given twice")


def _number(text: str, name: str, lineno: int, field: str) -> float:
    s = text.strip()
    if not _NUMBER.match(s):
        what = "missing" if not s else f"not a number: {s!r}"
        raise TruthError(f"{name}:{lineno}: {field}: {what} (a truth file needs every value)")
    v = float(s)
    if not math.isfinite(v):
        raise TruthError(f"{name}:{lineno}: {field}: {s!r} is too large")
    return v


@dataclass(frozen=True)
class TruthScore:
    """Estimates scored against the truth.

    Attributes
    ----------
    matched, total
        Estimates with a truth row at their time, and all estimates.
    rmse
        ``{kind: (rmse, labels)}`` for kind position, velocity, acceleration
        (those the file has).
    nees
        ``(matched,)`` NEES of each matched estimate on the file's components.
    dof
        Degrees of freedom of each NEES (the number of components).
    level
        Probability of the χ² bounds.
    mean_bounds
        Two-sided bounds for the mean NEES of ``matched`` independent values.
    step_bounds
        Two-sided bounds for one NEES value.
    """

    matched: int
    total: int
    rmse: dict[str, tuple[float, tuple[str, ...]]]
    nees: np.ndarray
    dof: int
    level: float
    mean_bounds: tuple[float, float]
    step_bounds: tuple[float, float]

    @property
    def nees_mean(self) -> float:
        """Average NEES over the matched estimates."""
        return float(np.mean(self.nees))

    @property
    def inside(self) -> int:
        """How many NEES values lie within ``step_bounds``."""
        lo, hi = self.step_bounds
        return int(np.count_nonzero((self.nees >= lo) & (self.nees <= hi)))


def score(estimates: Sequence[Any], truth: Truth, kinds: dict[str, Sequence[int]], level: float = 0.95) -> TruthScore:
    """Score estimates (with ``time``, ``mean`` and ``cov``) against the truth rows at their times.

    Parameters
    ----------
    estimates
        The tracker's estimates.
    truth
        From :func:`read_truth`.
    kinds
        ``{"position": indices, "velocity": indices, ...}``: the state
        indices of each kind, for the RMSE per kind.
    level
        Probability of the two-sided χ² bounds.

    Raises
    ------
    TruthError
        When no estimate has a truth row at its time.
    """
    times = np.array([e.time for e in estimates], dtype=float)
    pos = np.searchsorted(truth.times, times)
    matched_est, matched_row = [], []
    for i, (t, p) in enumerate(zip(times, pos)):
        for j in (p - 1, p):
            if 0 <= j < truth.times.size and abs(truth.times[j] - t) <= TIME_TOLERANCE:
                matched_est.append(i)
                matched_row.append(j)
                break
    if not matched_est:
        raise TruthError(
            f"{truth.path}: time: no truth row at the time of any of the {len(estimates)} estimates "
            f"(estimates from {times.min():g} to {times.max():g} s, truth from {truth.times[0]:g} to {truth.times[-1]:g} s)"
        )
    idx = list(truth.indices)
    est = np.array([estimates[i].mean[idx] for i in matched_est])
    cov = np.array([estimates[i].cov[np.ix_(idx, idx)] for i in matched_est])
    err = est - truth.states[matched_row]
    rmse = {}
    for kind, members in kinds.items():
        cols = [c for c, i in enumerate(idx) if i in set(members)]
        if cols:
            rmse[kind] = (float(np.sqrt(np.mean(np.sum(err[:, cols] ** 2, axis=1)))), tuple(truth.labels[c] for c in cols))
    nees = metrics.nees(est, cov, truth.states[matched_row])  # NaN where a covariance is not positive definite
    d, m, a = len(idx), len(matched_est), 1.0 - level
    mean_bounds = (float(chi2_ppf(a / 2, d * m) / m), float(chi2_ppf(1 - a / 2, d * m) / m))
    step_bounds = (float(chi2_ppf(a / 2, d)), float(chi2_ppf(1 - a / 2, d)))
    return TruthScore(m, len(estimates), rmse, nees, d, level, mean_bounds, step_bounds)


_UNITS = {"position": "m", "velocity": "m/s", "acceleration": "m/s^2"}


def format_score(s: TruthScore, truth: Truth) -> list[str]:
    """The score as lines for the terminal."""
    pct = round(100 * s.level)
    lines = [f"truth {truth.path}: {s.matched} of {s.total} estimates have a truth row at their time"]
    parts = [f"{kind} {value:.6g} {_UNITS[kind]} ({', '.join(labels)})" for kind, (value, labels) in s.rmse.items()]
    if parts:
        lines.append("RMSE: " + "; ".join(parts))
    lo, hi = s.mean_bounds
    slo, shi = s.step_bounds
    lines.append(
        f"NEES on {', '.join(truth.labels)} (chi-square, {s.dof} dof): mean {s.nees_mean:.4g} over {s.matched} estimates, "
        f"{pct}% bounds for the mean [{lo:.4g}, {hi:.4g}] (exact for independent errors; a track's are correlated); "
        f"{s.inside} of {s.matched} ({100 * s.inside / s.matched:.1f}%) within the {pct}% band of one value [{slo:.4g}, {shi:.4g}]"
    )
    return lines
