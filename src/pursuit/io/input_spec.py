"""The ``[input]`` section of MODEL.toml: the data's columns, its time origin, and the largest time gap.

Everything here is optional; a model file without ``[input]`` reads the
``time,sensor,value`` CSV of docs/track.md::

    [input]
    time_column = "t"           # the time column's name (default "time")
    sensor_column = "id"        # the sensor column's name (default "sensor")
    columns = {gps = ["east", "north"]}   # a wide file: each sensor's value columns,
                                          # and no sensor column
    time_origin = 2026-07-01T00:00:00Z    # ISO 8601 times count seconds from here
                                          # (default: the Unix epoch)
    max_gap = 86400.0           # a record further than this after the last time
                                # reached is a bad record (default: derived below)

**The largest gap.**  A time far beyond the last one reached is much more
likely a corrupt clock than a pause, and accepting it would make every later
record "late".  The default ``max_gap`` is the gap over which the motion
model's own process noise spreads the predicted position over more than
:data:`POSITION_SCALE` (10⁹, the default bound of every sensor's ``valid``
range): the smallest gap at which a position standard deviation of the
process-noise covariance Q(gap) exceeds it.  Across such a gap the prediction
says nothing about where the target is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import date, datetime, time, timezone
from typing import Any, Mapping

import numpy as np

from ..registry import Component, Param

__all__ = ["InputSpec", "INPUT_PARAMS", "POSITION_SCALE", "EPOCH", "build_input_spec", "default_max_gap", "to_origin"]

POSITION_SCALE = 1.0e9
"""Position spread (model units, m) beyond which a prediction carries no information."""

EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
"""The default origin of ISO 8601 times: the Unix epoch."""


@dataclass(frozen=True)
class InputSpec:
    """How to read a data file, and which time gaps are believable.

    Attributes
    ----------
    time_column, sensor_column
        Names of the CSV columns holding the time and the sensor id
        (compared without case and surrounding spaces).
    columns
        For a *wide* CSV (no sensor column): each sensor id's value columns,
        in component order; None for the usual one-record-per-row layout.
    time_origin
        ISO 8601 times become seconds after this instant (aware, UTC).
    max_gap
        A record more than this many seconds after the last time reached is
        a bad record (``inf``: no limit).
    """

    time_column: str = "time"
    sensor_column: str = "sensor"
    columns: Mapping[str, tuple[str, ...]] | None = None
    time_origin: datetime = EPOCH
    max_gap: float = math.inf


def to_origin(value: date | datetime) -> datetime:
    """An aware UTC datetime from a TOML date or datetime; naive times are read as UTC."""
    if not isinstance(value, datetime):
        value = datetime.combine(value, time(0))
    if value.tzinfo is None:
        return value.replace(tzinfo=timezone.utc)
    return value.astimezone(timezone.utc)


def _time_origin(field_name: str, v: Any) -> datetime:
    if isinstance(v, str):
        try:
            v = datetime.fromisoformat(v.strip())
        except ValueError:
            raise ValueError(f"{field_name}: not an ISO 8601 time: {v!r} (write e.g. 2026-07-01T00:00:00Z)") from None
    if isinstance(v, time) or not isinstance(v, (date, datetime)):
        raise ValueError(f"{field_name}: expected a date and time such as 2026-07-01T00:00:00Z, got {v!r}")
    return to_origin(v)


def _max_gap(field_name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or not v > 0:
        raise ValueError(f"{field_name}: expected a positive number of seconds (or inf for no limit), got {v!r}")
    return float(v)


def _column_name(field_name: str, v: Any) -> str:
    if not isinstance(v, str) or not v.strip() or any(c in v for c in ',"\r\n'):
        raise ValueError(f"{field_name}: expected a column name (non-empty, no commas, quotes or line breaks), got {v!r}")
    return v.strip()


def _columns(field_name: str, v: Any) -> dict[str, tuple[str, ...]]:
    if not isinstance(v, dict) or not v:
        raise ValueError(f"{field_name}: expected a table of sensor ids and their columns, e.g. {{gps = [\"east\", \"north\"]}}")
    out = {}
    for sensor, names in v.items():
        where = f"{field_name}.{sensor}"
        names = names if isinstance(names, list) else [names]
        if not names:
            raise ValueError(f"{where}: expected one column name per component, got none")
        out[sensor] = tuple(_column_name(where, n) for n in names)
    return out


INPUT_PARAMS = (
    Param("time_column", "any", "time", "name of the CSV time column", check=_column_name),
    Param("sensor_column", "any", "sensor", "name of the CSV sensor-id column", check=_column_name),
    Param("columns", "any", None, "wide CSV: sensor id -> its value column(s); the file has no sensor column", check=_columns),
    Param("time_origin", "any", EPOCH, "ISO 8601 times are seconds after this (default the Unix epoch)", check=_time_origin),
    Param(
        "max_gap", "any", None, "largest believable gap after the last time reached, s (default: derived from [motion])", check=_max_gap
    ),
)


def default_max_gap(motion: Any, scale: float = POSITION_SCALE) -> float:
    """The gap over which the motion's process noise spreads a position over more than ``scale``.

    The smallest ``g`` (to a relative 10⁻⁶) with ``sqrt(Q(g)[i, i]) > scale``
    for a position index ``i``, found by bisection on ``log g``; ``inf`` when
    no gap up to 10³⁰⁰ s does (a model whose noise stays bounded), and for a
    motion model without ``cov(dt=...)``, ``position_indices`` and ``dt``
    (nothing to derive the rule from).
    """
    try:
        idx = list(motion.position_indices)
        np.diagonal(np.asarray(motion.cov(dt=float(motion.dt)), dtype=float))[idx]
    except (AttributeError, TypeError, ValueError, IndexError):
        return math.inf

    def too_wide(gap: float) -> bool:
        try:
            with np.errstate(all="ignore"):
                q = np.asarray(motion.cov(dt=gap), dtype=float)
                var = np.diagonal(q)[idx]
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):
            return True
        return bool(np.any(~np.isfinite(var)) or np.any(var > scale**2))

    lo = float(motion.dt)
    if too_wide(lo):
        return lo
    hi = lo
    while not too_wide(hi):
        if hi > 1e300:
            return math.inf
        lo, hi = hi, hi * 10.0
    while hi / lo > 1 + 1e-6:
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if too_wide(mid) else (mid, hi)
    return hi


def build_input_spec(table: Any, motion: Any, sensors: Mapping[str, Any]) -> InputSpec:
    """The ``[input]`` section, checked against the sensors; raises ``ValueError`` naming the field.

    Parameters
    ----------
    table
        The parsed ``[input]`` table (``{}`` when the file has none).
    motion
        The motion model (for the default ``max_gap``).
    sensors
        The configured sensors by id (``dim``).
    """
    if not isinstance(table, dict):
        raise ValueError("input: expected a table")
    vals = Component("section", "input", "", INPUT_PARAMS, dict).resolve(table, "input")
    columns = vals["columns"]
    if columns is not None:
        if "sensor_column" in table:
            raise ValueError("input.sensor_column: a wide file (input.columns) has no sensor column; give one or the other")
        seen = {vals["time_column"].lower(): "input.time_column"}
        for sensor, names in columns.items():
            where = f"input.columns.{sensor}"
            if sensor not in sensors:
                raise ValueError(f"{where}: unknown sensor {sensor!r} (known: {', '.join(sensors)})")
            if len(names) != sensors[sensor].dim:
                raise ValueError(f"{where}: sensor {sensor!r} has {sensors[sensor].dim} component(s), got {len(names)} column(s)")
            for name in names:
                if name.lower() in seen:
                    raise ValueError(f"{where}: column {name!r} is already used by {seen[name.lower()]}")
                seen[name.lower()] = where
    elif vals["time_column"].lower() == vals["sensor_column"].lower():
        raise ValueError(f"input.sensor_column: the same column as input.time_column ({vals['time_column']!r})")
    max_gap = default_max_gap(motion) if vals["max_gap"] is None else vals["max_gap"]
    return InputSpec(
        time_column=vals["time_column"],
        sensor_column=vals["sensor_column"],
        columns=columns,
        time_origin=vals["time_origin"],
        max_gap=max_gap,
    )
