"""CPU time of saving an experiment's figures: PNG, PDF with its own layout, PDF with the PNG's layout (two ways).

``PYTHONPATH=src MPLBACKEND=Agg taskset -c 1 python benchmarks/_figure_cost.py p1-wsn 2``
runs the experiment with few runs (the figures' cost hardly depends on it),
then saves each figure to memory four ways and prints the CPU seconds
(``time.process_time``, so a loaded machine inflates it less than wall time):
PNG; PDF with its own layout; PDF with the PNG's layout, the engine switched
off (``set_layout_engine("none")``, whose placeholder engine still makes
``savefig`` draw twice); the same with the engine removed (one draw).
``pursuit.report.output.save_figure`` does the first and the last.
"""

from __future__ import annotations

import io
import sys
import time

from pursuit.experiment import find_experiment, load_experiment
from pursuit.report.output import _remove_layout_engine


def main() -> None:
    name, runs = sys.argv[1], int(sys.argv[2])
    out = load_experiment(find_experiment(name)).run(runs=runs)
    totals = [0.0, 0.0, 0.0, 0.0]
    for fname, fig in out.figures.items():
        engine = fig.get_layout_engine()
        cost = []
        for fmt, frozen in (("png", None), ("pdf", None), ("pdf", "switched off"), ("pdf", "removed")):
            if frozen == "switched off":
                fig.set_layout_engine("none")  # the layout the draws above made
            elif frozen == "removed":
                _remove_layout_engine(fig)
            t = time.process_time()
            fig.savefig(io.BytesIO(), format=fmt, dpi=150)
            cost.append(time.process_time() - t)
        if engine is not None:
            fig.set_layout_engine(engine)
        totals = [a + b for a, b in zip(totals, cost)]
        print(f"{fname:34s} png {cost[0]:.2f}  pdf {cost[1]:.2f}  pdf with the png's layout {cost[2]:.2f}, "
              f"one draw {cost[3]:.2f}")
    print(f"{name}: {len(out.figures)} figures, CPU s: png {totals[0]:.2f}, pdf {totals[1]:.2f}, "
          f"pdf with the png's layout {totals[2]:.2f} ({totals[2] / totals[1]:.2f}x), "
          f"one draw {totals[3]:.2f} ({totals[3] / totals[1]:.2f}x)")


if __name__ == "__main__":
    main()
