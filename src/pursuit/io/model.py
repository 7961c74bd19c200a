"""MODEL.toml: the motion model, the sensors, the prior and the filter for ``pursuit track``.

A model file names everything a filter needs to run on recorded data::

    [motion]                  # cv, ca, ct or singer, with its parameters; or [imm] (io.motions)
    type = "cv"
    ndim = 2
    q = 0.01

    [[sensors]]               # one table per sensor; its id is the CSV/JSON "sensor" field
    id = "A"
    type = "range"            # range | toa | bearing | position
    position = [0.0, 0.0]
    sigma = 1.0

    [prior]                   # optional: without it (or with from = "measurements")
    mean = [10.0, 0.5, 40.0, 0.8]   # the first positions start the track (pursuit.io.initiate)
    cov = [4.0, 0.25, 4.0, 0.25]
    time = 0.0                # optional: the time the prior refers to

    [filter]                  # any registered filter (`pursuit list filters`) and its parameters
    type = "ekf"
    gate = 0.999

    [input]                   # optional: CSV columns, ISO time origin, max_gap (pursuit.io.input_spec)

Loading checks the whole file and reports the first problem as one line that
names the file, the line and the field (:class:`pursuit.experiment.ConfigError`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import registry
from .._validation import MAX_MEASUREMENT
from ..experiment import ConfigError, config_error, read_toml
from ..filters.fading import MAX_CONSTANT_FADING
from ..filters.gaussian import check_prior_against_noise
from ..gaussian import Gaussian
from ..models.measurement import LinearGaussian, RangeSensors, TimeOfArrival
from ..models.sensors import BearingSensors, stack
from ..registry import REQUIRED, Component, Param
from .initiate import INITIATION_PARAMS, Initiation
from .input_spec import InputSpec, build_input_spec
from .motions import IMM_FILTERS, MOTION_EXTRA_PARAMS, MOTION_TYPES, build_imm, build_motion, imm_motions

__all__ = ["Sensor", "TrackModel", "load_track_model", "build_track_model", "SENSOR_TYPES", "DEFAULT_VALID"]

SENSOR_TYPES = ("range", "toa", "bearing", "position")
DEFAULT_VALID = (-1.0e9, 1.0e9)
"""Accepted measurement values unless a sensor sets ``valid``: anything
outside is a bad record (it would only overflow the filter)."""

_SECTIONS = ("motion", "imm", "sensors", "prior", "filter", "track", "input")
_SENSOR_ID = re.compile(r"^[^\s,\"#][^,\"\r\n]*(?<!\s)$")


@dataclass(frozen=True)
class Sensor:
    """One configured sensor.

    Attributes
    ----------
    id
        The name records use in their ``sensor`` field.
    type
        ``"range"``, ``"toa"``, ``"bearing"`` or ``"position"``.
    dim
        Number of components a record of this sensor carries.
    start
        Where its block starts in the filter's measurement vector.
    valid
        ``(low, high)``: values outside are bad records.
    position
        Where the sensor is (range, toa, bearing), else None.
    c
        Signal speed (toa), else None.
    """

    id: str
    type: str
    dim: int
    start: int
    valid: tuple[float, float]
    position: tuple[float, ...] | None = None
    c: float | None = None

    @property
    def block(self) -> slice:
        """Its slice of the measurement vector."""
        return slice(self.start, self.start + self.dim)


@dataclass(frozen=True)
class TrackModel:
    """A loaded, validated MODEL.toml.

    Attributes
    ----------
    name
        Label (the file stem unless ``[track] name`` sets one).
    motion, measurement
        The models the filter uses; ``measurement`` stacks every sensor.
    prior
        Gaussian prior on the state, or None when it is to be built from
        the first measurements (``initiation``).
    prior_time
        Time the prior refers to, or None: then the first step is taken to
        come ``dt`` after the prior.
    dt
        The motion model's nominal interval (s).
    sensors
        Sensors by id, in file order.
    state_labels, position_indices, velocity_indices
        State layout.
    filter
        The filter, built through the registry.
    seed
        Seed for filters that draw random numbers (particle filters).
    path
        The file it came from.
    input
        How to read the data (columns, ISO time origin) and the largest
        believable time gap (``[input]``, :mod:`pursuit.io.input_spec`).
    initiation
        With no ``[prior]`` or ``[prior] from = "measurements"``: how the
        prior is built from the first measurements
        (:mod:`pursuit.io.initiate`); else None.
    """

    name: str
    motion: Any
    measurement: Any
    prior: Gaussian | None
    prior_time: float | None
    dt: float
    sensors: Mapping[str, Sensor]
    state_labels: tuple[str, ...]
    position_indices: tuple[int, ...]
    velocity_indices: tuple[int, ...]
    filter: Any
    seed: int
    path: Path | None = None
    input: InputSpec = InputSpec()
    initiation: Initiation | None = None

    @property
    def measurement_dim(self) -> int:
        """Length of the stacked measurement vector."""
        return sum(s.dim for s in self.sensors.values())


@dataclass(frozen=True)
class _ScenarioView:
    """What a registered filter builder may read from its ``scenario`` argument."""

    name: str
    motion: Any
    measurement: Any
    prior: Gaussian | None
    dt: float
    state_labels: tuple[str, ...]
    position_indices: tuple[int, ...]
    velocity_indices: tuple[int, ...]


# --------------------------------------------------------------------------
# parameters of each section
# --------------------------------------------------------------------------
def _one_to_three(field: str, v: int) -> int:
    if not 1 <= v <= 3:
        raise ValueError(f"{field}: must be 1, 2 or 3, got {v}")
    return v


def _positive(field: str, v: float) -> float:
    if not v > 0:
        raise ValueError(f"{field}: must be positive, got {v!r}")
    return v


def _sigma(field: str, v: Any) -> np.ndarray:
    arr = registry.Param("sigma", "vector").convert(field, v)
    if arr.size == 0 or np.any(arr <= 0):
        raise ValueError(f"{field}: noise standard deviations must be positive, got {v!r}")
    _sigma_squarable(field, arr)
    return arr


# --------------------------------------------------------------------------
# magnitudes float64 can square, invert and update with
# --------------------------------------------------------------------------
_SQUARABLE = MAX_MEASUREMENT  # 2^500: its square 2^1000 leaves a factor 2^24 below float64's overflow at 2^1024
_MIN_SIGMA = 2.0**-537  # its square 2^-1074 is the smallest positive float64; below, R = σ² is 0


def _sigma_squarable(field: str, sigma: np.ndarray) -> None:
    """σ within [2⁻⁵³⁷, 2⁵⁰⁰]: R = σ² must be a positive, finite float64 number, with room to spare above.

    σ = 1e200 overflowed R to infinity (and every record was blamed), σ = 1e-300 underflowed it
    to 0 ("Matrix is not positive definite").  2⁵⁰⁰ squared is 2¹⁰⁰⁰ (float64 overflows above
    2¹⁰²⁴), leaving a factor 2²⁴ for the sums and products of the update; 2⁻⁵³⁷ squared is
    2⁻¹⁰⁷⁴, the smallest positive float64.  A σ² that is positive but tiny is usable: a particle
    filter's weights then underflow and it recovers and flags it, and the Gaussian filters are
    held to the prior rule of :func:`_check_magnitudes`, which refuses such an R.
    """
    a = np.abs(sigma)
    out = (a > _SQUARABLE) | (a < _MIN_SIGMA)
    if np.any(out):
        bad = float(sigma.reshape(-1)[int(np.argmax(out))])
        raise ValueError(
            f"{field}: {bad:g} is outside [2^-537, 2^500] ≈ [{_MIN_SIGMA:.3g}, {_SQUARABLE:.3g}]: the filter squares the "
            "noise standard deviation, and float64 holds that square only in this range (0 below, infinity above)"
        )


def _state_squarable(field: str, values: np.ndarray) -> None:
    """Positions and the prior mean within ±2⁵⁰⁰: the filter squares them (ranges, sigma points), as it squares measurements."""
    a = np.abs(values)
    if np.any(a > _SQUARABLE):
        bad = float(values.reshape(-1)[int(np.argmax(a))])
        raise ValueError(
            f"{field}: {bad:g} is beyond ±2^500 ≈ {_SQUARABLE:.3g}, the largest magnitude the filter can square "
            "(ranges, sigma points) without overflowing float64"
        )


def _kalman_updates(filt: Any) -> bool:
    """Whether ``filt`` (or a mode of an IMM) runs a Gaussian filter's Kalman update."""
    from ..filters.gaussian import _GaussianFilter

    return isinstance(filt, _GaussianFilter) or any(_kalman_updates(f) for f in getattr(filt, "filters", ()))


def _check_magnitudes(motion: Any, measurement: Any, prior: Gaussian | None, filt: Any, sensors: Mapping[str, Sensor]) -> None:
    """Refuse a prior, a process noise or a fading factor too large for float64 to update against R (Gaussian filters).

    The prior covariance and the process noise of one nominal step are held to the rule of
    :func:`pursuit.filters.gaussian.check_prior_against_noise`: every measurement component's
    (H P Hᵀ)_ii / R_ii at most 2⁴⁸ (≈ 2.8e14, a factor 16 below 1/ε), since the first update
    leaves a covariance of about that condition number.  Every step adds Q, so a Q that breaks
    the rule breaks every update.  A constant fading factor multiplies the covariance at every
    step and compounds: measured on WSNRange (EKF, 10 runs x 100 steps) λ = 1e4 is exact and
    λ = 1e6 gives non-positive-definite covariances and negative NIS from the first steps, so
    λ ≤ 2¹³ ≈ 8.2e3 (measured, not derived).  A model without ``[prior]`` (initiation from the
    first measurements) has no state to take H at, so only its fading factor is checked here;
    the prior it builds is checked by the filter's ``init``.
    """
    order = {sid: i for i, sid in enumerate(sensors)}
    names = [""] * sum(sen.dim for sen in sensors.values())
    for sid, sen in sensors.items():
        for j in range(sen.dim):
            axis = f", component {j}" if sen.dim > 1 else ""
            names[sen.start + j] = f"sensor {sid!r} (sensors[{order[sid]}]{axis})"
    if not _kalman_updates(filt):  # particle filters do not form S = H P Hᵀ + R
        return
    _check_fading(filt)
    if prior is None:
        return
    try:
        check_prior_against_noise(measurement, prior.mean, prior.cov, names=names)
    except ValueError as e:
        raise ValueError(str(e).replace("scale the prior covariance by", "scale prior.cov by", 1)) from None
    for field, mode_motion, mode_measurement, mean in _noise_sources(motion, measurement, prior, filt):
        with np.errstate(over="ignore", invalid="ignore"):  # an overflowing Q is refused just below
            Q = np.asarray(mode_motion.cov(1, mode_motion.dt), dtype=float)
        try:
            check_prior_against_noise(mode_measurement, mean, Q, names=names)
        except ValueError as e:
            msg = str(e).split(":", 1)[1].replace("scale the prior covariance by", f"scale {field} by", 1)
            raise ValueError(f"{field}: the process noise of one {mode_motion.dt:g} s step is{msg}") from None


def _noise_sources(motion: Any, measurement: Any, prior: Gaussian, filt: Any) -> list[tuple[str, Any, Any, np.ndarray]]:
    """(field that sets Q, motion, measurement model, prior mean in that motion's state) for each motion in use.

    One for ``[motion]``; one per mode for ``[imm]``, each in its own state (the
    prior mean mapped there), so every mode's process noise is checked and named.
    """

    def param(m: Any) -> str:  # what scales Q: a Singer model's acceleration sigma, the others' q
        return "sigma" if type(m).__name__ == "Singer" else "q"

    modes, maps = getattr(filt, "filters", None), getattr(filt, "maps", None)
    if modes is None or maps is None or not all(hasattr(f, "motion") for f in modes):
        return [(f"motion.{param(motion)}", motion, measurement, prior.mean)]
    out = []
    for i, (f, m) in enumerate(zip(modes, maps)):
        mean = prior.mean if m is None else m.to_mode(prior.mean, prior.cov)[0]
        out.append((f"imm.modes[{i}].{param(f.motion)}", f.motion, f.measurement, mean))
    return out


def _check_fading(filt: Any) -> None:
    for f in getattr(filt, "filters", ()):  # an IMM's modes each take the [filter] table's fading
        _check_fading(f)
    lam = getattr(getattr(filt, "fading", None), "lam", None)
    if isinstance(lam, float) and lam > MAX_CONSTANT_FADING:
        raise ValueError(
            f"filter.fading: {lam:g} is beyond 2^13 ≈ {MAX_CONSTANT_FADING:.3g}: a constant fading factor multiplies the covariance "
            "at every step, and beyond that the updates lose positive definiteness in float64 (measured: 1e4 is exact, 1e6 is not)"
        )


def _valid(field: str, v: np.ndarray) -> tuple[float, float]:
    if v.shape != (2,) or not v[0] < v[1]:
        raise ValueError(f"{field}: expected [low, high] with low < high, got {v.tolist()}")
    return float(v[0]), float(v[1])


def _nonnegative_int(field: str, v: int) -> int:
    if v < 0:
        raise ValueError(f"{field}: must be a non-negative integer, got {v}")
    return v


def _sensor_id(field: str, v: str) -> str:
    if not _SENSOR_ID.match(v):
        raise ValueError(
            f"{field}: {v!r} is not a usable sensor id (non-empty, no commas, quotes or line breaks, "
            "no spaces at either end, not starting with '#')"
        )
    return v


MOTION_PARAMS = (
    Param("type", "str", REQUIRED, "motion model", choices=MOTION_TYPES),
    Param("ndim", "int", 2, "spatial axes (1, 2 or 3)", check=_one_to_three),
    Param("q", "float", None, "acceleration (cv, ct) or jerk (ca) noise intensity", check=_positive),
    Param("noise", "str", "discrete", "white-noise model", choices=("discrete", "continuous")),
    Param("dt", "float", 1.0, "nominal interval, s: the first step's dt when [prior] has no time", check=_positive),
    *MOTION_EXTRA_PARAMS,
)

SENSOR_PARAMS = (
    Param("id", "str", REQUIRED, "the sensor's name in the data", check=_sensor_id),
    Param("type", "str", REQUIRED, "what it measures", choices=SENSOR_TYPES),
    Param("position", "vector", None, "sensor position (range, toa, bearing)"),
    Param("sigma", "any", REQUIRED, "noise standard deviation (m, s or rad; per axis for position)", check=_sigma),
    Param("c", "float", None, "signal speed for toa, m/s (default 1500)", check=_positive),
    Param("valid", "vector", None, f"[low, high] accepted values (default {list(DEFAULT_VALID)})", check=_valid),
)

PRIOR_PARAMS = (
    Param("mean", "vector", REQUIRED, "prior mean of the state"),
    Param("cov", "matrix", REQUIRED, "prior covariance (matrix, or its diagonal)"),
    Param("time", "float", None, "time the prior refers to (default: one nominal dt before the first record)"),
)

TRACK_PARAMS = (
    Param("name", "str", "", "label for the output (default: the file name)"),
    Param("seed", "int", 0, "seed for filters that draw random numbers", check=_nonnegative_int),
)


def _resolve(table: Any, name: str, params: tuple[Param, ...]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise ValueError(f"{name}: expected a table")
    return Component("section", name, "", params, dict).resolve(table, name)


# --------------------------------------------------------------------------
# loading
# --------------------------------------------------------------------------
def load_track_model(path: str | Path) -> TrackModel:
    """Read and validate a MODEL.toml.

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
        return build_track_model(doc, name=path.stem, path=path)
    except ValueError as e:
        raise config_error(path, text, e) from None


def build_track_model(doc: Mapping[str, Any], name: str = "track", path: Path | None = None) -> TrackModel:
    """Build a :class:`TrackModel` from a parsed document; raises ``ValueError`` naming the field."""
    for key in doc:
        if key not in _SECTIONS:
            raise ValueError(f"{key}: unknown section (known: {', '.join(_SECTIONS)})")
    if "motion" in doc and "imm" in doc:
        raise ValueError("imm: give either [motion] (one model) or [imm] (several), not both")
    for key in ("motion" if "imm" not in doc else "imm", "sensors", "filter"):
        if key not in doc:
            raise ValueError(f"{key}: required section is missing")
    track = _resolve(doc.get("track", {}), "track", TRACK_PARAMS)
    if "imm" in doc:
        imm_vals, modes, motion, labels = imm_motions(doc["imm"])
    else:
        vals = _resolve(doc["motion"], "motion", MOTION_PARAMS)
        motion, labels = build_motion(vals, "motion", vals["ndim"], vals["dt"])
    n = motion.dim
    sensors, measurement = _build_sensors(doc["sensors"], motion)
    prior, prior_time, initiation = _prior_section(doc.get("prior"), n)
    view = _ScenarioView(
        name=track["name"] or name,
        motion=motion,
        measurement=measurement,
        prior=prior,
        dt=motion.dt,
        state_labels=labels,
        position_indices=motion.position_indices,
        velocity_indices=motion.velocity_indices,
    )
    filt = _build_filter(doc["filter"], view) if "imm" not in doc else _imm_filter(doc["filter"], view, imm_vals, modes, doc["sensors"])
    _check_magnitudes(motion, measurement, prior, filt, sensors)
    return TrackModel(
        name=view.name,
        motion=motion,
        measurement=measurement,
        prior=prior,
        prior_time=prior_time,
        dt=motion.dt,
        sensors=sensors,
        state_labels=labels,
        position_indices=motion.position_indices,
        velocity_indices=motion.velocity_indices,
        filter=filt,
        seed=track["seed"],
        path=path,
        input=build_input_spec(doc.get("input", {}), motion, sensors),
        initiation=initiation,
    )


def _prior_section(table: Any, n: int) -> tuple[Gaussian | None, float | None, Initiation | None]:
    """``[prior]`` with mean and cov, or (absent, or ``from = "measurements"``) an initiation rule."""
    if table is None:
        return None, None, Initiation()
    if table == {}:
        raise ValueError('prior: empty: give mean and cov, or from = "measurements" (or leave [prior] out) to start from the data')
    if isinstance(table, dict) and "from" in table:
        vals = _resolve(table, "prior", INITIATION_PARAMS)
        return None, None, Initiation(vals["velocity_sigma"], vals["acceleration_sigma"])
    vals = _resolve(table, "prior", PRIOR_PARAMS)
    return _build_prior(vals, n), vals["time"], None


def _build_prior(vals: dict[str, Any], n: int) -> Gaussian:
    mean = vals["mean"]
    if mean.shape != (n,):
        raise ValueError(f"prior.mean: expected {n} values for the state, got {mean.shape[0]}")
    _state_squarable("prior.mean", mean)
    try:
        return Gaussian(mean, vals["cov"])
    except ValueError as e:
        msg = str(e)
        raise ValueError(f"prior.{msg}" if msg.startswith(("mean", "cov")) else f"prior.cov: {msg}") from None


def _build_sensors(entries: Any, motion: Any) -> tuple[dict[str, Sensor], Any]:
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        raise ValueError("sensors: expected one or more [[sensors]] tables")
    ndim = motion.ndim
    pos_idx = motion.position_indices
    specs = []
    seen: dict[str, int] = {}
    for i, entry in enumerate(entries):
        where = f"sensors[{i}]"
        v = _resolve(entry, where, SENSOR_PARAMS)
        if v["id"] in seen:
            raise ValueError(f"{where}.id: {v['id']!r} is already used by sensors[{seen[v['id']]}]")
        seen[v["id"]] = i
        kind = v["type"]
        if kind == "position":
            if v["position"] is not None:
                raise ValueError(f"{where}.position: a 'position' sensor measures the target's position and has none of its own")
            if v["sigma"].size not in (1, ndim):
                raise ValueError(f"{where}.sigma: expected 1 or {ndim} values, got {v['sigma'].size}")
        else:
            if v["position"] is None:
                raise ValueError(f"{where}.position: required for a {kind!r} sensor")
            if v["position"].shape != (ndim,):
                raise ValueError(f"{where}.position: expected {ndim} coordinates (motion.ndim), got {v['position'].size}")
            _state_squarable(f"{where}.position", v["position"])
            if v["sigma"].size != 1:
                raise ValueError(f"{where}.sigma: expected one number for a {kind!r} sensor")
        if kind == "bearing" and ndim != 2:
            raise ValueError(f"{where}.type: bearing sensors need a 2-D motion model (motion.ndim = 2)")
        if v["c"] is not None and kind != "toa":
            raise ValueError(f"{where}.c: only a 'toa' sensor has a signal speed")
        c = 1500.0 if v["c"] is None else v["c"]
        specs.append((v, c))

    # One model per sensor type (and per signal speed for toa), in order of first appearance.
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for v, c in specs:
        groups.setdefault((v["type"], c if v["type"] == "toa" else None), []).append(v)
    parts = []
    sensors: dict[str, Sensor] = {}
    start = 0
    order = {v["id"]: i for i, (v, _) in enumerate(specs)}
    for (kind, c), members in groups.items():
        if kind == "position":
            n = motion.dim
            rows, variances = [], []
            for v in members:
                sig = np.broadcast_to(v["sigma"], (ndim,))
                H = np.zeros((ndim, n))
                H[np.arange(ndim), list(pos_idx)] = 1.0
                rows.append(H)
                variances.extend((sig**2).tolist())
            part = LinearGaussian(np.vstack(rows), np.diag(variances))
        else:
            where = f"sensors[{order[members[0]['id']]}]"
            positions = np.array([v["position"] for v in members])
            sigmas = np.array([float(v["sigma"][0]) for v in members])
            try:
                if kind == "range":
                    part = RangeSensors(positions, sigmas, pos_idx)
                elif kind == "toa":
                    part = TimeOfArrival(positions, sigmas, pos_idx, c=c)
                else:
                    part = BearingSensors(positions, sigmas, pos_idx)
            except ValueError as e:  # pragma: no cover - the checks above catch these first
                raise ValueError(f"{where}.{e}") from None
        parts.append(part)
        for v in members:
            dim = ndim if kind == "position" else 1
            valid = DEFAULT_VALID if v["valid"] is None else v["valid"]
            where_at = None if v["position"] is None else tuple(float(a) for a in v["position"])
            sensors[v["id"]] = Sensor(v["id"], kind, dim, start, valid, where_at, c if kind == "toa" else None)
            start += dim
    ordered = {v["id"]: sensors[v["id"]] for v, _ in specs}
    return ordered, stack(parts)


def _build_filter(table: Any, view: _ScenarioView) -> Any:
    if not isinstance(table, dict):
        raise ValueError("filter: expected a table")
    values = dict(table)
    kind = values.pop("type", None)
    if kind is None:
        raise ValueError("filter.type: required (see `pursuit list filters`)")
    comp = registry.get("filter", kind, "filter.type")
    params = comp.resolve(values, "filter")
    try:
        return comp.build(scenario=view, where="filter", **params)
    except (AttributeError, TypeError) as e:  # a builder that wants more than a track model gives
        raise ValueError(f"filter.type: {kind!r} cannot run on a track model ({e})") from None


def _imm_filter(table: Any, view: _ScenarioView, imm_vals: dict[str, Any], modes: list[Any], sensors: Any) -> Any:
    """``[imm]``: the ``[filter]`` type runs each mode (with the sensors read in its state); its gate and name go to the IMM."""
    if not isinstance(table, dict):
        raise ValueError("filter: expected a table")
    values = dict(table)
    kind = values.get("type")
    if kind not in IMM_FILTERS:
        raise ValueError(f"filter.type: with [imm] the filter runs each mode, so it must be one of {', '.join(IMM_FILTERS)}; got {kind!r}")
    gate = values.pop("gate", None)
    if gate is not None and (isinstance(gate, bool) or not isinstance(gate, (int, float)) or not 0.0 < gate < 1.0):
        raise ValueError(f"filter.gate: a chi-square gate probability must lie in (0, 1), got {gate!r}")
    name = values.pop("name", "")
    if not isinstance(name, str):
        raise ValueError(f"filter.name: expected a string, got {name!r}")
    types = [m["type"] for m in imm_vals["modes"]]

    def mode(motion: Any, i: int) -> Any:
        measurement = view.measurement if motion is view.motion else _build_sensors(sensors, motion)[1]
        return _build_filter({**values, "name": f"{kind.upper()} {types[i]}"}, replace(view, motion=motion, measurement=measurement))

    return build_imm(imm_vals, modes, view.motion, mode, gate, name)
