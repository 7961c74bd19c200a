"""The self-contained HTML report of an output folder, and the index of many.

The report is built from the files of an output folder only (``run.json`` and
``figures/*.png``), never from the objects in memory, so ``pursuit report
DIR`` rebuilds exactly what ``pursuit run`` wrote, for any experiment kind.
Figures are embedded as base64 PNG; the page has no scripts and loads nothing
from the network.
"""

from __future__ import annotations

import base64
import html
import json
import sys
from pathlib import Path
from typing import Any

from ..io.output_file import write_whole
from ..tables import cell

__all__ = ["write_report", "write_index", "render_report", "render_index", "REPORT_NAME", "INDEX_NAME"]

REPORT_NAME = "report.html"
INDEX_NAME = "index.html"

_CSS = """
:root { --fg: #1b1f24; --muted: #57606a; --line: #d0d7de; --head: #f6f8fa; --paper: #fff8c5; --accent: #0a5cad; }
* { box-sizing: border-box; }
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: var(--fg);
       max-width: 1400px; margin: 0 auto; padding: 24px; }
.desc, .note, nav, section > p, section > ul { max-width: 1000px; }
h1 { font-size: 1.6em; margin: 0 0 4px; } h2 { border-bottom: 1px solid var(--line); padding-bottom: 4px; margin-top: 2em; }
h3 { font-size: 1.05em; margin: 1.4em 0 0.4em; }
.desc { color: var(--muted); white-space: pre-line; }
dl.meta { display: grid; grid-template-columns: max-content 1fr; gap: 2px 16px; margin: 12px 0; }
dl.meta dt { color: var(--muted); } dl.meta dd { margin: 0; font-family: ui-monospace, monospace; }
nav a { margin-right: 14px; color: var(--accent); }
.scroll { overflow-x: auto; }
table { border-collapse: collapse; font-size: 0.85em; margin: 4px 0; }
th, td { border: 1px solid var(--line); padding: 3px 6px; }
th { background: var(--head); text-align: left; vertical-align: bottom; }
td.num { text-align: right; font-family: ui-monospace, monospace; font-size: 0.95em; }
figure img { max-width: min(100%, 1100px); }
table.paper th.paper, table.paper td.paper { background: var(--paper); }
.note { color: var(--muted); font-size: 0.9em; white-space: pre-line; }
figure { margin: 16px 0; } figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { color: var(--muted); font-size: 0.9em; }
.missing { color: #b42318; }
pre { background: var(--head); border: 1px solid var(--line); padding: 10px; overflow-x: auto; font-size: 0.85em; }
"""


def _e(v: Any) -> str:
    return html.escape(str(v), quote=True)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _table(t: dict[str, Any], name: str) -> str:
    paper = t.get("kind") == "paper"
    cols = t.get("columns", [])
    # a break opportunity after each underscore: long column names (rmse_position) wrap instead of widening the table
    head = "".join(f'<th class="{"paper" if paper and c == "paper" else ""}">{_e(c).replace("_", "_<wbr>")}</th>' for c in cols)
    body = []
    for row in t.get("rows", []):
        cells = []
        for c, v in zip(cols, row):
            cls = ["num"] if _is_num(v) else []
            if paper and c == "paper":
                cls.append("paper")
            cells.append(f'<td class="{" ".join(cls)}">{_e(cell(v))}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    title = t.get("title") or name
    notes = f'<p class="note">{_e(t["notes"])}</p>' if t.get("notes") else ""
    csv_link = f' <a href="{_e(name)}.csv">CSV</a>'
    return (
        f'<h3 id="table-{_e(name)}">{_e(title)}{csv_link}</h3>'
        f'<div class="scroll"><table class="{"paper" if paper else "result"}"><thead><tr>{head}</tr></thead>'
        f'<tbody>{"".join(body)}</tbody></table></div>{notes}'
    )


def _figure(folder: Path, name: str) -> tuple[str, bool]:
    png = folder / "figures" / f"{name}.png"
    others = [f'<a href="figures/{_e(p.name)}">{_e(p.suffix[1:].upper())}</a>'
              for p in sorted((folder / "figures").glob(f"{name}.*")) if p.suffix != ".png"]
    links = (" — " + ", ".join(others)) if others else ""
    if not png.is_file():
        return f'<figure><p class="missing">figure {_e(name)}: figures/{_e(name)}.png is missing</p></figure>', False
    data = base64.b64encode(png.read_bytes()).decode("ascii")
    return (
        f'<figure id="figure-{_e(name)}"><img src="data:image/png;base64,{data}" alt="{_e(name)}">'
        f"<figcaption>{_e(name)}{links}</figcaption></figure>",
        True,
    )


def _backend_text(b: dict[str, Any] | None) -> str | None:
    if not b:
        return None
    where = b.get("backend", "?")
    if b.get("scheduler"):
        where += f" at {b['scheduler']}"
    n = b.get("workers")
    return f"{where} ({n} worker{'s' if n != 1 else ''})" if n is not None else where


def _config_text(sidecar: dict[str, Any]) -> str:
    if sidecar.get("config_text"):
        return sidecar["config_text"]
    return json.dumps(sidecar.get("config"), indent=2, default=str)


def render_report(folder: str | Path) -> tuple[str, list[str]]:
    """The report page of an output folder, and a list of problems (missing figures).

    Raises
    ------
    ValueError
        If the folder has no readable ``run.json``.
    """
    folder = Path(folder)
    try:
        sidecar = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{folder}: not a pursuit output folder (no run.json)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{folder / 'run.json'}: cannot read ({e})") from None
    problems: list[str] = []
    name = sidecar.get("experiment", folder.name)
    title = sidecar.get("title") or name
    engine = sidecar.get("engine", {})
    meta = [
        ("experiment", name),
        ("root seed", sidecar.get("seed")),
        ("runs", sidecar.get("runs")),
        ("chunk size", engine.get("chunk_size")),
        ("backend", _backend_text(engine.get("backend"))),
        ("storage", engine.get("store")),
        ("saved data", sidecar.get("data")),
        ("config file", sidecar.get("config_file")),
        ("reference", sidecar.get("reference")),
        ("written", sidecar.get("written")),
        ("command", sidecar.get("command")),
    ]
    meta_html = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in meta if v not in (None, ""))
    tables = sidecar.get("tables", {})
    paper = {k: t for k, t in tables.items() if t.get("kind") == "paper"}
    results = {k: t for k, t in tables.items() if t.get("kind") != "paper"}
    parts = [f"<header><h1>{_e(title)}</h1>"]
    if sidecar.get("description"):
        parts.append(f'<p class="desc">{_e(str(sidecar["description"]).strip())}</p>')
    parts.append(f'<dl class="meta">{meta_html}</dl>')
    nav = [("paper", "Paper vs measured", paper), ("results", "Results", results), ("figures", "Figures", sidecar.get("figures")),
           ("files", "Files", True), ("config", "Configuration", True), ("versions", "Versions", True)]
    parts.append("<nav>" + "".join(f'<a href="#{a}">{_e(t)}</a>' for a, t, show in nav if show) + "</nav></header>")
    if paper:
        parts.append('<section id="paper"><h2>Paper against measured</h2>')
        parts.append('<p class="note">The paper\'s numbers (column <b>paper</b>) beside ours (column <b>measured</b>), '
                     "both from the table's source; a difference is discussed in docs/papers.md.</p>")
        parts.extend(_table(t, k) for k, t in paper.items())
        parts.append("</section>")
    if results:
        parts.append('<section id="results"><h2>Results</h2>')
        parts.extend(_table(t, k) for k, t in results.items())
        parts.append("</section>")
    figs = sidecar.get("figures", [])
    if figs:
        parts.append('<section id="figures"><h2>Figures</h2>')
        for fig in figs:
            block, ok = _figure(folder, fig)
            if not ok:
                problems.append(f"figures/{fig}.png is missing")
            parts.append(block)
        parts.append("</section>")
    files = sidecar.get("files", {})
    listing = [f'<li><a href="{_e(f)}">{_e(f)}</a> — {_e(what)}</li>' for f, what in files.items()]
    for key, entry in sidecar.get("results", {}).items():
        if entry.get("file"):
            listing.append(f'<li><a href="{_e(entry["file"])}">{_e(entry["file"])}</a> — result {_e(key)} ({_e(entry["type"])}; load with pursuit.load)</li>')
    parts.append('<section id="files"><h2>Files</h2><ul>' + "".join(listing) + "</ul></section>")
    parts.append(f'<section id="config"><h2>Configuration</h2><pre>{_e(_config_text(sidecar))}</pre></section>')
    versions = sidecar.get("versions", {})
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in versions.items())
    parts.append(f'<section id="versions"><h2>Package versions</h2><table>{rows}</table></section>')
    return _page(f"{title} — pursuit report", "".join(parts)), problems


def _page(title: str, body: str) -> str:
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        '<link rel="icon" href="data:,">'
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>{body}</body></html>\n"
    )


def write_report(folder: str | Path, *, warn: bool = True) -> Path:
    """Write ``report.html`` into an output folder from its files; returns its path.

    A figure listed in ``run.json`` whose PNG is missing is shown as missing
    in the page and reported on standard error.
    """
    folder = Path(folder)
    text, problems = render_report(folder)
    if warn:
        for p in problems:
            print(f"pursuit: warning: {folder}: {p}", file=sys.stderr)
    path = folder / REPORT_NAME
    write_whole(path, text)
    return path


def render_index(root: str | Path, folders: list[Path]) -> str:
    """The index page linking the reports of ``folders`` (each an output folder under ``root``)."""
    root = Path(root)
    rows = []
    for f in folders:
        try:
            sc = json.loads((f / "run.json").read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            sc = {}
        rel = f.relative_to(root).as_posix()
        kinds = [t.get("kind") for t in sc.get("tables", {}).values()]
        rows.append(
            f'<tr><td><a href="{_e(rel)}/{REPORT_NAME}">{_e(sc.get("experiment", f.name))}</a></td>'
            f'<td>{_e(sc.get("title", ""))}</td><td class="num">{_e(sc.get("runs", ""))}</td>'
            f'<td class="num">{_e(sc.get("seed", ""))}</td><td class="num">{len(sc.get("figures", []))}</td>'
            f'<td>{"yes" if "paper" in kinds else ""}</td></tr>'
        )
    body = (
        "<header><h1>pursuit: reproduced experiments</h1>"
        f'<p class="desc">{len(folders)} experiment(s). Each report embeds its figures, tables, configuration, '
        "root seed and package versions.</p></header>"
        '<table><thead><tr><th>experiment</th><th>title</th><th>runs</th><th>root seed</th><th>figures</th>'
        f'<th>paper values</th></tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )
    return _page("pursuit: reproduced experiments", body)


def write_index(root: str | Path, folders: list[Path]) -> Path:
    """Write ``index.html`` into ``root`` linking every output folder's report; returns its path."""
    root = Path(root)
    path = root / INDEX_NAME
    write_whole(path, render_index(root, folders))
    return path
