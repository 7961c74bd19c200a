"""Saving figures (pursuit.report.output.save_figure)."""

from __future__ import annotations

from matplotlib.figure import Figure

from pursuit.report.output import save_figure


def _figure() -> Figure:
    fig = Figure(figsize=(4.0, 3.0), layout="constrained")
    ax = fig.subplots()
    ax.semilogy([0, 1, 2, 3], [1.0, 30.0, 2.0, 0.5], label="estimate")
    ax.set(xlabel="time [s]", ylabel="position RMSE [m]", title="a title long enough to need the layout")
    ax.legend()
    return fig


def test_later_formats_are_drawn_once_with_the_first_ones_layout(tmp_path, monkeypatch):
    """The PNG is laid out and drawn; the PDF is drawn once with that layout, the same bytes as a PDF saved with the
    engine merely switched off; the figure keeps its layout engine."""
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")  # no creation date in the PDFs: comparable bytes
    fig = _figure()
    engine = fig.get_layout_engine()
    draws = []
    plain_draw = fig.draw
    monkeypatch.setattr(fig, "draw", lambda renderer: (draws.append(type(renderer).__name__), plain_draw(renderer)))
    save_figure(fig, [tmp_path / "f.png", tmp_path / "f.pdf"])
    assert len(draws) == 3  # PNG: layout draw + render; PDF: render only
    assert fig.get_layout_engine() is engine
    fig.set_layout_engine("none")  # what save_figure did before: the placeholder engine, one more draw
    fig.savefig(tmp_path / "ref.pdf", dpi=150)
    assert (tmp_path / "f.pdf").read_bytes() == (tmp_path / "ref.pdf").read_bytes()
    assert (tmp_path / "f.png").stat().st_size > 0


def test_one_format_is_saved_as_savefig_saves_it(tmp_path):
    fig = _figure()
    engine = fig.get_layout_engine()
    save_figure(fig, [tmp_path / "f.png"])
    save_figure(fig, [])
    assert fig.get_layout_engine() is engine and (tmp_path / "f.png").stat().st_size > 0
