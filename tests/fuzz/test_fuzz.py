"""The fuzz suite in the test command: a few hundred seeded cases, no traceback, no silent wrong
answer, no partial output, none over its time limit (see docs/testing.md).

Each kind is its own test so that a failure names the kind; the assertion message is the
outcome table and one reproducer per failing group.  More cases on demand:
``PYTHONPATH=src python -m tests.fuzz --cases 2000 --seed 7``.
"""

from __future__ import annotations

import pytest

from .common import FAILURES
from .runner import failures, run, table

SEED = 16  # issue 16
CASES = {"track": 120, "model": 60, "config": 30}


def _report(outcomes) -> str:
    lines = [table(outcomes)]
    for (kind, outcome, reason), cases in sorted(failures(outcomes).items()):
        o = cases[0]
        argv = " ".join(o.reproducer.get("argv", []))
        lines.append(f"{kind} / {outcome} x{len(cases)}: {o.name}: {o.why.strip()[-300:]}  $ pursuit {argv}")
    return "\n".join(lines)


@pytest.mark.parametrize("kind", sorted(CASES))
def test_fuzz_cases_end_cleanly_or_correctly(kind):
    outcomes = run(CASES[kind], SEED, (kind,))
    assert len(outcomes) == CASES[kind]
    bad = [o for o in outcomes if o.outcome in FAILURES]
    assert not bad, "\n" + _report(outcomes)


def test_the_oracle_is_not_vacuous():
    """The generators reach both sides: inputs refused cleanly and inputs accepted and checked."""
    outcomes = run(40, SEED, ("track",))
    kinds = {o.outcome for o in outcomes}
    assert {"clean error", "accepted, correct"} <= kinds
