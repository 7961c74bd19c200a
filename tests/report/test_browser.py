"""The HTML report in a real headless browser: loads cleanly, every figure decodes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pursuit.cli import main

from .browser import Browser

EXPERIMENT = Path(__file__).resolve().parents[2] / "experiments" / "wsn-gaussian.toml"


@pytest.fixture(scope="module")
def output(tmp_path_factory) -> Path:
    """A real output folder: wsn-gaussian (few runs) with a paper-value table added."""
    tmp = tmp_path_factory.mktemp("browser")
    config = tmp / "wsn-paper.toml"
    config.write_text(
        EXPERIMENT.read_text()
        + '\n[[paper]]\nfilter = "EKF"\nmetric = "rmse_position"\nvalue = 0.7\nnote = "made-up reference for the test"\n'
    )
    assert main(["run", str(config), "--runs", "6", "--no-progress", "-o", str(tmp / "out" / "wsn-paper")]) == 0
    return tmp / "out" / "wsn-paper"


def _image_states(browser: Browser) -> list[dict]:
    return browser.evaluate(
        "Array.from(document.images).map(i => ({alt: i.alt, complete: i.complete,"
        " width: i.naturalWidth, height: i.naturalHeight, inline: i.src.startsWith('data:image/png;base64,')}))"
    )


def test_report_loads_without_errors_and_every_image_decodes(chromium, artifacts, output):
    sidecar = json.loads((output / "run.json").read_text())
    with Browser(chromium) as browser:
        browser.open((output / "report.html").as_uri())
        images = _image_states(browser)
        assert [i["alt"] for i in images] == sidecar["figures"]
        for img in images:
            assert img["complete"] and img["inline"], img
            assert img["width"] > 0 and img["height"] > 0, img
        text = browser.evaluate("document.body.innerText")
        assert str(sidecar["seed"]) in text and "numpy" in text and "Paper against measured" in text
        assert browser.evaluate("document.querySelectorAll('table.paper').length") == 1
        assert browser.evaluate("document.querySelectorAll('script').length") == 0
        shot = browser.screenshot(artifacts / "report-wsn-gaussian.png")
        errors = browser.console_errors()
    assert errors == []
    assert shot.stat().st_size > 10_000


def test_broken_image_is_detected(chromium, tmp_path):
    """The check can fail: a page with a corrupt embedded PNG has naturalWidth 0."""
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><head><link rel="icon" href="data:,"></head>'
                    '<body><img alt="bad" src="data:image/png;base64,iVBORw0KGgoAAAAA"></body></html>')
    with Browser(chromium) as browser:
        browser.open(page.as_uri())
        images = _image_states(browser)
    assert images[0]["complete"] and images[0]["width"] == 0


def test_index_page_links_every_report(chromium, artifacts, output):
    from pursuit.report.html import write_index

    index = write_index(output.parent, [output])
    with Browser(chromium) as browser:
        browser.open(index.as_uri())
        links = browser.evaluate("Array.from(document.links).map(a => a.href)")
        browser.screenshot(artifacts / "index.png")
        errors = browser.console_errors()
    assert errors == []
    assert links == [(output / "report.html").as_uri()]


def _wide_output(folder: Path) -> Path:
    """An output folder whose summary table is as wide as p3-upf's (18 columns, with the diverged-run counts)."""
    from pursuit.report.output import write_output
    from pursuit.tables import ExperimentOutput, Table

    cols = ["variant", "l", "filter", "rmse", "ci95", "rms_x", "rms_vx", "rms_y", "rms_vy", "rmse_position",
            "rmse_velocity", "diverged", "diverged_from_step", "nis_mean", "ess_mean", "resample_rate", "wall_time_s", "runs"]
    rows = [["4 corner nodes", 0.25, "UPF-local", 50.86116476155978, 7.463904868788435, 45.55308448769722, 0.8836507929462359,
             22.62243520400156, 0.5517066736015148, 50.86116476155978, 1.04173844009471, 100, 100, 0.995416478342234,
             121.25971906888066, 0.3147, 111.1715915089999953, 100]] * 4
    out = ExperimentOutput("wide", "Wide tables", "", [Table("summary", "Summary", cols, rows)], {}, {}, sidecar={"seed": 1, "runs": 100})
    return write_output(out, folder / "wide")


def test_wide_tables_fit_a_1400_px_window(chromium, artifacts, tmp_path):
    """p1-wsn's and p3-upf's tables scrolled sideways at 1400 px: the page must fit without a horizontal scroll."""
    folder = _wide_output(tmp_path)
    with Browser(chromium) as browser:
        browser.call("Emulation.setDeviceMetricsOverride", width=1400, height=1000, deviceScaleFactor=1, mobile=False)
        browser.open((folder / "report.html").as_uri())
        widths = browser.evaluate(
            "({page: document.documentElement.scrollWidth, view: document.documentElement.clientWidth,"
            " tables: Array.from(document.querySelectorAll('table')).map(t => [t.parentElement.scrollWidth, t.parentElement.clientWidth])})"
        )
        browser.screenshot(artifacts / "report-wide-table-1400.png")
    assert widths["view"] == 1400
    assert widths["page"] <= widths["view"], widths
    for scroll, client in widths["tables"]:
        assert scroll <= client, widths
