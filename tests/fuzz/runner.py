"""Running a seeded, bounded batch of fuzz cases and tabulating the outcomes."""

from __future__ import annotations

import random
import tempfile
import time
from collections import Counter
from pathlib import Path

from . import config_cases, model_cases, track_cases
from .common import FAILURES, OUTCOMES, Outcome

KINDS = ("track", "model", "config")
# Share of the cases each kind gets: the track cases are the cheapest (a few ms each).
WEIGHTS = {"track": 0.6, "model": 0.25, "config": 0.15}


def split(cases: int, kinds=KINDS) -> dict[str, int]:
    """How many of ``cases`` each kind runs."""
    total = sum(WEIGHTS[k] for k in kinds)
    n = {k: int(cases * WEIGHTS[k] / total) for k in kinds}
    n[kinds[0]] += cases - sum(n.values())
    return n


def run(cases: int, seed: int, kinds=KINDS, max_seconds: float | None = None, full: bool = False, progress=None) -> list[Outcome]:
    """Run ``cases`` cases (split over ``kinds``) from ``seed``; stop early after ``max_seconds``.

    The same seed gives the same cases; the time bound only cuts the list short.
    """
    start = time.monotonic()
    outcomes: list[Outcome] = []
    cache: dict = {}
    for kind, n in split(cases, kinds).items():
        rng = random.Random(f"{seed}:{kind}")
        for i in range(n):
            if max_seconds is not None and time.monotonic() - start > max_seconds:
                return outcomes
            with tempfile.TemporaryDirectory(prefix=f"pursuit-fuzz-{kind}-") as d:
                folder = Path(d)
                if kind == "track":
                    o = track_cases.generate(rng, folder)
                elif kind == "model":
                    o = model_cases.generate(rng, folder, cache)
                else:
                    o = config_cases.generate(rng, folder, full)
            outcomes.append(o)
            if progress:
                progress(kind, i + 1, n, o)
    return outcomes


def run_every_mutation(kinds=("model", "config"), max_seconds: float | None = None) -> list[Outcome]:
    """Every model and config mutation on every base, once (no sampling): the exhaustive pass."""
    start = time.monotonic()
    outcomes: list[Outcome] = []
    cache: dict = {}
    cases = [("model", c) for c in model_cases.all_cases() if "model" in kinds]
    cases += [("config", c) for c in config_cases.all_cases() if "config" in kinds]
    for kind, case in cases:
        if max_seconds is not None and time.monotonic() - start > max_seconds:
            break
        with tempfile.TemporaryDirectory(prefix=f"pursuit-fuzz-{kind}-") as d:
            if kind == "model":
                outcomes.append(model_cases.run_case(case, Path(d), cache))
            else:
                outcomes.append(config_cases.run_case(case, Path(d)))
    return outcomes


def table(outcomes: list[Outcome]) -> str:
    """kind × outcome counts as a Markdown table."""
    counts = Counter((o.kind, o.outcome) for o in outcomes)
    kinds = [k for k in KINDS if any(o.kind == k for o in outcomes)]
    head = "| kind | cases | " + " | ".join(OUTCOMES) + " |"
    rule = "|---|---:|" + "---:|" * len(OUTCOMES)
    rows = []
    for k in kinds:
        n = sum(counts[(k, c)] for c in OUTCOMES)
        rows.append(f"| {k} | {n} | " + " | ".join(str(counts[(k, c)]) for c in OUTCOMES) + " |")
    n = len(outcomes)
    rows.append("| all | " + str(n) + " | " + " | ".join(str(sum(counts[(k, c)] for k in kinds)) for c in OUTCOMES) + " |")
    return "\n".join([head, rule, *rows])


def failures(outcomes: list[Outcome]) -> dict[tuple[str, str, str], list[Outcome]]:
    """Failing cases grouped by (kind, class, first line of the reason)."""
    groups: dict[tuple[str, str, str], list[Outcome]] = {}
    for o in outcomes:
        if o.outcome in FAILURES:
            reason = o.why.strip().splitlines()[-1] if o.outcome == "traceback" and o.why.strip() else o.why.strip().split("\n")[0]
            key = (o.kind, o.outcome, reason[:160] if o.kind == "track" else o.name)
            groups.setdefault(key, []).append(o)
    return groups
