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


def test_long_run_script_takes_fading_variants_and_a_step_count():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "long_run.py"), "kf", "ekf+stf", "--steps", "1500"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("kf (position): 1500 steps in one run") and "max_lambda" not in lines[0]
    assert lines[1].startswith("ekf+stf (range): 1500 steps in one run") and "max_lambda=" in lines[1]
    for line in lines:
        assert "repaired=0" in line and "cholesky_failures=0" in line and "all_finite=True" in line
    bad = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "long_run.py"), "ekf+xyz"], capture_output=True, text=True, timeout=60)
    assert bad.returncode != 0 and "unknown name 'ekf+xyz'" in bad.stderr
