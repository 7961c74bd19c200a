"""Experiments: TOML files that regenerate a comparison from one command.

An experiment file has an ``[experiment]`` table (name, title, kind, runs,
seed, ...) and whatever sections its *kind* reads.  The default kind,
``montecarlo``, reads ``[scenario]``, ``[[filters]]``, optional
``[figures]`` and optional ``[[paper]]`` reference values.  Loading checks the
whole file against the registry (:mod:`pursuit.registry`) before anything
runs, and reports the first problem as one line naming the file, the line
and the field.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import registry
from .registry import Param

if TYPE_CHECKING:
    from .engine.memory import MemoryNeeded
    from .tables import ExperimentOutput

__all__ = [
    "ConfigError",
    "Experiment",
    "load_experiment",
    "experiments_dir",
    "find_experiment",
    "list_experiments",
    "EXPERIMENT_PARAMS",
    "read_toml",
    "config_error",
]


class ConfigError(ValueError):
    """A bad configuration file: knows the file, the field and (when found) the line."""

    def __init__(self, path: str | Path, message: str, line: int | None = None):
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line else self.path
        super().__init__(f"{where}: {message}")


@dataclass
class Experiment:
    """A loaded, validated experiment ready to run.

    Attributes
    ----------
    name, title, description, kind
        From the ``[experiment]`` table (name defaults to the file stem).
    runs, seed
        Monte Carlo runs and root seed.
    path
        The file it came from.
    document
        The parsed TOML, for the sidecar.
    plan
        The kind's prepared object, with ``run(runs, seed, progress, chunk_size)``.
    cpu_s
        Its measured CPU seconds (``[experiment] cpu_s``; 0 when not given):
        ``pursuit reproduce --workers`` starts the costliest experiment first.
    """

    name: str
    title: str
    description: str
    kind: str
    runs: int
    seed: int
    chunk_size: int | None
    path: Path
    document: dict[str, Any]
    plan: Any
    reference: str = ""
    cpu_s: float = 0.0

    def check_runs(self, runs: int) -> None:
        """Check the options that name a run (such as ``figures.trajectory_run``) against ``runs``.

        Raises
        ------
        ConfigError
            Naming the file, the field's line and the field, when an option
            refers to a run that ``runs`` runs do not have.
        """
        check = getattr(self.plan, "check_runs", None)
        if check is None:
            return
        try:
            check(runs)
        except ValueError as e:
            try:
                text = self.path.read_text(encoding="utf-8")
            except OSError:
                text = ""
            raise config_error(self.path, text, e) from None

    def run(
        self, *, runs: int | None = None, seed: int | None = None, progress: bool = False, chunk_size: int | None = None
    ) -> ExperimentOutput:
        """Run it; ``runs`` and ``seed`` override the file's values.

        Raises
        ------
        ConfigError
            When an option names a run beyond ``runs`` (nothing is run).
        """
        runs = self.runs if runs is None else runs
        self.check_runs(runs)
        seed = self.seed if seed is None else seed
        chunk = self.chunk_size if chunk_size is None else chunk_size
        from .engine.memory import MemoryNeeded  # here: importing the engine is slow, `pursuit list` needs none of it

        try:
            out = self.plan.run(runs=runs, seed=seed, progress=progress, chunk_size=chunk)
        except MemoryNeeded as e:  # refused before computing: one line at the field to change
            try:
                text = self.path.read_text(encoding="utf-8")
            except OSError:
                text = ""
            raise ConfigError(self.path, str(e), locate(text, self._memory_field(e))) from None
        out.sidecar.setdefault("experiment", self.name)
        out.sidecar.setdefault("config_file", str(self.path))
        out.sidecar.setdefault("config", self.document)
        out.sidecar.setdefault("runs", runs)
        out.sidecar.setdefault("seed", seed)
        out.sidecar.setdefault("chunk_size", chunk)
        if self.reference:
            out.sidecar.setdefault("reference", self.reference)
        try:
            out.sidecar.setdefault("config_text", self.path.read_text(encoding="utf-8"))
        except OSError:
            pass
        if not out.title:
            out.title = self.title
        if not out.description:
            out.description = self.description
        return out


    def _memory_field(self, e: MemoryNeeded) -> str:
        """The file's field behind a memory refusal (for its line)."""
        if e.field == "particles":
            sweep = self.document.get("sweep")
            if isinstance(sweep, dict) and sweep.get("parameter") == "particles":
                return "sweep.values"
            entries = self.document.get("filters")
            for i, entry in enumerate(entries if isinstance(entries, list) else []):
                if isinstance(entry, dict) and e.filter_name in (entry.get("name"), entry.get("type")):
                    return f"filters[{i}].particles"
        return {"steps": "scenario.steps", "horizon": "scenario.horizon"}.get(e.field, f"experiment.{e.field}")


def _nonneg_seed(field_name: str, v: int) -> int:
    if v < 0:
        raise ValueError(f"{field_name}: must be a non-negative integer, got {v}")
    return v


def _nonneg_seconds(field_name: str, v: float) -> float:
    if not v >= 0:  # also NaN
        raise ValueError(f"{field_name}: must be a number of seconds >= 0, got {v}")
    return v


def _at_least_one(field_name: str, v: int) -> int:
    if v < 1:
        raise ValueError(f"{field_name}: must be at least 1, got {v}")
    return v


EXPERIMENT_PARAMS = (
    Param("name", "str", None, "experiment name (default: the file name without .toml)"),
    Param("title", "str", "", "one-line title for tables and reports"),
    Param("description", "str", "", "what the experiment shows"),
    Param("kind", "str", "montecarlo", "experiment kind (see `pursuit list`)"),
    Param("runs", "int", 100, "Monte Carlo runs", check=_at_least_one),
    Param("seed", "int", 2026, "root seed (run i uses SeedSequence(seed, spawn_key=(i,)))", check=_nonneg_seed),
    Param("chunk_size", "int", None, "runs per chunk (memory bound; results do not depend on it)", check=_at_least_one),
    Param("reference", "str", "", "the paper or source the experiment reproduces"),
    Param(
        "cpu_s", "float", 0.0,
        "CPU seconds it takes (measured; `reproduce --workers` starts the costliest first; results do not depend on it)",
        check=_nonneg_seconds,
    ),
)


def load_experiment(path: str | Path) -> Experiment:
    """Read and validate an experiment file.

    Raises
    ------
    ConfigError
        For a missing or unreadable file, invalid TOML, an unknown key, a
        wrong type or an impossible value; the message names the file, the
        line when it can be found, and the field.
    """
    path = Path(path)
    text, doc = read_toml(path)
    if "experiment" not in doc and "sensors" in doc and {"motion", "imm"} & set(doc):
        raise ConfigError(path, f"this is a `pursuit track` model file, not an experiment: run it as pursuit track DATA --config {path}")
    try:
        exp = _build(doc, path)
        check = getattr(exp.plan, "check_runs", None)
        if check is not None:
            check(exp.runs)
        return exp
    except ValueError as e:
        raise config_error(path, text, e) from None


def read_toml(path: Path) -> tuple[str, dict[str, Any]]:
    """The text and the parsed document of a TOML file.

    Raises
    ------
    ConfigError
        For a missing or unreadable file or invalid TOML (with its line).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(path, "file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(path, f"cannot read file: {e}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        m = re.search(r"line (\d+)", str(e))
        raise ConfigError(path, f"invalid TOML: {e}", int(m.group(1)) if m else None) from None
    return text, doc


def config_error(path: Path, text: str, error: ValueError) -> ConfigError:
    """A ``ValueError`` whose message starts with a field name, as a ConfigError at that field's line."""
    msg = str(error)
    return ConfigError(path, msg, locate(text, msg.split(":", 1)[0]))


def _build(doc: dict[str, Any], path: Path) -> Experiment:
    exp_table = doc.get("experiment", {})
    if not isinstance(exp_table, dict):
        raise ValueError("experiment: expected a table")
    spec = registry.Component("experiment", "experiment", "", EXPERIMENT_PARAMS, lambda **kw: kw)
    values = spec.resolve(exp_table, "experiment")
    kind = registry.get("experiment", values["kind"], "experiment.kind")
    sections = {k: v for k, v in doc.items() if k != "experiment"}
    plan = kind.build(sections=sections, path=path, name=values["name"] or path.stem)
    return Experiment(
        name=values["name"] or path.stem,
        title=values["title"],
        description=values["description"],
        kind=kind.name,
        runs=values["runs"],
        seed=values["seed"],
        chunk_size=values["chunk_size"],
        path=path,
        document=doc,
        plan=plan,
        reference=values["reference"],
        cpu_s=values["cpu_s"],
    )


_FIELD_PART = re.compile(r"([A-Za-z0-9_\-]+)(?:\[(\d+)\])?")
_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-]+)\s*\]\]?")


def locate(text: str, field_path: str) -> int | None:
    """Best-effort line number of a field such as ``filters[1].alpha`` in TOML text.

    Finds the table (``[scenario]``, the second ``[[filters]]``, ...) and then
    the key inside it; a key nested in an inline table falls back to the line
    of its outermost key.  Returns None when nothing matches.
    """
    parts = [(n, int(i) if i else None) for n, i in _FIELD_PART.findall(field_path)]
    if not parts:
        return None
    lines = text.splitlines()
    for cut in range(len(parts), 0, -1):  # the key inside the deepest table that has it
        table, rest = parts[:cut], parts[cut:]
        line = _find(lines, table, rest[0][0] if rest else None)
        if line is not None:
            return line
    for cut in range(len(parts) - 1, 0, -1):  # else the header of the table it belongs in
        line = _find(lines, parts[:cut], None)
        if line is not None:
            return line
    return None


def _find(lines: list[str], table: list[tuple[str, int | None]], key: str | None) -> int | None:
    name = ".".join(n for n, _ in table)
    index = table[-1][1]
    counts: dict[str, int] = {}
    inside = False
    for lineno, line in enumerate(lines, start=1):
        m = _HEADER.match(line)
        if m:
            hname = m.group(2)
            if m.group(1) == "[[":
                counts[hname] = counts.get(hname, -1) + 1
                inside = hname == name and counts[hname] == (index or 0)
            else:
                inside = hname == name and index is None
            if inside and key is None:
                return lineno
            continue
        if inside and key is not None and re.match(rf"^\s*{re.escape(key)}\s*=", line):
            return lineno
    return None


# --------------------------------------------------------------------------
# where experiments live
# --------------------------------------------------------------------------
def experiments_dir() -> Path:
    """The folder of bundled experiments.

    ``$PURSUIT_EXPERIMENTS`` wins; then ``experiments/`` in the current
    directory; then the copy shipped in the wheel; then the source tree's
    ``experiments/`` (editable installs).
    """
    env = os.environ.get("PURSUIT_EXPERIMENTS")
    if env:
        return Path(env)
    cwd = Path.cwd() / "experiments"
    if cwd.is_dir() and any(cwd.glob("*.toml")):
        return cwd
    packaged = Path(__file__).parent / "_experiments"
    if packaged.is_dir():
        return packaged
    return Path(__file__).resolve().parents[2] / "experiments"


def list_experiments() -> list[str]:
    """Names of the bundled experiments, sorted."""
    d = experiments_dir()
    return sorted(p.stem for p in d.glob("*.toml")) if d.is_dir() else []


def find_experiment(name: str) -> Path:
    """Path of a bundled experiment by name, or of a TOML file given directly."""
    p = Path(name)
    if p.suffix == ".toml" and p.exists():
        return p
    candidate = experiments_dir() / f"{name}.toml"
    if candidate.exists():
        return candidate
    known = ", ".join(list_experiments()) or "none"
    raise ConfigError(candidate, f"no experiment named {name!r} (known: {known})")

