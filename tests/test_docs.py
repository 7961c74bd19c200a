"""Every ```python block in README.md and docs/*.md runs, as a reader would run it.

Each block is written to a file and run as a script (``python block.py``, so
``__name__ == "__main__"``) in a fresh temporary folder, in its own process,
with a timeout.  A block therefore has to be complete: its imports, its data.
Two HTML comments on the line before a block change that (see
docs/contributing.md):

* ``<!-- fragment -->``: the block is an excerpt (``state = filt.step(...)``
  with names from the prose); it is compiled, not run.
* ``<!-- continues -->``: the block goes on from the previous block of the same
  file; both run as one script.

Other Python fences (```py, ```python3, ...) are refused, so that no block
escapes the test without saying so.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import pursuit

ROOT = Path(__file__).resolve().parents[1]
FILES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SRC = Path(pursuit.__file__).resolve().parents[1]
TIMEOUT_S = 300

FENCE = re.compile(r"^(?P<indent> *)```(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ \t]*$", re.S | re.M)
MARKER = re.compile(r"<!--\s*(fragment|continues)\s*-->")
OTHER_PYTHON = {"py", "python3", "py3", "ipython", "pycon"}


@dataclass
class Script:
    """One or more consecutive blocks of a file that run as one script."""

    doc: str
    line: int  # 1-based line of the first block's fence
    blocks: list[str] = field(default_factory=list)
    fragment: bool = False

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"

    @property
    def source(self) -> str:
        return "\n".join(self.blocks)


def marker_before(text: str, start: int) -> str | None:
    """The marker in the last non-blank line before offset ``start``, if any."""
    lines = text[:start].rstrip().splitlines()
    m = MARKER.fullmatch(lines[-1].strip()) if lines else None
    return m.group(1) if m else None


def extract(text: str, doc: str) -> list[Script]:
    """The scripts of a Markdown text: ```python blocks joined as their markers say.

    Raises ``ValueError`` naming the line for a Python block fenced otherwise than
    ```python, and for ``continues`` with no runnable block before it.
    """
    scripts: list[Script] = []
    for m in FENCE.finditer(text):
        info = m.group("info").strip().split()[0] if m.group("info").strip() else ""
        line = text.count("\n", 0, m.start()) + 1
        if info in OTHER_PYTHON:
            raise ValueError(f"{doc}:{line}: fence ```{info}: write ```python (and <!-- fragment --> if it should not run)")
        if info != "python":
            continue
        body = re.sub(rf"(?m)^{m.group('indent')}", "", m.group("body"))
        marker = marker_before(text, m.start())
        if marker == "fragment":
            scripts.append(Script(doc, line, [body], fragment=True))
        elif marker == "continues":
            runnable = [s for s in scripts if not s.fragment]
            if not runnable:
                raise ValueError(f"{doc}:{line}: <!-- continues --> but no runnable ```python block before it")
            runnable[-1].blocks.append(body)
        else:
            scripts.append(Script(doc, line, [body]))
    return scripts


def all_scripts() -> list[Script]:
    return [s for path in FILES for s in extract(path.read_text(encoding="utf-8"), path.relative_to(ROOT).as_posix())]


SCRIPTS = all_scripts()


def test_every_doc_block_is_found():
    # The parametrised test below would pass vacuously if the parser found nothing.
    assert sum(not s.fragment for s in SCRIPTS) >= 8
    assert {"README.md", "docs/maneuvering.md", "docs/scale-out.md"} <= {s.doc for s in SCRIPTS}


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda s: s.id)
def test_documented_python_runs(script: Script, tmp_path):
    if script.fragment:
        compile(script.source, script.id, "exec")  # an excerpt still has to be Python
        return
    path = tmp_path / "block.py"
    path.write_text(script.source, encoding="utf-8")
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]))
    try:
        proc = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{script.id}: still running after {TIMEOUT_S} s (make the example smaller)")
    assert proc.returncode == 0, f"{script.id} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    assert "Traceback" not in proc.stderr, f"{script.id} printed a traceback:\n{proc.stderr[-3000:]}"


# -- the extractor itself -----------------------------------------------------------------------------

SAMPLE = """\
Text.

```python
a = 1
```

<!-- continues -->
```python
b = a + 1
```

<!-- fragment -->
```python
state, info = filt.step(state, z, k)
```

```toml
x = 1
```

1. A list item:

   ```python
   c = 3
   ```
"""


def test_extract_joins_continued_blocks_and_marks_fragments():
    scripts = extract(SAMPLE, "sample.md")
    assert [(s.line, s.fragment, s.source) for s in scripts] == [
        (3, False, "a = 1\n\nb = a + 1\n"),
        (13, True, "state, info = filt.step(state, z, k)\n"),
        (23, False, "c = 3\n"),
    ]


@pytest.mark.parametrize("fence", ["py", "python3", "pycon"])
def test_extract_refuses_other_python_fences(fence):
    with pytest.raises(ValueError, match=rf"sample.md:1: fence ```{fence}"):
        extract(f"```{fence}\nx = 1\n```\n", "sample.md")


def test_extract_refuses_continues_without_a_block_before():
    with pytest.raises(ValueError, match="sample.md:2: <!-- continues -->"):
        extract("<!-- continues -->\n```python\nx = 1\n```\n", "sample.md")
