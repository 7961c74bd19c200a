"""The benchmark scripts still run (quick sizes; nothing about speed is asserted here)."""

import os
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
    assert "JAX vmap(lax.scan)" in proc.stdout  # measured where JAX is installed, else "not installed"
    assert "Rows other than numba's: one core" in proc.stdout


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc")
def test_one_core_pins_numpys_blas_to_one_thread():
    # OpenBLAS starts a thread per core when NumPy loads it unless told otherwise
    code = (
        "import os, sys; sys.path.insert(0, {bench!r}); import _one_core; assert _one_core.pin(); "
        "import numpy as np; np.ones((300, 300)) @ np.ones((300, 300)); "
        "print(len(os.listdir('/proc/self/task')), os.environ['OPENBLAS_NUM_THREADS'])"
    ).format(bench=str(ROOT / "benchmarks"))
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["1", "1"]
    late = "import numpy, sys; sys.path.insert(0, {bench!r}); import _one_core; print(_one_core.pin())".format(bench=str(ROOT / "benchmarks"))
    proc = subprocess.run([sys.executable, "-c", late], capture_output=True, text=True, timeout=120, env=env)
    assert proc.stdout.strip() == "False"  # too late once NumPy is loaded, and it says so


def test_the_timer_counts_cpu_time_when_told():
    """``median_time(..., clock=time.process_time)`` leaves out time the process spends off the CPU."""
    import time

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from _timing import median_time
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    assert median_time(lambda: time.sleep(0.05), 3) >= 0.05
    assert median_time(lambda: time.sleep(0.05), 3, time.process_time) < 0.02


def test_pf_benchmark_takes_cpu_time_only_with_its_one_thread_rows():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_pf.py"), "--cpu"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "--cpu goes with --cv" in proc.stderr


@pytest.mark.slow
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


def test_upf_benchmark_quick_mode():
    pytest.importorskip("numba")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "upf"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    for row in ("| bootstrap PF | numpy |", "| UPF l = 1 | numpy |", "| bootstrap PF | numba |", "| UPF l = 0.1 | numba |"):
        assert row in proc.stdout


@pytest.mark.slow
def test_p1_benchmark_and_its_floor_quick_mode():
    pytest.importorskip("numba")
    for extra, rows in (
        ([], ("| PF |", "| CS-PF (mh) |", "| ICS-PF (greedy) |", "PF + CS-PF + ICS-PF (mh):")),
        (["--floor"], ("| one MH proposal", "| one Lévy step entry", "4x the PF needs")),
    ):
        proc = subprocess.run(
            [sys.executable, str(ROOT / "benchmarks" / "bench_p1.py"), "--quick", "--repeat", "1", *extra],
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert proc.returncode == 0, proc.stderr
        for row in rows:
            assert row in proc.stdout, (extra, row)


def test_multi_target_benchmark_quick_mode():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "mt"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "| pursuit GNN | 10 |" in proc.stdout and "| pursuit JPDA | 10 |" in proc.stdout


@pytest.mark.slow
def test_pmht_benchmark_quick_mode():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "pmht"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    assert "| pursuit PMHT | 3 |" in proc.stdout
    assert "| pursuit PMHT, own initiation and termination | 3 |" in proc.stdout
    # the clutter-prior case: pursuit's track ignores the false alarm 6 m away (its error is far below 6 m / 2)
    row = next(line for line in proc.stdout.splitlines() if line.startswith("| pursuit PMHT (estimate_priors) |"))
    assert float(row.split("|")[2]) < 0.5


def test_pmht_cost_growth_quick_mode(tmp_path):
    code = (
        "import sys; sys.path.insert(0, {bench!r}); import _one_core; _one_core.pin(); from pathlib import Path; "
        "from _pmht_growth import growth; out = growth(quick=True, figure=Path({png!r})); "
        "print(sorted(out))"
    ).format(bench=str(ROOT / "benchmarks"), png=str(tmp_path / "g.png"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "PMHT ~ x^" in proc.stdout and (tmp_path / "g.png").stat().st_size > 10_000


@pytest.mark.slow
def test_gmphd_benchmark_quick_mode():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--only", "gmphd"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    assert "| pursuit GM-PHD, the same fixed birth | 3 |" in proc.stdout
    assert "| pursuit GM-PHD, adaptive two-point births (its default) | 3 |" in proc.stdout
