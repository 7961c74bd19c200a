"""Every reference to the specification resolves inside the repository.

The code and the docs cite the paper-reconstruction notes in ``docs/spec/`` as
``docs/spec/03-fading-memory-ekf.md §4.2`` (in Markdown: a link to the file whose text
carries the section, ``[spec 03 §4.2](spec/03-fading-memory-ekf.md)``).  This test fails
when

* the cited file does not exist, or a cited section (§N or §N.M) is not a numbered
  heading of that file;
* a relative Markdown link of the docs (or of README.md) names a file that does not
  exist, or a ``#fragment`` that is not a heading or ``<a id>`` of its target;
* the sources, the docs, the bundled experiments or README.md use the bare shorthand
  ``spec 03`` (a reader cannot tell where that is) or a path to the notes outside
  ``docs/spec/`` (they used to live outside the repository).

Tests and CHANGELOG.md may keep the shorthand (``spec 04 §1``), but it must still resolve.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC_DIR = ROOT / "docs" / "spec"

# "docs/spec/03-fading-memory-ekf.md §4.2", "... §4.2 and §4.3", "... §7 (U6)"
PATH_REF = re.compile(
    r"(?P<prefix>[\w./-]*?)(?<![\w-])spec/(?P<file>\d\d-[\w.-]+?\.md)"
    r"(?P<sections>(?:\s*(?:,|and|or|/)?\s*§\s*\d+(?:\.\d+)*)*)"
)
SECTION = re.compile(r"§\s*(\d+(?:\.\d+)*)")
# "spec 03", "Spec 04 §3", "spec 02 U6" (the shorthand: resolvable only by convention)
SHORTHAND = re.compile(r"\b[Ss]pec\s+(?P<num>\d\d)\b(?P<sections>(?:\s*(?:,|and|or|/)?\s*§\s*\d+(?:\.\d+)*)*)")
LINK = re.compile(r"(?<!!)\[(?P<text>[^\]\n]*)\]\((?P<target>[^)\s]+)\)")
HEADING = re.compile(r"^#{1,6}\s+(?P<title>.+?)\s*#*\s*$", re.M)
NUMBERED = re.compile(r"^(\d+(?:\.\d+)*)\.?(?:\s|$)")
ANCHOR = re.compile(r"<a\s+(?:id|name)=\"([^\"]+)\"")
FENCE = re.compile(r"^ *```.*?^ *```[ \t]*$", re.S | re.M)
INLINE_CODE = re.compile(r"`[^`\n]+`")


@dataclass(frozen=True)
class Ref:
    """One citation of a spec file (and of sections of it) at ``where``."""

    where: str
    file: str
    sections: tuple[str, ...]


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else path.name


def _line(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def spec_sections(path: Path) -> set[str]:
    """The section numbers of a spec file: "4.2" for a heading "### 4.2 EWFMKF ...", "1" for "## 1. ..."."""
    out = set()
    for m in HEADING.finditer(FENCE.sub("", path.read_text(encoding="utf-8"))):
        num = NUMBERED.match(m.group("title"))
        if num:
            out.add(num.group(1))
    return out


def slug(title: str) -> str:
    """The anchor a Markdown host (GitHub) gives a heading: lower case, punctuation dropped, spaces to '-'."""
    title = re.sub(r"`|\*\*|\[([^\]]*)\]\([^)]*\)", r"\1", title.strip().lower())
    kept = "".join(c for c in title if c in " -_" or unicodedata.category(c)[0] in "LNM")
    return kept.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The fragments a link into ``path`` may name: heading slugs (with GitHub's -1, -2 for repeats) and <a id>."""
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    seen: dict[str, int] = {}
    out = set(ANCHOR.findall(text))
    for m in HEADING.finditer(text):
        s = slug(m.group("title"))
        out.add(s if s not in seen else f"{s}-{seen[s]}")
        seen[s] = seen.get(s, 0) + 1
    return out


def sections_of(text: str) -> tuple[str, ...]:
    return tuple(SECTION.findall(text or ""))


def _spec_file(num: str) -> str | None:
    found = sorted(SPEC_DIR.glob(f"{num}-*.md"))
    return found[0].name if len(found) == 1 else None


def code_files() -> list[Path]:
    """The sources and bundled experiments, where only the full ``docs/spec/...`` form may appear."""
    return sorted((ROOT / "src").rglob("*.py")) + sorted((ROOT / "experiments").rglob("*.toml"))


def markdown_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def lenient_files() -> list[Path]:
    """Files that may keep the shorthand ``spec 04 §1`` (tests, the changelog's history); it must still resolve."""
    tests = [p for p in sorted((ROOT / "tests").rglob("*.py")) if p.name != Path(__file__).name]  # not its own cases
    return tests + [ROOT / "CHANGELOG.md"]


def _code_problems(path: Path, text: str, refs: list[Ref], first_line: int = 1) -> list[str]:
    """Source text (``text`` starts at ``first_line`` of ``path``): only ``docs/spec/NN-name.md §N.M`` may cite the spec.

    The citations found are appended to ``refs``; the problems are returned.
    """
    problems = []
    for m in PATH_REF.finditer(text):
        where = f"{_rel(path)}:{_line(text, m.start()) + first_line - 1}"
        if m.group("prefix") != "docs/":
            problems.append(f"{where}: write the path from the repository root, docs/spec/{m.group('file')}")
        refs.append(Ref(where, m.group("file"), sections_of(m.group("sections"))))
    for m in SHORTHAND.finditer(text):
        where = f"{_rel(path)}:{_line(text, m.start()) + first_line - 1}"
        problems.append(f"{where}: {m.group(0)!r}: cite docs/spec/NN-name.md §N.M")
    return problems


def _markdown_problems(path: Path, refs: list[Ref]) -> list[str]:
    """A Markdown page: its relative links resolve, and it cites the spec by links to the files."""
    text = path.read_text(encoding="utf-8")
    problems = []
    in_spec = path.parent == SPEC_DIR  # the notes themselves also say "file 03 §4.3", in code blocks too
    for code in (FENCE, INLINE_CODE):  # code cannot link: there the sources' rules hold
        if not in_spec:
            for block in code.finditer(text):
                problems += _code_problems(path, block.group(0), refs, _line(text, block.start()))
        # blanked, not removed, so that offsets still give line numbers
        text = code.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)
    for m in LINK.finditer(text):
        where = f"{_rel(path)}:{_line(text, m.start())}"
        target = m.group("target")
        if re.match(r"[a-z][a-z0-9+.-]*:", target):
            continue  # http:, mailto:, ...
        file_part, _, fragment = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            problems.append(f"{where}: link to {target}: no such file")
            continue
        if fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            problems.append(f"{where}: link to {target}: {dest.name} has no heading or anchor {fragment!r}")
        if dest.parent == SPEC_DIR:
            refs.append(Ref(where, dest.name, sections_of(m.group("text"))))
    if not in_spec:  # the shorthand is fine as the text of a link to the file; anywhere else it is a dead end
        bare = LINK.sub(lambda m: " " * len(m.group(0)) if "spec/" in m.group("target") else m.group(0), text)
        for m in SHORTHAND.finditer(bare):
            where = f"{_rel(path)}:{_line(text, m.start())}"
            problems.append(f"{where}: {m.group(0)!r}: link it, [{m.group(0)}](spec/{m.group('num')}-....md)")
        for m in PATH_REF.finditer(bare):
            where = f"{_rel(path)}:{_line(text, m.start())}"
            problems.append(f"{where}: {m.group(0)!r} is not a link: write [text](spec/{m.group('file')})")
    return problems


def _lenient_problems(path: Path, refs: list[Ref]) -> list[str]:
    """Tests and the changelog: the shorthand ``spec 04 §1`` is allowed but must resolve."""
    text = path.read_text(encoding="utf-8")
    problems = []
    for m in SHORTHAND.finditer(text):
        where = f"{_rel(path)}:{_line(text, m.start())}"
        name = _spec_file(m.group("num"))
        if name is None:
            problems.append(f"{where}: {m.group(0)!r}: no single docs/spec/{m.group('num')}-*.md")
        else:
            refs.append(Ref(where, name, sections_of(m.group("sections"))))
    return problems + [p for p in _code_problems(path, text, refs) if "cite docs/spec/NN-name.md" not in p]


def collect(files_code: list[Path], files_md: list[Path], files_lenient: list[Path]) -> tuple[list[Ref], list[str]]:
    """The spec references of the given files, and the problems found on the way (not yet resolved)."""
    refs: list[Ref] = []
    problems: list[str] = []
    for path in files_code:
        problems += _code_problems(path, path.read_text(encoding="utf-8"), refs)
    for path in files_md:
        problems += _markdown_problems(path, refs)
    for path in files_lenient:
        problems += _lenient_problems(path, refs)
    return refs, problems


def unresolved(refs: list[Ref]) -> list[str]:
    """The references whose file is not in docs/spec/ or whose section is not a heading of it."""
    out = []
    cache: dict[str, set[str]] = {}
    for ref in refs:
        path = SPEC_DIR / ref.file
        if not path.is_file():
            out.append(f"{ref.where}: docs/spec/{ref.file} does not exist")
            continue
        have = cache.setdefault(ref.file, spec_sections(path))
        out += [f"{ref.where}: docs/spec/{ref.file} has no section §{s}" for s in ref.sections if s not in have]
    return out


def test_the_spec_is_in_the_repository():
    names = {p.name for p in SPEC_DIR.glob("*.md")}
    assert {"00-overview.md", "03-fading-memory-ekf.md", "04-adaptive-cs-model.md"} <= names
    assert "4.4" in spec_sections(SPEC_DIR / "03-fading-memory-ekf.md")


def test_every_spec_reference_resolves():
    refs, problems = collect(code_files(), markdown_files(), lenient_files())
    problems += unresolved(refs)
    assert not problems, "\n".join(problems)
    # the scan found the citations it is meant to check (a broken pattern would pass vacuously)
    assert sum(r.where.startswith("src/") for r in refs) >= 10
    assert sum(r.where.startswith("docs/") and bool(r.sections) for r in refs) >= 10


# ---------------------------------------------------------------------------
# the checker itself: each kind of broken reference is caught
# ---------------------------------------------------------------------------
def _problems(tmp_path: Path, name: str, text: str) -> list[str]:
    """The problems ``collect`` finds in one file ``name`` holding ``text``, without the file:line prefix.

    A Markdown page is written to a folder that looks like docs/ (its spec/ and the pages it links
    are links to the real ones), so that its relative links resolve as they would in docs/.
    """
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "spec").symlink_to(SPEC_DIR, target_is_directory=True)
    for page in ("fading.md", "papers.md"):
        (docs / page).symlink_to(ROOT / "docs" / page)
    path = docs / name
    path.write_text(text, encoding="utf-8")
    if name.endswith(".md"):
        refs, problems = collect([], [path], [])
    elif name.startswith("test_"):
        refs, problems = collect([], [], [path])
    else:
        refs, problems = collect([path], [], [])
    return [p.split(": ", 1)[1] for p in problems + unresolved(refs)]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('"""See docs/spec/03-fading-memory-ekf.md §4.2."""', None),
        ('"""See docs/spec/03-fading-memory-ekf.md §4.2 and §4.3; docs/spec/02-upf-partial.md §7 (U6)."""', None),
        ('"""See docs/spec/03-fading-memory-ekf.md §4.9."""', "has no section §4.9"),
        ('"""See docs/spec/03-fading-memory-ekf.md §4.2 and §9."""', "has no section §9"),
        ('"""See docs/spec/09-nothing.md §1."""', "does not exist"),
        ('"""See spec 03 §4.2."""', "cite docs/spec/NN-name.md"),
        ('# Spec: shared/spec/01-particle-filters.md §6.', "write the path from the repository root"),
    ],
)
def test_a_broken_source_reference_fails(tmp_path, text, expected):
    problems = _problems(tmp_path, "module.py", text)
    if expected is None:
        assert problems == []
    else:
        assert len(problems) == 1 and expected in problems[0], problems


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[spec 03 §4.2](spec/03-fading-memory-ekf.md) and [fading](fading.md#bounds-on-λ)", None),
        ("[P1](papers.md#p1), [spec 01 §7](spec/01-particle-filters.md)", None),
        ("[spec 03 §4.7](spec/03-fading-memory-ekf.md)", "has no section §4.7"),
        ("[the notes](spec/03-fading.md)", "no such file"),
        ("[fading](fading.md#no-such-heading)", "no heading or anchor"),
        ("as spec 03 §4.4 says", "link it"),
        ("see docs/spec/03-fading-memory-ekf.md §4.4", "is not a link"),
        ("```python\nx = 1  # docs/spec/03-fading-memory-ekf.md §4.4\n```", None),
        ("```python\nx = 1  # docs/spec/03-fading-memory-ekf.md §4.8\n```", "has no section §4.8"),
        ("```python\nx = 1  # spec 03 §4.4\n```", "cite docs/spec/NN-name.md"),
        ("cited as `docs/spec/03-fading-memory-ekf.md §4.4` in code", None),
        ("cited as `docs/spec/03-fading-memory-ekf.md §4.5` in code", "has no section §4.5"),
    ],
)
def test_a_broken_docs_reference_fails(tmp_path, text, expected):
    problems = _problems(tmp_path, "page.md", text)
    if expected is None:
        assert problems == []
    else:
        assert len(problems) == 1 and expected in problems[0], problems


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("# spec 04 §1: MATLAB singerProcessNoise", None),
        ("# spec 04 §7: nothing there", "has no section §7"),
        ("# spec 09 §1", "no single docs/spec/09-*.md"),
    ],
)
def test_the_shorthand_of_tests_must_still_resolve(tmp_path, text, expected):
    problems = _problems(tmp_path, "test_x.py", text)
    if expected is None:
        assert problems == []
    else:
        assert len(problems) == 1 and expected in problems[0], problems


def test_headings_give_the_sections_and_anchors_a_reader_follows():
    assert slug("4.2 EWFMKF – exponentially weighted adaptive fading (baseline) [RECON + LIT]") == (
        "42-ewfmkf--exponentially-weighted-adaptive-fading-baseline-recon--lit"
    )
    assert slug("Bounds on λ") == "bounds-on-λ"
    assert {"1", "4", "4.2", "4.4", "6.2"} <= spec_sections(SPEC_DIR / "03-fading-memory-ekf.md")
