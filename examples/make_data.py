"""Regenerate the example data sets under examples/data with pursuit's own simulator.

    python examples/make_data.py [OUTDIR]      (default: examples/data)

Two data sets, each as a CSV file (a recording) and as JSON Lines (the same
records as a live stream would deliver them), with the true trajectory beside
them for checking:

* ``wsn-range``: the ``wsn-range`` scenario (a constant-velocity target among
  four range anchors at the corners of a 100 m square, 1 m range noise,
  one ranging round per second for 60 s), simulated by
  :class:`pursuit.scenarios.WSNRange`; then each anchor's report is lost with
  probability 0.15 (packet loss), so some times have fewer than four sensors.
* ``underwater-toa``: a constant-velocity target in the L-shaped hydrophone
  array A(0, 0), B(0, 50), C(50, 0) of paper P2, travel times with
  sigma_t = 1e-5 s (c = 1500 m/s), pings at irregular intervals of 0.5-1.5 s
  (times rounded to the millisecond), drawn with pursuit's models
  (ConstantVelocity.sample with each step's dt, TimeOfArrival.sample).  One
  echo at about t = 15 s arrives 5 ms late at hydrophone B: a multipath
  outlier that the example's chi-square gate rejects.

``wsn-range-damaged.csv`` is ``wsn-range.csv`` with four lines spoiled the
way real logs get spoiled (an infinite value, an unknown sensor, a line cut
short, a garbled number), for the validation example in docs/track.md.

Every number comes from fixed seeds, so running this again gives the shipped
files (tests/io/test_examples.py checks it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from pursuit.models import ConstantVelocity, TimeOfArrival
from pursuit.scenarios import WSNRange

WSN_SEED = 20260701
TOA_SEED = 20260702
WSN_ANCHORS = {"A1": (0.0, 0.0), "A2": (100.0, 0.0), "A3": (0.0, 100.0), "A4": (100.0, 100.0)}
TOA_ARRAY = {"A": (0.0, 0.0), "B": (0.0, 50.0), "C": (50.0, 0.0)}
LABELS = ("x", "vx", "y", "vy")


def wsn_range() -> tuple[list[tuple[float, str, float]], np.ndarray, np.ndarray]:
    """Records (time, sensor, range), times and truth of the WSN example."""
    scenario = WSNRange(
        anchors=np.array(list(WSN_ANCHORS.values())),
        sigma=1.0,
        steps=60,
        dt=1.0,
        q=0.01,
        x0=np.array([10.0, 0.5, 40.0, 0.8]),
        prior_mean="truth",
    )
    rng = np.random.default_rng(WSN_SEED)
    sim = scenario.simulate(rng, runs=1)
    lost = rng.random(sim.measurements.shape) < 0.15
    records = []
    for k, t in enumerate(sim.times):
        for j, sensor in enumerate(WSN_ANCHORS):
            if not lost[k, 0, j]:
                records.append((float(t), sensor, float(sim.measurements[k, 0, j])))
    return records, sim.times, sim.truth[:, 0]


def underwater_toa() -> tuple[list[tuple[float, str, float]], np.ndarray, np.ndarray]:
    """Records (time, hydrophone, travel time), times and truth of the TOA example."""
    rng = np.random.default_rng(TOA_SEED)
    times = np.round(np.cumsum(rng.uniform(0.5, 1.5, 60)), 3)
    dts = np.diff(np.concatenate([[0.0], times]))
    motion = ConstantVelocity(ndim=2, q=1e-4)
    sensors = TimeOfArrival(np.array(list(TOA_ARRAY.values())), 1e-5, c=1500.0)
    x = np.array([[10.0, 0.5, 20.0, 0.4]])
    truth, records = [], []
    for k, dt in enumerate(dts, start=1):
        x = motion.sample(x, k, rng, dt=float(dt))
        z = sensors.sample(x, k, rng)[0]
        truth.append(x[0])
        for j, name in enumerate(TOA_ARRAY):
            records.append((float(times[k - 1]), name, float(z[j])))
    # A multipath echo: hydrophone B hears the ping nearest t = 15 s 5 ms late.
    i = int(np.argmin(np.abs(times - 15.0)))
    t_out = float(times[i])
    records = [(t, s, v + 5e-3 if (t == t_out and s == "B") else v) for t, s, v in records]
    return records, times, np.array(truth)


def write(outdir: Path, name: str, records, times, truth) -> None:
    """Write NAME.csv, NAME.jsonl and NAME-truth.csv."""
    with open(outdir / f"{name}.csv", "w", newline="") as f:
        f.write("time,sensor,value\n")
        for t, s, v in records:
            f.write(f"{t!r},{s},{v!r}\n")
    with open(outdir / f"{name}.jsonl", "w") as f:
        for t, s, v in records:
            f.write(json.dumps({"time": t, "sensor": s, "value": v}) + "\n")
    with open(outdir / f"{name}-truth.csv", "w", newline="") as f:
        f.write("time," + ",".join(LABELS) + "\n")
        for t, x in zip(times, truth):
            f.write(",".join(repr(float(v)) for v in (t, *x)) + "\n")


def damage(outdir: Path, name: str) -> None:
    """NAME-damaged.csv: NAME.csv with four spoiled lines (line numbers count the header as 1)."""
    lines = (outdir / f"{name}.csv").read_text().splitlines()

    def spoil(lineno: int, how) -> None:
        t, sensor, value = lines[lineno - 1].split(",")
        lines[lineno - 1] = how(t, sensor, value)

    spoil(6, lambda t, s, v: f"{t},{s},inf")
    spoil(11, lambda t, s, v: f"{t},A5,{v}")
    spoil(17, lambda t, s, v: f"{t},{s}")
    spoil(25, lambda t, s, v: f"{t},{s},{v[:5]}.{v[5:8]}")
    (outdir / f"{name}-damaged.csv").write_text("\n".join(lines) + "\n")


def main(argv: list[str]) -> int:
    """Write the data sets; ``argv`` as ``sys.argv`` (program name first)."""
    parser = argparse.ArgumentParser(
        prog=Path(argv[0]).name if argv else "make_data.py",
        description="Regenerate the example data sets (CSV, JSON Lines and the true trajectories) with "
        "pursuit's own simulator, from fixed seeds.",
    )
    parser.add_argument(
        "outdir", nargs="?", type=Path, default=Path(__file__).parent / "data",
        help="folder to write (default: examples/data beside this script)",
    )
    outdir = parser.parse_args(argv[1:]).outdir
    outdir.mkdir(parents=True, exist_ok=True)
    write(outdir, "wsn-range", *wsn_range())
    write(outdir, "underwater-toa", *underwater_toa())
    damage(outdir, "wsn-range")
    print(f"wrote {outdir}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
