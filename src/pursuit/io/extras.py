"""``pursuit track --truth FILE`` and ``--plot FILE``: what happens after the estimates are written.

Both are checked before any record is read (a truth file is read whole, a
plot's folder and format looked at), so a mistake in them stops the command
before it writes anything.  After a successful run the truth score goes to
standard error (standard output may be carrying the estimates) and the
figure is written whole or not at all (a temporary file beside it, renamed
into place).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Iterator, TextIO

import numpy as np

from .output_file import replace_with
from .records import Record
from .truth import Truth, TruthError, format_score, read_truth, score

__all__ = ["Extras", "PLOT_FORMATS"]

PLOT_FORMATS = (".png", ".pdf", ".svg")


class Extras:
    """The truth file and plot of one ``pursuit track`` run.

    Use :meth:`prepare`, pass the records through :meth:`watch`, append the
    estimates written to :attr:`estimates`, and call :meth:`finish`.
    """

    def __init__(self, model: Any, truth: Truth | None, plot: str | None):
        self.model = model
        self.truth = truth
        self.plot = plot
        self.estimates: list[Any] = []
        self._fixes: list[tuple[float, float]] = []

    @classmethod
    def prepare(cls, args: Any, model: Any) -> Extras:
        """Read the truth file and check the plot's name; ``ValueError`` names the file and field."""
        truth = read_truth(args.truth, model.state_labels) if getattr(args, "truth", None) else None
        plot = getattr(args, "plot", None)
        if plot:
            if Path(plot).suffix.lower() not in PLOT_FORMATS:
                raise ValueError(f"{plot}: --plot: cannot tell the figure format; name it .png, .pdf or .svg")
            folder = Path(plot).parent
            if not folder.is_dir():
                raise ValueError(f"{plot}: cannot write: no folder {str(folder)!r}")
            if len(model.position_indices) < 2:
                raise ValueError(f"{plot}: --plot draws the x-y plane; this model has {len(model.position_indices)} axis")
        return cls(model, truth, plot)

    @property
    def sink(self) -> list[Any] | None:
        """Where the run appends its estimates, or None when neither --truth nor --plot needs them."""
        return self.estimates if (self.truth is not None or self.plot) else None

    def watch(self, records: Iterable[Any]) -> Iterator[Any]:
        """Pass the records on, keeping the position fixes for the plot."""
        if not self.plot:
            yield from records
            return
        kinds = {sid: s.type for sid, s in self.model.sensors.items()}
        for r in records:
            if isinstance(r, Record) and r.sensor is not None and kinds.get(r.sensor) == "position" and len(r.values) >= 2:
                if np.isfinite(r.values[0]) and np.isfinite(r.values[1]):
                    self._fixes.append((float(r.values[0]), float(r.values[1])))
            yield r

    def finish(self, stderr: TextIO) -> int:
        """Print the truth score and write the plot; the exit code (2 when either fails)."""
        code = 0
        if self.truth is not None and self.estimates:
            try:
                s = score(self.estimates, self.truth, self._kinds())
                for line in format_score(s, self.truth):
                    print(f"pursuit track: {line}", file=stderr)
            except TruthError as e:
                print(f"pursuit track: error: {e}", file=stderr)
                code = 2
        if self.plot and self.estimates:
            try:
                self._write_plot()
            except OSError as e:
                print(f"pursuit track: error: {self.plot}: cannot write: {e.strerror or e}", file=stderr)
                code = 2
        return code

    def _kinds(self) -> dict[str, tuple[int, ...]]:
        m = self.model
        kinds = {"position": tuple(m.position_indices), "velocity": tuple(m.velocity_indices)}
        acc = getattr(m.motion, "acceleration_indices", None)
        if acc:
            kinds["acceleration"] = tuple(acc)
        return kinds

    def _write_plot(self) -> None:
        from ..report.track_plot import plot_track
        from ..track import Track

        m = self.model
        i, j = m.position_indices[:2]
        track = Track(
            mean=np.array([e.mean for e in self.estimates]),
            cov=np.array([e.cov for e in self.estimates]),
            name=m.name,
        )
        truth_xy = None
        if self.truth is not None and {m.state_labels[i], m.state_labels[j]} <= set(self.truth.labels):
            cols = [self.truth.labels.index(m.state_labels[k]) for k in (i, j)]
            truth_xy = self.truth.states[:, cols]
        sensors = [s.position[:2] for s in m.sensors.values() if s.position is not None]
        fig = plot_track(
            track,
            measurements=np.array(self._fixes) if self._fixes else None,
            truth=truth_xy,
            sensors=np.array(sensors) if sensors else None,
            position_indices=(i, j),
            labels=(m.state_labels[i], m.state_labels[j]),
            title=f"{m.name}: {len(self.estimates)} estimates",
        )
        replace_with(self.plot, lambda tmp: fig.savefig(tmp, dpi=150))  # written whole or not at all
