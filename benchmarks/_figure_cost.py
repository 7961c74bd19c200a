"""CPU time of saving an experiment's figures: PNG, PDF with its own layout, PDF with the PNG's layout.

``PYTHONPATH=src MPLBACKEND=Agg taskset -c 1 python benchmarks/_figure_cost.py p1-wsn 2``
runs the experiment with few runs (the figures' cost hardly depends on it),
then saves each figure to memory three ways and prints the CPU seconds
(``time.process_time``, so a loaded machine inflates it less than wall time).
``pursuit.report.output.save_figure`` does the first and the third.
"""

from __future__ import annotations

import io
import sys
import time

from pursuit.experiment import find_experiment, load_experiment


def main() -> None:
    name, runs = sys.argv[1], int(sys.argv[2])
    out = load_experiment(find_experiment(name)).run(runs=runs)
    totals = [0.0, 0.0, 0.0]
    for fname, fig in out.figures.items():
        cost = []
        for fmt, frozen in (("png", False), ("pdf", False), ("pdf", True)):
            if frozen:
                fig.set_layout_engine("none")  # the layout the draws above made
            t = time.process_time()
            fig.savefig(io.BytesIO(), format=fmt, dpi=150)
            cost.append(time.process_time() - t)
        totals = [a + b for a, b in zip(totals, cost)]
        print(f"{fname:34s} png {cost[0]:.2f}  pdf {cost[1]:.2f}  pdf with the png's layout {cost[2]:.2f}")
    print(f"{name}: {len(out.figures)} figures, CPU s: png {totals[0]:.2f}, pdf {totals[1]:.2f}, "
          f"pdf with the png's layout {totals[2]:.2f} ({totals[2] / totals[1]:.2f}x)")


if __name__ == "__main__":
    main()
