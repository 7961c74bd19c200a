"""plot_track: one track in the plane, with its covariance ellipses; and ``pursuit track --plot``."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from pursuit import Track
from pursuit.cli import main
from pursuit.report.figures import figure_problems
from pursuit.report.track_plot import ellipse_axes, plot_track

from ..io.conftest import EXAMPLES

WSN = [str(EXAMPLES / "data" / "wsn-range.csv"), "-c", str(EXAMPLES / "wsn-range.toml")]


def test_ellipse_axes_are_sigma_times_the_standard_deviations():
    w, h, angle = ellipse_axes(np.diag([9.0, 1.0]), 2.0)
    assert (w, h) == pytest.approx((12.0, 4.0)) and angle % 180 == pytest.approx(0.0)
    # rotated by 30°: the long axis turns with it
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    Rot = np.array([[c, -s], [s, c]])
    w, h, angle = ellipse_axes(Rot @ np.diag([9.0, 1.0]) @ Rot.T, 1.0)
    assert (w, h) == pytest.approx((6.0, 2.0)) and angle % 180 == pytest.approx(30.0)


def _track(K=40):
    t = np.arange(K)
    mean = np.stack([t * 1.0, np.ones(K), 0.02 * t**2, 0.04 * t], axis=-1)
    cov = np.broadcast_to(np.diag([4.0, 0.1, 1.0, 0.1]), (K, 4, 4)).copy()
    return Track(mean, cov, name="demo")


def test_plot_track_draws_everything_a_reader_needs():
    tr = _track()
    truth = tr.mean[:, [0, 2]] + 0.5
    fig = plot_track(tr, measurements=truth + 1.0, truth=truth, sensors=[[0.0, 0.0], [40.0, 0.0]], sigma=2.0, ellipses=10)
    assert isinstance(fig, Figure) and figure_problems(fig) == []
    ax = fig.axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (m)", "y (m)")
    ellipses = [p for p in ax.patches if isinstance(p, Ellipse)]
    assert len(ellipses) == 10  # every 4th of 40 estimates
    assert ellipses[0].width == pytest.approx(2 * 2 * 2.0) and ellipses[0].height == pytest.approx(2 * 2 * 1.0)
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts == ["sensors", "measurements", "truth", "estimate", "first estimate", "2σ position ellipse (86.5 %, every 4th estimate)"]


def test_plot_track_on_given_axes_and_bad_shapes():
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_track(_track(5), ax=ax, ellipses=0) is fig
    assert not [p for p in ax.patches if isinstance(p, Ellipse)] and ax.get_legend() is not None
    with pytest.raises(ValueError, match="one run"):
        plot_track(Track(np.zeros((5, 3, 4)), None))


def test_track_plot_writes_a_png(tmp_path, capsys):
    png = tmp_path / "track.png"
    truth = str(EXAMPLES / "data" / "wsn-range-truth.csv")
    assert main(["track", *WSN, "--plot", str(png), "--truth", truth]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["track.png"]  # no temporary file left


@pytest.mark.parametrize(
    "name, message",
    [("track.jpeg", "cannot tell the figure format; name it .png, .pdf or .svg"), ("no/such/track.png", "cannot write: no folder")],
)
def test_a_bad_plot_name_stops_before_anything_is_written(tmp_path, capsys, name, message):
    out = tmp_path / "est.csv"
    assert main(["track", *WSN, "--plot", str(tmp_path / name), "-o", str(out)]) == 2
    assert not out.exists()
    assert message in capsys.readouterr().err


def test_a_wide_path_gets_a_wide_figure():
    K = 50
    t = np.arange(K, dtype=float)
    wide = Track(np.stack([10 * t, np.ones(K), t, np.ones(K)], axis=-1), None)
    square = Track(np.stack([t, np.ones(K), t, np.ones(K)], axis=-1), None)
    fw, fs = plot_track(wide), plot_track(square)
    assert fw.get_figwidth() == fs.get_figwidth()
    assert fw.get_figheight() < 0.6 * fs.get_figheight()


def test_a_runaway_estimate_does_not_set_the_axes_and_is_marked():
    from pursuit.report.figures import LEAVES_LABEL, VIEW_MARGIN

    tr = _track()
    truth = tr.mean[:, [0, 2]].copy()
    mean = tr.mean.copy()
    mean[30:, 0] = 10.0 ** np.arange(1, 11)  # runs away to 1e10 m
    fig = plot_track(Track(mean, tr.cov, name="runaway"), truth=truth, sensors=[[0.0, 0.0]])
    assert figure_problems(fig) == []
    ax = fig.axes[0]
    lo, hi = truth.min(axis=0), truth.max(axis=0)
    margin = VIEW_MARGIN * float(np.max(hi - lo))
    assert ax.get_xlim() == pytest.approx((lo[0] - margin, hi[0] + margin))
    assert ax.get_ylim() == pytest.approx((lo[1] - margin, hi[1] + margin))
    assert [c for c in ax.collections if c.get_label() == LEAVES_LABEL]
    assert LEAVES_LABEL in [t.get_text() for t in fig.legends[0].get_texts()]
