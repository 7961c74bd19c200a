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
