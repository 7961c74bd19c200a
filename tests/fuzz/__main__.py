"""``python -m tests.fuzz --cases 2000 --seed 7``: run the fuzzer and print its table.

Run from the repository root with the sources first on the path
(``PYTHONPATH=src python -m tests.fuzz``).  ``--show N`` prints up to N failing cases of each
group with a reproducer (the files and the ``pursuit`` arguments).
"""

from __future__ import annotations

import argparse
import sys
import time

from .runner import KINDS, failures, run, run_every_mutation, table


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m tests.fuzz", description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=300, help="cases in all, split over the kinds (default 300)")
    p.add_argument("--seed", type=int, default=0, help="root seed: the same seed runs the same cases")
    p.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS), help="which inputs to fuzz")
    p.add_argument("--max-seconds", type=float, help="stop starting new cases after this long")
    p.add_argument("--full", action="store_true", help="also run every accepted configuration through `pursuit run` (slow: figures)")
    p.add_argument("--every-mutation", action="store_true", help="run each model and config mutation once on every base (no sampling)")
    p.add_argument("--show", type=int, default=1, help="reproducers shown per failing group (default 1)")
    args = p.parse_args(argv)
    start = time.monotonic()
    if args.every_mutation:
        outcomes = run_every_mutation(tuple(args.kinds), args.max_seconds)
        print(f"{len(outcomes)} cases (every mutation), {time.monotonic() - start:.1f} s\n")
    else:
        outcomes = run(args.cases, args.seed, tuple(args.kinds), args.max_seconds, args.full)
        print(f"{len(outcomes)} cases, seed {args.seed}, {time.monotonic() - start:.1f} s\n")
    print(table(outcomes))
    groups = failures(outcomes)
    if groups:
        print(f"\n{sum(len(v) for v in groups.values())} failing cases in {len(groups)} groups:")
    for (kind, outcome, reason), cases in sorted(groups.items()):
        print(f"\n## {kind} / {outcome} ({len(cases)}): {reason}")
        for o in cases[: args.show]:
            print(f"   case: {o.name}")
            if o.why.strip() and o.why.strip() != reason:
                print("   why: " + o.why.strip().replace("\n", "\n        ")[-600:])
            for fname, text in o.reproducer.get("files", {}).items():
                print(f"   --- {fname}\n" + "".join(f"   | {ln}\n" for ln in text.splitlines()[:40]), end="")
            print("   $ pursuit " + " ".join(o.reproducer.get("argv", [])))
    return 1 if groups else 0


if __name__ == "__main__":
    sys.exit(main())
