"""The wheel carries what an installed pursuit needs: typing marker, licence, experiments, examples."""

from __future__ import annotations

import email
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import pursuit

ROOT = Path(__file__).resolve().parents[1]


def test_examples_dir_in_a_source_checkout():
    assert pursuit.examples_dir() == ROOT / "examples"
    assert (pursuit.examples_dir() / "wsn-range.toml").is_file()


def test_licence_file_is_bsd_3_clause():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "pursuit developers" in text


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    pytest.importorskip("hatchling", reason="building the wheel needs hatchling (in the `test` extra)")
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "--no-build-isolation", "--no-index", "-q", "-w", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    [whl] = out.glob("pursuit-*.whl")
    return whl


def test_wheel_contents(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "pursuit/py.typed" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    for folder, packaged in (("examples", "pursuit/_examples"), ("experiments", "pursuit/_experiments")):
        files = [p.relative_to(ROOT / folder).as_posix() for p in (ROOT / folder).rglob("*") if p.is_file() and "__pycache__" not in p.parts]
        assert files, folder
        missing = [f for f in files if f"{packaged}/{f}" not in names]
        assert not missing, f"{folder}/ files not in the wheel: {missing}"


def test_wheel_metadata(wheel):
    with zipfile.ZipFile(wheel) as z:
        [meta] = [n for n in z.namelist() if n.endswith(".dist-info/METADATA")]
        msg = email.message_from_bytes(z.read(meta))
    classifiers = msg.get_all("Classifier")
    assert "License :: OSI Approved :: BSD License" in classifiers
    assert "Typing :: Typed" in classifiers
    assert len(classifiers) >= 8
    assert msg["License"] == "BSD-3-Clause"


def test_installed_wheel_finds_its_examples(wheel, tmp_path):
    # A wheel unpacked onto sys.path is what pip installs (less the console script).
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    env = dict(os.environ, PYTHONPATH=str(site))
    code = "import pursuit; d = pursuit.examples_dir(); print(d); print((d / 'data' / 'wsn-range.csv').is_file())"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    where, has_data = proc.stdout.split()
    assert Path(where) == site / "pursuit" / "_examples"
    assert has_data == "True"
