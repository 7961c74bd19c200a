"""Shared helpers for the io tests: the example models and data, and CSV text builders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"


def read_truth(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Times and states of an examples/data/*-truth.csv file."""
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return data[:, 0], data[:, 1:]


def csv_text(rows) -> str:
    """A measurement CSV from (time, sensor, value...) rows, numbers written with repr."""
    lines = ["time,sensor,value"]
    for t, s, *vals in rows:
        lines.append(",".join([repr(float(t)), s, *("nan" if np.isnan(v) else repr(float(v)) for v in vals)]))
    return "\n".join(lines) + "\n"


@pytest.fixture
def wsn_model_path() -> Path:
    return EXAMPLES / "wsn-range.toml"


@pytest.fixture
def toa_model_path() -> Path:
    return EXAMPLES / "underwater-toa.toml"
