"""``make demo``'s glibc malloc settings (``DEMO_MALLOC`` in the Makefile) change no number.

They only change where freed memory goes (docs/cli.md#memory-allocation); this runs
a small experiment with and without them, each in a fresh process (glibc reads the
variables at start-up), and compares every file that does not hold a wall time.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def demo_malloc() -> dict[str, str]:
    """The ``NAME=VALUE`` pairs of the Makefile's ``DEMO_MALLOC``."""
    text = (ROOT / "Makefile").read_text()
    line = re.search(r"^DEMO_MALLOC \?= (.+)$", text, flags=re.M)
    assert line, "Makefile: no DEMO_MALLOC line"
    pairs = dict(p.split("=", 1) for p in line.group(1).split())
    assert pairs and all(k.startswith("MALLOC_") for k in pairs), pairs
    return pairs


def _reproduce(out: Path, extra_env: dict[str, str]) -> Path:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env.update(extra_env)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    subprocess.run(
        [sys.executable, "-m", "pursuit", "reproduce", "wsn-gaussian", "--runs", "3", "--no-pdf",
         "--no-progress", "--out", str(out)],
        env=env, check=True, capture_output=True, cwd=ROOT,
    )
    return out / "wsn-gaussian"


def test_demo_malloc_settings_change_no_number(tmp_path):
    env = demo_malloc()
    plain = _reproduce(tmp_path / "plain", {})
    tuned = _reproduce(tmp_path / "tuned", env)
    for name in ("per_step.csv", "errors.csv", "consistency.csv"):
        assert (plain / name).read_bytes() == (tuned / name).read_bytes(), name
    a = np.load(plain / "results" / "result.npz", allow_pickle=True)
    b = np.load(tuned / "results" / "result.npz", allow_pickle=True)
    assert a.files == b.files
    for key in a.files:
        if key != "meta":  # meta holds the wall times
            assert a[key].tobytes() == b[key].tobytes(), key
