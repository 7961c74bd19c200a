"""What an experiment produces (:class:`Table`, :class:`ExperimentOutput`) and the one CSV writer.

This is the results layer's vocabulary for tables: experiment kinds build
them, :mod:`pursuit.storage` and :mod:`pursuit.report` write and show them.
It imports nothing from the config loader, the engine or the report, so all
of those can import it.  Every CSV file pursuit writes goes through
:func:`write_csv`, so they all spell numbers the same way.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

__all__ = ["Table", "ExperimentOutput", "cell", "csv_value", "write_csv"]


@dataclass
class Table:
    """A result table: printed on the terminal, written as CSV, shown in reports.

    Attributes
    ----------
    name
        File stem for the CSV (``summary`` -> ``summary.csv``).
    title
        One line shown above the table.
    columns, rows
        Header and rows (numbers stay numbers; formatting is the writer's job).
    notes
        Free text shown under the table (caveats, definitions).
    kind
        ``"result"`` for our measurements, ``"paper"`` for a table that
        puts a paper's numbers beside ours (its columns then say which is
        which, e.g. ``paper`` and ``measured``).
    """

    name: str
    title: str
    columns: list[str]
    rows: list[list[Any]]
    notes: str = ""
    kind: str = "result"


@dataclass
class ExperimentOutput:
    """What running an experiment produces: tables, figures and result objects."""

    name: str
    title: str
    description: str
    tables: list[Table]
    figures: dict[str, Any]
    results: dict[str, Any] = field(default_factory=dict)
    sidecar: dict[str, Any] = field(default_factory=dict)

    @property
    def result(self) -> Any:
        """The only result object (``results`` with one entry); an error naming them otherwise."""
        if len(self.results) != 1:
            names = ", ".join(map(str, self.results)) or "none"
            raise ValueError(f"{self.name}: {len(self.results)} results ({names}); pick one from .results")
        return next(iter(self.results.values()))


def cell(v: Any) -> str:
    """One table value as text for people: floats with four decimals (or scientific when tiny or huge)."""
    if v is None:
        return ""
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return str(v)
        a = abs(float(v))
        if a != 0 and (a < 1e-3 or a >= 1e6):
            return f"{v:.4e}"
        return f"{v:.4f}"
    return str(v)


def csv_value(v: Any) -> Any:
    """One value as written to CSV: a float as its shortest round-tripping text, None as empty."""
    if v is None:
        return ""
    if isinstance(v, (float, np.floating)):
        return repr(float(v))  # repr: reads back to the same bits
    return v


def write_csv(path: str | Path, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> int:
    """Write a header and rows as CSV (values through :func:`csv_value`); returns the number of rows.

    ``rows`` may be a generator: large tables (every run's errors) are
    streamed, not held in memory.
    """
    n = 0
    with Path(path).open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for row in rows:
            w.writerow([csv_value(v) for v in row])
            n += 1
    return n
