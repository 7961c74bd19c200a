"""The benchmark scripts still run (quick sizes; nothing about speed is asserted here)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_benchmark_runner_quick_mode():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "kf"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "pursuit KF numpy (shared P)" in proc.stdout
    assert "pursuit UKF numpy" in proc.stdout


def test_floor_benchmark_quick_mode():
    pytest.importorskip("numba")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "floor"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Generator.standard_normal() in numba, per draw" in proc.stdout
    assert "step kernel alone" in proc.stdout
