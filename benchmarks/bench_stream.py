"""``pursuit track --stream``: records per second and peak memory on one core.

Work: a 2-D constant-velocity target (q = 0.01, dt = 1 s) with a position fix
(σ = 5 m) every second, tracked by a Kalman filter (``type = "kf"``) from a
known prior.  The input is written to a temporary directory as CSV and JSON
Lines (``N`` records each); ``pursuit track DATA --config MODEL.toml --stream
-o OUT`` then runs in a subprocess pinned to one core (``taskset -c 1`` where
``taskset`` exists), for the NumPy and the numba backend.  The rate is
records / wall time of the whole command, interpreter start-up and imports
included (so short inputs understate it), and the peak resident memory is the
child's ``ru_maxrss``.

The peer is a FilterPy loop on the same model (its ``KalmanFilter``, the CSV
read with ``split`` and the estimates written with ``repr``, line by line), as
a FilterPy user would track one target from a file.

Run::

    PYTHONPATH=src .bench-venv/bin/python benchmarks/bench_stream.py            # 10^5 records (make bench)
    # memory over a long stream (a NumPy run of 10^6 records takes minutes: numba only)
    PYTHONPATH=src .bench-venv/bin/python benchmarks/bench_stream.py --records 1000000 --backends numba --formats csv --no-peer
    # the code before a change in the same run (another checkout's src folder)
    PYTHONPATH=src .bench-venv/bin/python benchmarks/bench_stream.py --before ../main/src
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

MODEL = """\
[motion]
type = "cv"
ndim = 2
q = 0.01
dt = 1.0

[[sensors]]
id = "gps"
type = "position"
sigma = 5.0

[prior]
time = 0.0
mean = [0.0, 1.0, 0.0, 0.5]
cov = [100.0, 4.0, 100.0, 4.0]

[filter]
type = "kf"
backend = "{backend}"
"""


def write_inputs(folder: Path, n: int, seed: int = 0) -> dict[str, Path]:
    """A CV target's position fixes, ``n`` records at t = 1, 2, ..., as ``data.csv`` and ``data.jsonl``."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, n + 1, dtype=float)
    x = 1.0 * t + np.cumsum(rng.normal(0.0, 0.1, n))
    y = 0.5 * t + np.cumsum(rng.normal(0.0, 0.1, n))
    zx = np.round(x + rng.normal(0.0, 5.0, n), 3)
    zy = np.round(y + rng.normal(0.0, 5.0, n), 3)
    paths = {"csv": folder / "data.csv", "jsonl": folder / "data.jsonl"}
    with open(paths["csv"], "w") as f:
        f.write("time,sensor,x,y\n")
        f.writelines(f"{ti:g},gps,{a!r},{b!r}\n" for ti, a, b in zip(t.tolist(), zx.tolist(), zy.tolist()))
    with open(paths["jsonl"], "w") as f:
        f.writelines(
            f'{{"time": {ti:g}, "sensor": "gps", "value": [{a!r}, {b!r}]}}\n' for ti, a, b in zip(t.tolist(), zx.tolist(), zy.tolist())
        )
    return paths


PEER = """\
import sys
import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter

# FilterPy's KF on the same model, reading the CSV and writing time, state and variances line by line
kf = KalmanFilter(dim_x=4, dim_z=2)
kf.F = np.array([[1.0, 1.0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 1.0], [0, 0, 0, 1.0]])
kf.Q = Q_discrete_white_noise(dim=2, dt=1.0, var=0.01, block_size=2)
kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
kf.R = np.eye(2) * 25.0
kf.x = np.array([0.0, 1.0, 0.0, 0.5])
kf.P = np.diag([100.0, 4.0, 100.0, 4.0])
with open(sys.argv[1]) as src, open(sys.argv[2], "w") as out:
    next(src)
    out.write("time,x,vx,y,vy,var_x,var_vx,var_y,var_vy\\n")
    for line in src:
        t, _, x, y = line.split(",")
        kf.predict()
        kf.update(np.array([float(x), float(y)]))
        out.write(",".join(map(repr, [float(t), *kf.x.tolist(), *kf.P.diagonal().tolist()])) + "\\n")
"""


def _measure(cmd: list[str], pin: bool, src: str | None = None) -> tuple[float, float, float]:
    """Wall seconds, peak RSS (MiB) and CPU seconds (user + system) of one subprocess, run from a fresh helper.

    ``src``: the ``src`` folder of another checkout to import pursuit from (``--before``).
    """
    if pin and shutil.which("taskset"):
        cmd = ["taskset", "-c", "1", *cmd]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if src is not None:
        env["PYTHONPATH"] = src
    # ru_maxrss of RUSAGE_CHILDREN is the largest child so far: a fresh helper per run measures this one
    helper = (
        "import resource, subprocess, sys, time\n"
        "t = time.perf_counter(); rc = subprocess.call(sys.argv[1:]); dt = time.perf_counter() - t\n"
        "u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
        "print(rc, dt, u.ru_maxrss, u.ru_utime + u.ru_stime)\n"
    )
    res = subprocess.run([sys.executable, "-c", helper, *cmd], env=env, capture_output=True, text=True, check=True)
    rc, wall, rss_kib, cpu = res.stdout.split()
    if rc != "0":
        raise RuntimeError(f"{' '.join(cmd)} exited {rc}")
    return float(wall), int(rss_kib) / 1024, float(cpu)


def run_once(data: Path, model: Path, out: Path, pin: bool, src: str | None = None) -> tuple[float, float, float]:
    """Wall seconds, peak RSS (MiB) and CPU seconds of one ``pursuit track --stream``."""
    cmd = [sys.executable, "-m", "pursuit", "track", str(data), "--config", str(model), "--stream", "-o", str(out)]
    return _measure(cmd, pin, src)


def run_peer(data: Path, out: Path, pin: bool) -> tuple[float, float, float] | None:
    """The same of the FilterPy loop, or None where FilterPy is not installed."""
    try:
        import filterpy  # noqa: F401
    except ImportError:
        return None
    return _measure([sys.executable, "-c", PEER, str(data), str(out)], pin)


def main(argv: list[str] | None = None, quick: bool = False) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=int, nargs="+", default=[10_000] if quick else [100_000])
    ap.add_argument("--repeats", type=int, default=1 if quick else 3)
    ap.add_argument("--backends", nargs="+", default=["numpy", "numba"])
    ap.add_argument("--formats", nargs="+", default=["csv", "jsonl"])
    ap.add_argument("--no-pin", action="store_true", help="do not pin the child to core 1")
    ap.add_argument("--no-peer", action="store_true", help="leave out the FilterPy loop")
    ap.add_argument(
        "--before", metavar="SRC", help="also run pursuit from this src folder (another checkout: the code before a change), in the same run"
    )
    args = ap.parse_args(argv if argv is not None else [])
    os.environ.setdefault("NUMBA_CACHE_DIR", str(Path(tempfile.gettempdir()) / "pursuit-bench-numba"))
    pin = not args.no_pin
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        models = {}
        small = folder / "small"
        small.mkdir()
        start_inputs = write_inputs(small, 100)
        startup = {}
        versions = [("", None)] + ([(" (before)", args.before)] if args.before else [])
        for b in args.backends:
            models[b] = folder / f"model-{b}.toml"
            models[b].write_text(MODEL.format(backend=b))
            for tag, src in versions:
                run_once(start_inputs["csv"], models[b], small / "out.csv", pin, src)  # warms the numba cache: no compile measured
                startup[b, tag] = _medians([run_once(start_inputs["csv"], models[b], small / "out.csv", pin, src) for _ in range(args.repeats)])
        print("Start-up: the whole command on 100 records (CSV).\n")
        print("| run | wall, s | CPU, s | peak RSS, MiB |")
        print("|---|---:|---:|---:|")
        for (b, tag), (wall, rss, cpu) in startup.items():
            print(f"| pursuit track --stream, {b}{tag} | {wall:.2f} | {cpu:.2f} | {rss:.0f} |")
        print()
        print(
            "Records/s = records / time of the whole command: wall time, and CPU time (user + system) *after start-up*, "
            "which subtracts the CPU time of the same command on 100 records (interpreter, imports, model: paid once by a "
            "long stream); CPU time is the steadier figure on a shared machine. Peak RSS is the child's ru_maxrss. "
            f"Medians of {args.repeats}; one core (`taskset -c 1`). The ratio is to the FilterPy loop's CPU rate after start-up.\n"
        )
        print("| records | format | run | records/s, wall | records/s, CPU after start-up | vs FilterPy loop | peak RSS, MiB |")
        print("|---|---|---|---:|---:|---:|---:|")
        for n in args.records:
            inputs = write_inputs(folder, n)
            peer_rate = None
            if not args.no_peer and run_peer(start_inputs["csv"], small / "peer.csv", pin) is not None:
                peer_start = _medians([run_peer(start_inputs["csv"], small / "peer.csv", pin) for _ in range(args.repeats)])
                peer = _medians([run_peer(inputs["csv"], folder / "peer.csv", pin) for _ in range(args.repeats)])
                peer_rate = n / max(peer[2] - peer_start[2], 1e-9)
                print(f"| {n:,} | csv | FilterPy loop (peer) | {n / peer[0]:,.0f} | {peer_rate:,.0f} | 1 | {peer[1]:.0f} |")
            for fmt in args.formats:
                for b in args.backends:
                    for tag, src in versions:
                        runs = [run_once(inputs[fmt], models[b], folder / f"out.{fmt}", pin, src) for _ in range(args.repeats)]
                        wall, rss, cpu = _medians(runs)
                        rate = n / max(cpu - startup[b, tag][2], 1e-9)
                        ratio = f"{rate / peer_rate:.2f}" if peer_rate else "-"
                        print(f"| {n:,} | {fmt} | pursuit track --stream, {b}{tag} | {n / wall:,.0f} | {rate:,.0f} | {ratio} | {rss:.0f} |", flush=True)


def _medians(runs: list[tuple[float, float, float]]) -> tuple[float, float, float]:
    """Median wall and CPU seconds, and the largest peak RSS, of repeated runs."""
    return statistics.median(r[0] for r in runs), max(r[1] for r in runs), statistics.median(r[2] for r in runs)

if __name__ == "__main__":
    main(sys.argv[1:])
