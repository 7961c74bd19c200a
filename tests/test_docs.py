"""Every ```python block in README.md and docs/*.md runs.

The blocks of one file run in order in one namespace, like a notebook.
Blocks fenced as ```py are illustrative and not run (for example one that
would register a component in the global registry).
"""

import re
from pathlib import Path

import matplotlib
import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


@pytest.mark.parametrize("path", [p for p in FILES if BLOCK.search(p.read_text())], ids=lambda p: p.name)
def test_documented_python_runs(path, tmp_path, monkeypatch):
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__doc__"}
    for i, m in enumerate(BLOCK.finditer(path.read_text())):
        exec(compile(m.group(1), f"{path.name}[block {i}]", "exec"), namespace)
