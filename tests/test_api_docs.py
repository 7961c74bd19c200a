"""The API reference (docs/api, Sphinx autodoc + napoleon) builds with warnings as errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_api_reference_builds_without_warnings(tmp_path):
    pytest.importorskip("sphinx", reason="the API reference needs Sphinx (the `docs` and `test` extras)")
    out = tmp_path / "html"
    # -W: a docstring that does not parse (an unknown role, bad indentation, a broken reference) fails
    proc = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", "-E",
         "-d", str(tmp_path / "doctrees"), str(ROOT / "docs" / "api"), str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-5000:]
    filters = (out / "filters.html").read_text()
    for name in ("KalmanFilter", "InteractingMultipleModel", "BootstrapParticleFilter"):
        assert f'id="pursuit.filters.{name}"' in filters
    assert 'id="pursuit.results.MonteCarloResult.to_dataframe"' in (out / "results.html").read_text()
    assert 'id="pursuit.examples_dir"' in (out / "top-level.html").read_text()
