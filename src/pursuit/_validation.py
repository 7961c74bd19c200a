"""Input checks shared by models, filters and the config loader.

Each check raises ``ValueError`` whose message starts with the name of the
offending field, so a caller (the config loader, the CLI) can prefix the file
and show one clear line.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = [
    "as_float_array",
    "as_vector",
    "as_matrix",
    "as_covariance",
    "positive",
    "nonnegative",
    "positive_int",
    "in_range",
    "no_infinite_measurement",
    "no_infinite_measurements",
    "MAX_MEASUREMENT",
    "model_dim",
    "measurement_for_step",
    "prior_of_size",
    "state_of_size",
    "time_step",
    "MAX_TIME_STEP",
]


def as_float_array(name: str, value, ndim: int | None = None) -> np.ndarray:
    """Convert to a finite float64 array, optionally of a given number of axes."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers, got {value!r}") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name}: expected {ndim}-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinity")
    return arr


def as_vector(name: str, value, length: int | None = None) -> np.ndarray:
    """A finite 1-D float vector, optionally of a given length."""
    v = as_float_array(name, value)
    if v.ndim == 0:
        v = v.reshape(1)
    if v.ndim != 1:
        raise ValueError(f"{name}: expected a vector, got shape {v.shape}")
    if length is not None and v.shape[0] != length:
        raise ValueError(f"{name}: expected length {length}, got {v.shape[0]}")
    return v


def as_matrix(name: str, value, shape: Sequence[int | None] | None = None) -> np.ndarray:
    """A finite 2-D float matrix whose shape matches ``shape`` (None = any)."""
    A = as_float_array(name, value)
    if A.ndim != 2:
        raise ValueError(f"{name}: expected a matrix, got shape {A.shape}")
    if shape is not None:
        for want, got in zip(shape, A.shape):
            if want is not None and want != got:
                raise ValueError(f"{name}: expected shape {tuple(shape)}, got {A.shape}")
    return A


def as_covariance(name: str, value, dim: int | None = None, *, allow_singular: bool = False) -> np.ndarray:
    """A covariance matrix: scalar (times identity), vector (diagonal) or matrix.

    Checks symmetry and positive definiteness (or semidefiniteness with
    ``allow_singular``) and raises ``ValueError`` naming ``name`` otherwise.
    """
    C = as_float_array(name, value)
    if C.ndim == 0:
        if dim is None:
            raise ValueError(f"{name}: a scalar covariance needs a known dimension")
        C = C * np.eye(dim)
    elif C.ndim == 1:
        C = np.diag(C)
    if C.ndim != 2 or C.shape[0] != C.shape[1]:
        raise ValueError(f"{name}: expected a square matrix, got shape {C.shape}")
    if dim is not None and C.shape[0] != dim:
        raise ValueError(f"{name}: expected a {dim}x{dim} matrix, got {C.shape[0]}x{C.shape[1]}")
    scale = max(float(np.max(np.abs(C))), 1e-300)
    if not np.allclose(C, C.T, rtol=1e-9, atol=1e-12 * scale):
        raise ValueError(f"{name}: covariance is not symmetric")
    C = 0.5 * (C + C.T)
    w = np.linalg.eigvalsh(C)
    if allow_singular:
        if w.min() < -1e-9 * max(w.max(), 1e-300):
            raise ValueError(f"{name}: covariance is not positive semidefinite (smallest eigenvalue {w.min():.3g})")
    elif w.min() <= 0:
        raise ValueError(f"{name}: covariance is not positive definite (smallest eigenvalue {w.min():.3g})")
    return C


def positive(name: str, value) -> float:
    """A finite number > 0."""
    v = _number(name, value)
    if not v > 0:
        raise ValueError(f"{name}: must be positive, got {value!r}")
    return v


def nonnegative(name: str, value) -> float:
    """A finite number >= 0."""
    v = _number(name, value)
    if not v >= 0:
        raise ValueError(f"{name}: must be non-negative, got {value!r}")
    return v


def positive_int(name: str, value) -> int:
    """An integer >= 1 (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if value < 1:
        raise ValueError(f"{name}: must be at least 1, got {value}")
    return int(value)


def in_range(name: str, value, low: float, high: float, *, low_open: bool = False, high_open: bool = False) -> float:
    """A finite number inside [low, high], with optionally open ends."""
    v = _number(name, value)
    lo_ok = v > low if low_open else v >= low
    hi_ok = v < high if high_open else v <= high
    if not (lo_ok and hi_ok):
        lb = "(" if low_open else "["
        hb = ")" if high_open else "]"
        raise ValueError(f"{name}: must lie in {lb}{low}, {high}{hb}, got {value!r}")
    return v


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    return v


MAX_MEASUREMENT = 2.0**500
"""Largest accepted measurement magnitude (≈ 3.3e150).

The filters square measurements and what they move the state to (NIS is
νᵀ S⁻¹ ν, a range is √(Δx² + Δy²)); float64 overflows above 2¹⁰²⁴, so a
value's square must stay below that with room to spare: 2⁵⁰⁰ squared is
2¹⁰⁰⁰, leaving a factor 2²⁴ (1.7e7) for sums of squares over the
components and products with gains.  A 1e300 measurement used to turn the
EKF's estimate into NaN from that step on, with nothing flagged."""


def no_infinite_measurement(z: np.ndarray, k: int) -> None:
    """Raise ``ValueError`` naming step ``k`` if the measurement ``z`` holds an infinity or a value beyond ±:data:`MAX_MEASUREMENT`.

    A missing value is NaN and passes.
    """
    if np.isinf(z).any():
        raise ValueError(f"step {k}: measurement contains infinity (use NaN for a missing value)")
    with np.errstate(invalid="ignore"):
        huge = np.abs(z) > MAX_MEASUREMENT
    if huge.any():
        where = np.unravel_index(int(np.argmax(huge)), np.shape(z))
        value = float(np.asarray(z)[where])
        raise ValueError(
            f"step {k}: measurement z{list(map(int, where))} = {value:.6g} is beyond ±2^500 ≈ {MAX_MEASUREMENT:.3g}, "
            "the largest magnitude the filters can square without overflowing float64"
        )


def no_infinite_measurements(zs: np.ndarray) -> None:
    """:func:`no_infinite_measurement` for a whole sequence ``(K, ...)``, naming the first step (from 1) with a bad value."""
    zs = np.asarray(zs)
    if zs.size == 0:
        return
    # the common case first, in two passes with no temporary: fmax/fmin skip NaN (a missing component), so
    # both bounds hold exactly when no value is beyond ±MAX (an infinity included); all NaN falls through
    if np.fmax.reduce(zs, axis=None) <= MAX_MEASUREMENT and np.fmin.reduce(zs, axis=None) >= -MAX_MEASUREMENT:
        return
    with np.errstate(invalid="ignore"):
        bad = (np.abs(zs) > MAX_MEASUREMENT).any(axis=tuple(range(1, zs.ndim)))  # ∞ > MAX too
    if bad.any():
        first = int(np.argmax(bad))
        no_infinite_measurement(zs[first], first + 1)


def model_dim(model) -> int | None:
    """The ``dim`` a motion or measurement model declares, or ``None`` for a user's model that does not say."""
    dim = getattr(model, "dim", None)
    if isinstance(dim, (int, np.integer)) and not isinstance(dim, bool):
        return int(dim)
    return None


def measurement_for_step(z, batch: tuple[int, ...], m: int | None, k: int) -> np.ndarray:
    """The measurement ``z`` as a float array of shape ``(*batch, m)``, broadcast from fewer axes.

    ``m`` is the measurement model's dimension (``None``: any).  A size or
    shape that cannot be used raises ``ValueError`` naming step ``k``, the
    expected and the received shape, instead of a broadcasting error deep in
    a filter.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim == 0:
        z = z.reshape(1)
    want = "(" + ", ".join([*map(str, batch), "m" if m is None else str(m)]) + ")"
    if m is not None and z.shape[-1] != m:
        raise ValueError(f"step {k}: z: expected shape {want} (m = {m} components per measurement), got {z.shape}")
    if z.shape[:-1] != batch:
        try:
            z = np.broadcast_to(z, (*batch, z.shape[-1]))
        except ValueError:
            raise ValueError(f"step {k}: z: expected shape {want} for a batch of {batch}, got {z.shape}") from None
    no_infinite_measurement(z, k)
    return z


def prior_of_size(prior_dim: int, n: int | None, model) -> None:
    """Raise ``ValueError`` if a prior of ``prior_dim`` state components does not fit an ``n``-state motion model."""
    if n is not None and prior_dim != n:
        raise ValueError(
            f"prior: expected {n} state components for the {type(model).__name__} motion model (mean shape (*batch, {n}), "
            f"cov (*batch, {n}, {n})), got {prior_dim}"
        )


def state_of_size(state, n: int | None) -> None:
    """Raise ``ValueError`` if a filter state's arrays do not hold ``n`` state components.

    The compiled kernels trust their shapes: a state of another size would be
    read past its arrays and step to a silent wrong answer.  ``state`` has
    ``mean (*batch, n)`` and ``cov (*batch, n, n)``, and a particle state also
    ``particles (*batch, N, n)``; ``n`` None (a user's model that does not say) checks nothing.
    """
    if n is None:
        return
    shapes = {"mean": np.shape(state.mean), "cov": np.shape(state.cov)}
    particles = getattr(state, "particles", None)
    if particles is not None:
        shapes["particles"] = np.shape(particles)
    fits = shapes["mean"][-1:] == (n,) and shapes["cov"][-2:] == (n, n) and shapes.get("particles", (n,))[-1:] == (n,)
    if not fits:
        got = ", ".join(f"{name} {shape}" for name, shape in shapes.items())
        raise ValueError(f"state: the filter's model has {n} states, got {got}")


MAX_TIME_STEP = 2.0**200
"""Largest accepted ``dt`` (≈ 1.6e60 s).

The motion models raise ``dt`` to powers up to the fifth (the constant-
acceleration model's continuous white-noise Q has dt⁵/20); 2²⁰⁰ to the fifth
is 2¹⁰⁰⁰, leaving a factor 2²⁴ below float64's overflow at 2¹⁰²⁴.  A
``dt`` of 1e300 raised Python's ``OverflowError`` ("Numerical result out of
range") inside the models."""


def time_step(dt, k: int) -> float | None:
    """A step's ``dt`` checked: ``None`` (the model's own) or a finite number of seconds in (0, 2²⁰⁰].

    A negative, zero, NaN or infinite ``dt`` raises ``ValueError`` naming
    step ``k`` (a NaN used to surface as "covariance is not symmetric"), and
    so does one beyond :data:`MAX_TIME_STEP`.
    """
    if dt is None:
        return None
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise ValueError(f"step {k}: dt: expected a number of seconds, got {dt!r}")
    v = float(dt)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"step {k}: dt: must be a finite time step > 0 s, got {dt!r}")
    if v > MAX_TIME_STEP:
        raise ValueError(
            f"step {k}: dt: {v:g} s is beyond 2^200 ≈ {MAX_TIME_STEP:.3g} s, the longest step whose fifth power "
            "(the motion models' process noise) float64 holds"
        )
    return v
