"""MODEL.toml for ``pursuit track --multi``: motion, the detecting sensor and a ``[tracker]`` table.

A multi-target model file names the motion model every target follows, the
one sensor that made the detections, and the tracker::

    [motion]                  # as for `pursuit track` (io.model): cv, ca, ct or singer
    type = "cv"
    ndim = 2
    q = 0.005

    [[sensors]]               # exactly one, of type "position": the detections are position fixes
    id = "radar"
    type = "position"
    sigma = 0.87

    [tracker]                 # a registered tracker (`pursuit list trackers`): gnn or jpda
    type = "gnn"
    filter = {type = "kf"}    # the per-track filter, built against [motion] and [[sensors]]
    p_detect = 0.9            # required: P_D the tracker assumes
    clutter_density = 0.003   # required: false alarms per scan per unit area of measurement space
    max_speed = 5.0           # required: largest target speed, for two-point initiation
    gate = 0.99               # optional: chi-square gate probability
    confirm = [2, 3]          # optional: M of N confirmation
    max_misses = 3            # optional: consecutive misses that delete a track
    capacity = 32             # optional: track slots

    [input]                   # optional: time_column, sensor_column, columns = {radar = ["east", "north"]}, max_gap

**The prior of a new track.**  There is no ``[prior]``: every track starts
from the detections by two-point initiation
(:mod:`pursuit.multitarget.management`): two detections of consecutive
scans that no track gated and that lie within ``max_speed · dt`` of each
other (mutual nearest neighbours) give position p₂, velocity
(p₂ − p₁)/dt and covariance from the sensor's noise
(:func:`pursuit.initiation.two_point`).  So ``max_speed`` is required, and the
sensor must give positions.

Loading checks the whole file and reports the first problem as one line that
names the file, the line and the field (:class:`pursuit.experiment.ConfigError`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from .. import registry
from ..experiment import ConfigError, config_error, read_toml
from .input_spec import InputSpec, build_input_spec
from .model import MOTION_PARAMS, TRACK_PARAMS, Sensor, _build_sensors, _resolve, _ScenarioView
from .motions import build_motion

__all__ = ["MultiTrackModel", "load_multi_model", "build_multi_model"]

_SECTIONS = ("motion", "sensors", "tracker", "track", "input")

# Sections of a single-target model that have no place here, and why.
_NOT_HERE = {
    "prior": "--multi starts every track from the detections (two-point initiation within tracker.max_speed); remove [prior]",
    "filter": "with --multi the per-track filter is the [tracker] table's filter = {type = ...}; remove [filter]",
    "imm": "an IMM per track is not available from a model file yet: give one [motion] (or use pursuit.multitarget in Python)",
}


@dataclass(frozen=True)
class MultiTrackModel:
    """A loaded, validated multi-target MODEL.toml.

    Attributes
    ----------
    name
        Label (the file stem unless ``[track] name`` sets one).
    motion, measurement
        The per-track filter's models.
    tracker
        The tracker (:class:`pursuit.multitarget.GNNTracker` or
        :class:`~pursuit.multitarget.JPDATracker`), built through the registry.
    sensor
        The one sensor whose detections are tracked.
    values
        The detection file's value columns, in component order: the
        sensor's ``[input] columns`` entry, else the motion model's position
        labels (``x, y``).
    state_labels, position_indices
        State layout (the output's state columns).
    seed
        ``[track] seed``, for the tracker's ``rng`` (Gaussian filters draw nothing).
    input
        ``[input]``: column names and the largest believable gap.
    path
        The file it came from.
    """

    name: str
    motion: Any
    measurement: Any
    tracker: Any
    sensor: Sensor
    values: tuple[str, ...]
    state_labels: tuple[str, ...]
    position_indices: tuple[int, ...]
    seed: int
    input: InputSpec
    path: Path | None = None


def load_multi_model(path: str | Path) -> MultiTrackModel:
    """Read and validate a multi-target MODEL.toml.

    Raises
    ------
    ConfigError
        For a missing or unreadable file, invalid TOML, an unknown section or
        key, a wrong type or an impossible value; the message names the file,
        the line when it can be found, and the field.
    """
    path = Path(path)
    text, doc = read_toml(path)
    if "experiment" in doc and "motion" not in doc:
        raise ConfigError(path, f"this is an experiment file, not a `pursuit track` model file: run it as pursuit run {path}")
    try:
        return build_multi_model(doc, name=path.stem, path=path)
    except ValueError as e:
        raise config_error(path, text, e) from None


def build_multi_model(doc: Mapping[str, Any], name: str = "tracks", path: Path | None = None) -> MultiTrackModel:
    """Build a :class:`MultiTrackModel` from a parsed document; raises ``ValueError`` naming the field."""
    for key in doc:
        if key in _NOT_HERE:
            raise ValueError(f"{key}: {_NOT_HERE[key]}")
        if key not in _SECTIONS:
            raise ValueError(f"{key}: unknown section (known with --multi: {', '.join(_SECTIONS)})")
    for key in ("motion", "sensors", "tracker"):
        if key not in doc:
            raise ValueError(f"{key}: required section is missing")
    track = _resolve(doc.get("track", {}), "track", TRACK_PARAMS)
    vals = _resolve(doc["motion"], "motion", MOTION_PARAMS)
    motion, labels = build_motion(vals, "motion", vals["ndim"], vals["dt"])
    sensors, measurement = _build_sensors(doc["sensors"], motion)
    if len(sensors) != 1:
        raise ValueError(f"sensors: --multi tracks the detections of one sensor; got {len(sensors)} [[sensors]] tables")
    sensor = next(iter(sensors.values()))
    if sensor.type != "position":
        raise ValueError(
            f"sensors[0].type: --multi needs position detections (type = \"position\"), from which two-point initiation "
            f"starts tracks; got {sensor.type!r}"
        )
    spec = build_input_spec(doc.get("input", {}), motion, sensors)
    if isinstance(doc.get("input"), dict) and "time_origin" in doc["input"]:
        raise ValueError("input.time_origin: not available with --multi: ISO 8601 detection times count from the Unix epoch")
    view = _ScenarioView(
        name=track["name"] or name,
        motion=motion,
        measurement=measurement,
        prior=None,
        dt=motion.dt,
        state_labels=labels,
        position_indices=motion.position_indices,
        velocity_indices=motion.velocity_indices,
    )
    values = spec.columns[sensor.id] if spec.columns else tuple(labels[i] for i in motion.position_indices)
    return MultiTrackModel(
        name=view.name,
        motion=motion,
        measurement=measurement,
        tracker=_build_tracker(doc["tracker"], view),
        sensor=sensor,
        values=tuple(values),
        state_labels=tuple(labels),
        position_indices=tuple(motion.position_indices),
        seed=track["seed"],
        input=spec,
        path=path,
    )


def _build_tracker(table: Any, view: _ScenarioView) -> Any:
    if not isinstance(table, dict):
        raise ValueError("tracker: expected a table")
    values = dict(table)
    kind = values.pop("type", None)
    if kind is None:
        raise ValueError("tracker.type: required (gnn or jpda; see `pursuit list trackers`)")
    if kind not in STREAMING_TRACKERS:
        # PMHT, EPMHT and GM-PHD have no per-scan step for --stream yet (and GM-PHD no track table)
        raise ValueError(
            f"tracker.type: `pursuit track --multi` runs {' or '.join(STREAMING_TRACKERS)}, got {kind!r} "
            "(the other trackers run in Python and in experiment files)"
        )
    comp = registry.get("tracker", kind, "tracker.type")
    return comp.build(scenario=view, where="tracker", **comp.resolve(values, "tracker"))


STREAMING_TRACKERS = ("gnn", "jpda")
"""The trackers `pursuit track --multi` can run, batch and streaming (a per-scan step through track_stream)."""
