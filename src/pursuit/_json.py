"""JSON encoding of the values pursuit writes into sidecars and result files."""

from __future__ import annotations

from datetime import date, datetime, time
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["json_default"]


def json_default(o: Any) -> Any:
    """``json.dumps(default=...)`` hook: arrays to lists, NumPy scalars to numbers,
    paths and TOML dates to strings, anything else to its ``repr``."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    if isinstance(o, (datetime, date, time)):
        return o.isoformat()
    return repr(o)
