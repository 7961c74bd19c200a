"""Results on disk: saving and loading result objects, tidy error tables, output folders.

An output folder written by ``pursuit run`` / ``pursuit reproduce`` (see
:func:`pursuit.report.output.write_output`) holds

* ``run.json``: the sidecar (experiment, root seed, runs, config, package
  versions, tables, figures and a manifest of the files below);
* one CSV per table (``summary.csv``, and ``paper_vs_measured.csv`` where the
  experiment has paper values);
* ``errors.csv``: the tidy error table, one row per (result, filter, run,
  step) with the signed error of each state component, the position and
  velocity error norms, NEES and NIS;
* ``per_step.csv``: per (result, filter, step) RMSE of each component group,
  ANEES, ANIS and the mean of each scalar step-info value;
* ``results/NAME.npz``: each result object, exactly (``load_result`` gives back
  the same bits);
* ``figures/NAME.png`` and ``.pdf``; ``report.html``.

:func:`load` reads such a folder back into an
:class:`~pursuit.tables.ExperimentOutput` whose ``results`` are the
result objects.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ._json import json_default
from .reduction import FilterStatistics
from .results import FilterResult, MonteCarloResult
from .tables import ExperimentOutput, Table, write_csv

__all__ = [
    "save_result",
    "load_result",
    "write_errors_csv",
    "write_per_step_csv",
    "load",
    "FORMAT",
]

FORMAT = "pursuit-result/1"


# --------------------------------------------------------------------------
# one result object <-> .npz
# --------------------------------------------------------------------------
def _result_arrays(result: MonteCarloResult, prefix: str, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Put a result's arrays into ``arrays`` under ``prefix``; return its metadata."""
    arrays[f"{prefix}times"] = np.asarray(result.times)
    meta: dict[str, Any] = {
        "scenario": result.scenario,
        "seed": result.seed,
        "state_labels": list(result.state_labels),
        "position_indices": list(result.position_indices),
        "velocity_indices": list(result.velocity_indices),
        "state_units": None if result.state_units is None else list(result.state_units),
        "store": result.store,
        "total_runs": result.runs,
        "filters": [],
    }
    if result.truth is not None:
        arrays[f"{prefix}truth"] = result.truth
        arrays[f"{prefix}measurements"] = result.measurements
    for i, (name, fr) in enumerate(result.filters.items()):
        fmeta: dict[str, Any] = {"name": name, "wall_time": fr.wall_time, "info": list(fr.info)}
        if fr.estimates is not None:
            arrays[f"{prefix}f{i}.estimates"] = fr.estimates
            fmeta["covariances"] = fr.covariances is not None
            if fr.covariances is not None:
                arrays[f"{prefix}f{i}.covariances"] = fr.covariances
            for j, value in enumerate(fr.info.values()):
                arrays[f"{prefix}f{i}.info{j}"] = np.asarray(value)
        if result.truth is None:
            stats = result.filter_statistics(name)
            fmeta["sums"] = list(stats.sums)
            fmeta["per_run"] = list(stats.per_run)
            for j, value in enumerate(stats.sums.values()):
                arrays[f"{prefix}f{i}.sum{j}"] = value
            for j, value in enumerate(stats.per_run.values()):
                arrays[f"{prefix}f{i}.run{j}"] = value
        meta["filters"].append(fmeta)
    if result.truth is None and result.examples is not None:
        meta["examples"] = _result_arrays(result.examples, f"{prefix}examples.", arrays)
    return meta


def save_result(result: MonteCarloResult, path: str | Path) -> Path:
    """Write a result object to an ``.npz`` file that :func:`load_result` reads back exactly."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    meta = _result_arrays(result, "", arrays)
    meta["format"] = FORMAT
    meta["config"] = result.config
    arrays["meta"] = np.array(json.dumps(meta, default=json_default))
    with path.open("wb") as fh:
        np.savez(fh, **arrays)
    return path


def _result_from(meta: dict[str, Any], prefix: str, z: Any, config: Any) -> MonteCarloResult:
    full = meta["store"] == "full"
    filters: dict[str, FilterResult] = {}
    statistics: dict[str, FilterStatistics] | None = None if full else {}
    times = z[f"{prefix}times"]
    for i, fmeta in enumerate(meta["filters"]):
        name = fmeta["name"]
        if full:
            covs = z[f"{prefix}f{i}.covariances"] if fmeta.get("covariances") else None
            info = {key: z[f"{prefix}f{i}.info{j}"] for j, key in enumerate(fmeta["info"])}
            filters[name] = FilterResult(name, z[f"{prefix}f{i}.estimates"], covs, info, fmeta["wall_time"])
        else:
            filters[name] = FilterResult(name, None, None, {}, fmeta["wall_time"])
            statistics[name] = FilterStatistics(
                runs=meta["total_runs"],
                steps=len(times),
                sums={key: z[f"{prefix}f{i}.sum{j}"] for j, key in enumerate(fmeta["sums"])},
                per_run={key: z[f"{prefix}f{i}.run{j}"] for j, key in enumerate(fmeta["per_run"])},
            )
    examples = None
    if not full and meta.get("examples"):
        examples = _result_from(meta["examples"], f"{prefix}examples.", z, None)
    units = meta.get("state_units")
    return MonteCarloResult(
        scenario=meta["scenario"],
        seed=meta["seed"],
        times=times,
        truth=z[f"{prefix}truth"] if full else None,
        measurements=z[f"{prefix}measurements"] if full else None,
        state_labels=tuple(meta["state_labels"]),
        position_indices=tuple(meta["position_indices"]),
        velocity_indices=tuple(meta["velocity_indices"]),
        filters=filters,
        config=config,
        statistics=statistics,
        total_runs=None if full else meta["total_runs"],
        examples=examples,
        state_units=None if units is None else tuple(units),
    )


def load_result(path: str | Path) -> MonteCarloResult:
    """Read a result object written by :func:`save_result`.

    Raises
    ------
    ValueError
        If the file is not a pursuit result (names the file).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            files = list(z.files)
            data = {k: z[k] for k in files}
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path}: cannot read result file ({e})") from None
    if "meta" not in data:
        raise ValueError(f"{path}: not a pursuit result file (no metadata)")
    try:
        meta = json.loads(str(data["meta"]))
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: damaged result metadata ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise ValueError(f"{path}: unknown result format {got!r} (expected {FORMAT})")
    try:
        return _result_from(meta, "", data, meta.get("config"))
    except (KeyError, TypeError) as e:
        raise ValueError(f"{path}: damaged result file (missing {e})") from None


# --------------------------------------------------------------------------
# tidy tables
# --------------------------------------------------------------------------
def _f(values: np.ndarray) -> list[str]:
    return [repr(v) for v in np.asarray(values, dtype=float).ravel().tolist()]


def _norm(error: np.ndarray, idx: tuple[int, ...]) -> np.ndarray:
    out = error[..., idx[0]] ** 2
    for i in idx[1:]:
        out = out + error[..., i] ** 2
    return np.sqrt(out)


def write_errors_csv(path: str | Path, experiment: str, results: dict[str, MonteCarloResult]) -> int:
    """The tidy error table: one row per (result, filter, run, step); returns the number of rows.

    Columns: ``experiment, result, filter, run, step, time``, then
    ``err_LABEL`` (estimate minus truth) for each state component,
    ``err_position`` and ``err_velocity`` (Euclidean norms, where the scenario
    has them), ``nees`` and ``nis`` (empty where not available).  For a
    summary-mode result only the example runs it kept are listed.
    """
    ordered: list[str] = []
    for r in results.values():
        for lab in r.state_labels:
            if lab not in ordered:
                ordered.append(lab)
    labels = ordered
    has_pos = any(r.position_indices for r in results.values())
    has_vel = any(r.velocity_indices for r in results.values())
    header = ["experiment", "result", "filter", "run", "step", "time", *(f"err_{lab}" for lab in labels)]
    header += (["err_position"] if has_pos else []) + (["err_velocity"] if has_vel else []) + ["nees", "nis"]
    def lines():
        for key, result in results.items():
            if result.truth is None and result.examples is None:
                continue
            stored = result.stored()
            K, R = stored.truth.shape[:2]
            run_col = np.repeat(np.arange(R), K).tolist()
            step_col = np.tile(np.arange(1, K + 1), R).tolist()
            time_col = _f(np.tile(stored.times, R))
            for name, fr in stored.filters.items():
                err = (fr.estimates - stored.truth).transpose(1, 0, 2)  # (R, K, n): run-major rows
                cols: list[list[str]] = []
                for lab in labels:
                    cols.append(_f(err[..., stored.state_labels.index(lab)]) if lab in stored.state_labels else [""] * (K * R))
                if has_pos:
                    cols.append(_f(_norm(err, stored.position_indices)) if stored.position_indices else [""] * (K * R))
                if has_vel:
                    cols.append(_f(_norm(err, stored.velocity_indices)) if stored.velocity_indices else [""] * (K * R))
                nees = stored.nees(name).T if fr.covariances is not None else None
                cols.append(_f(nees) if nees is not None else [""] * (K * R))
                nis = fr.info.get("nis")
                cols.append(_f(np.asarray(nis).T) if nis is not None else [""] * (K * R))
                for i in range(K * R):
                    yield [experiment, key, name, run_col[i], step_col[i], time_col[i], *(c[i] for c in cols)]

    return write_csv(path, header, lines())


def write_per_step_csv(path: str | Path, experiment: str, results: dict[str, MonteCarloResult]) -> int:
    """Per-step summaries over all runs: one row per (result, filter, step); returns the number of rows.

    Columns: ``experiment, result, filter, step, time, runs``, ``rmse_position``,
    ``rmse_velocity``, ``rmse_LABEL`` per component, ``anees``, ``anees_low``,
    ``anees_high`` (the step's 95 % χ² bounds,
    :meth:`MonteCarloResult.consistency_bounds`), the same for ``anis``, and
    ``mean_KEY`` for each scalar step-info value.  Available in both storage
    modes and bit-identical between them.
    """
    table: list[dict[str, Any]] = []
    for key, result in results.items():
        for name in result.filter_names:
            cols: dict[str, np.ndarray] = {}
            if result.position_indices:
                cols["rmse_position"] = result.rmse_per_step(name, "position")
            if result.velocity_indices:
                cols["rmse_velocity"] = result.rmse_per_step(name, "velocity")
            for i, lab in enumerate(result.state_labels):
                cols[f"rmse_{lab}"] = result.rmse_per_step(name, (i,))
            for what in ("anees", "anis"):
                try:
                    cols[what] = getattr(result, what)(name)
                except ValueError:
                    continue
                cols[f"{what}_low"], cols[f"{what}_high"] = result.consistency_bounds(name, what[1:])
            for ik in result.info_keys(name):
                cols[f"mean_{ik}"] = result.info_mean(name, ik)
            for k in range(result.steps):
                row = {"experiment": experiment, "result": key, "filter": name, "step": k + 1,
                       "time": float(result.times[k]), "runs": result.runs}
                row.update({c: float(v[k]) for c, v in cols.items()})
                table.append(row)
    fields: list[str] = []
    for row in table:
        for c in row:
            if c not in fields:
                fields.append(c)
    return write_csv(path, fields, ([row.get(c) for c in fields] for row in table))


# --------------------------------------------------------------------------
# a whole output folder
# --------------------------------------------------------------------------
def monte_carlo_results(results: dict[str, Any]) -> dict[str, MonteCarloResult]:
    """The entries of an output's ``results`` that are :class:`MonteCarloResult` objects."""
    return {k: v for k, v in results.items() if isinstance(v, MonteCarloResult)}


def save_results(results: dict[str, Any], folder: Path) -> dict[str, dict[str, Any]]:
    """Write every result object into ``folder``; returns the manifest for the sidecar.

    Result objects go to ``NAME.npz``, arrays to ``NAME.npy``, JSON-able
    values to ``NAME.json``; anything else is listed as not saved.
    """
    manifest: dict[str, dict[str, Any]] = {}
    used: set[str] = set()
    for i, (key, value) in enumerate(results.items()):
        stem = _safe_stem(str(key), i, used)
        if isinstance(value, MonteCarloResult):
            folder.mkdir(exist_ok=True)
            save_result(value, folder / f"{stem}.npz")
            manifest[key] = {"type": "MonteCarloResult", "file": f"{folder.name}/{stem}.npz", "store": value.store,
                             "runs": value.runs, "filters": value.filter_names}
        elif isinstance(value, np.ndarray) and value.dtype.kind in "biufc":
            folder.mkdir(exist_ok=True)
            np.save(folder / f"{stem}.npy", value, allow_pickle=False)
            manifest[key] = {"type": "array", "file": f"{folder.name}/{stem}.npy"}
        else:
            try:
                text = json.dumps(value, allow_nan=True)
            except (TypeError, ValueError):
                manifest[key] = {"type": type(value).__name__, "file": None, "note": "not saved: not JSON-serialisable"}
                continue
            folder.mkdir(exist_ok=True)
            (folder / f"{stem}.json").write_text(text + "\n")
            manifest[key] = {"type": "json", "file": f"{folder.name}/{stem}.json"}
    return manifest


def _safe_stem(key: str, i: int, used: set[str]) -> str:
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in key).strip("._") or f"result{i}"
    base, n = stem, 1
    while stem in used:
        n += 1
        stem = f"{base}-{n}"
    used.add(stem)
    return stem


def load(folder: str | Path) -> ExperimentOutput:
    """Read an output folder back: tables, figure files, result objects and the sidecar.

    Parameters
    ----------
    folder
        A folder written by ``pursuit run`` or ``pursuit reproduce NAME``.

    Returns
    -------
    ExperimentOutput
        ``results`` maps each saved result's name to the object (a
        :class:`MonteCarloResult`, an array or a JSON value);
        ``figures`` maps figure names to the PNG files; ``.result`` is the
        only result object when there is one.

    Raises
    ------
    ValueError
        If the folder has no ``run.json`` or a file it lists is missing or
        damaged (the message names it).
    """
    folder = Path(folder)
    sidecar_path = folder / "run.json"
    if not sidecar_path.is_file():
        raise ValueError(f"{folder}: not a pursuit output folder (no run.json)")
    try:
        sidecar = json.loads(sidecar_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{sidecar_path}: cannot read ({e})") from None
    tables = [
        Table(name, t.get("title", ""), list(t["columns"]), [list(r) for r in t["rows"]], t.get("notes", ""), t.get("kind", "result"))
        for name, t in sidecar.get("tables", {}).items()
    ]
    figures = {name: folder / "figures" / f"{name}.png" for name in sidecar.get("figures", [])}
    results: dict[str, Any] = {}
    for key, entry in sidecar.get("results", {}).items():
        file = entry.get("file")
        if not file:
            continue
        path = folder / file
        if not path.is_file():
            raise ValueError(f"{path}: listed in run.json but missing")
        if entry["type"] == "MonteCarloResult":
            results[key] = load_result(path)
        elif entry["type"] == "array":
            results[key] = np.load(path, allow_pickle=False)
        else:
            results[key] = json.loads(path.read_text())
    return ExperimentOutput(
        name=sidecar.get("experiment", folder.name),
        title=sidecar.get("title", ""),
        description=sidecar.get("description", ""),
        tables=tables,
        figures=figures,
        results=results,
        sidecar=sidecar,
    )


def iter_output_folders(root: Path) -> Iterable[Path]:
    """Sub-folders of ``root`` that are output folders (have a ``run.json``), sorted by name."""
    return sorted(p.parent for p in root.glob("*/run.json"))
