"""One run stepped from Python by the compiled Kalman-family kernels: the online lane of ``filt.step`` (imports numba).

A user who tracks one target calls ``filt.step(state, z)`` once per
measurement.  The batched glue (:func:`pursuit._compiled.gaussian.gaussian_step`)
spends tens of microseconds per call around a kernel that takes well under
one: broadcasting and validating ``z``, rebuilding the lane-major arrays,
re-deriving the model matrices and their structure key, and assembling a
dict of a dozen transposed views.  The lane here does, per step, only what
one run needs:

* the model is packed once per filter (and per distinct ``dt``), not per step;
* the state a step returned is recognised by identity on the next step, so
  its arrays go to the kernel as they are (views of the previous output);
* ``z`` is checked by the kernel itself (its shape and dtype by Python), the
  NumPy validation runs only for a ``z`` that is not already a float vector;
* the kernel is called through the entry point of its compiled overload
  (numba's dispatcher resolves the argument types on every call, about a
  tenth of a microsecond per argument), with arguments whose types the lane
  fixes itself;
* the returned state is a :class:`pursuit.filters.GaussianState` whose mean
  and covariance are views of one freshly allocated output (so a state is
  never overwritten by a later step), and the info a :class:`StepInfo`, a
  mapping with the keys of the NumPy step that slices each value on first
  access.

A KF/EKF with a linear measurement runs the generated kernel ``one``
(:mod:`pursuit._compiled.kf_codegen`), written from the same body as the
batched ``step`` kernel, so both give the same bits; other measurements and
the UKF/CKF run the serial block kernel of the batched path on one lane,
the same kernel.  Where the lane does not apply (a moving observer, a motion
model that changes with the step, a run whose covariance needs the NumPy
repair, a batch other than ``()`` or ``(1,)``) it returns ``None`` and the
filter takes its batched compiled step.
"""

from __future__ import annotations

from collections.abc import MutableMapping
from typing import Any, Callable, Iterator

import numpy as np

from .._validation import MAX_MEASUREMENT, measurement_for_step, no_infinite_measurement, time_step
from ..filters.gating import gate_exceeded, keep_prediction
from ..filters.gaussian import GaussianState
from . import gauss_kernels as GK
from . import generated, kf_codegen
from .kernel_args import GaussOutputs, Prediction, SigmaPoints
from .specs import LINEAR, M_LINEAR

__all__ = ["StepInfo", "online_lane", "INFO_KEYS"]

INFO_KEYS = ("innovation", "S", "nis", "dof", "loglik", "fading", "faded", "repaired", "gated",
             "pred_mean", "pred_cov", "cross_cov")
"""The info keys of a compiled step, in the order of the batched path."""

_F64 = np.dtype(np.float64)
_MAX_DT_CACHE = 64  # distinct dt values whose packed model is kept


def _new_state(mean: np.ndarray, cov: np.ndarray, k: int) -> GaussianState:
    # GaussianState is a frozen dataclass without __post_init__: filling its __dict__ is what its
    # __init__ does (through object.__setattr__, field by field), at a third of the cost
    s = object.__new__(GaussianState)
    s.__dict__.update(mean=mean, cov=cov, k=k, memory=None)
    return s


class StepInfo(MutableMapping):
    """The info of one compiled step of one run: the keys of the NumPy step, each value made on first access.

    The values are views of the step's output (or small arrays made from
    it) with the shapes of the batched step for the batch ``()`` or ``(1,)``;
    each is made once and then returned again.  Setting or deleting a key
    first makes every value, after which it is an ordinary mapping.
    """

    __slots__ = ("_lane", "_out", "_batch", "_gated", "_made", "_full")

    def __init__(self, lane: Any, out: Any, batch: tuple[int, ...], gated: bool):
        self._lane = lane
        self._out = out
        self._batch = batch
        self._gated = gated
        self._made: dict[str, Any] | None = None
        self._full = False

    def __getitem__(self, key: str) -> Any:
        made = self._made
        if made is None:
            made = self._made = {}
        elif key in made:
            return made[key]
        if self._full or key not in INFO_KEYS:
            raise KeyError(key)
        value = self._lane.info_value(key, self._out, self._batch, self._gated)
        made[key] = value
        return value

    def _fill(self) -> dict[str, Any]:
        if not self._full:
            for key in INFO_KEYS:
                self[key]
            self._full = True
        return self._made

    def __setitem__(self, key: str, value: Any) -> None:
        self._fill()[key] = value

    def __delitem__(self, key: str) -> None:
        del self._fill()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._made) if self._full else iter(INFO_KEYS)

    def __len__(self) -> int:
        return len(self._made) if self._full else len(INFO_KEYS)

    def __contains__(self, key: object) -> bool:
        return key in self._made if self._full else key in INFO_KEYS

    def __repr__(self) -> str:
        return f"StepInfo({dict(self)!r})"


def _entry_point(kernel, args: tuple) -> Callable:
    """Call ``kernel`` through its dispatcher once (compiling or loading it), then return the entry point of that overload."""
    kernel(*args)
    return kernel.overloads[tuple(kernel.typeof_pyval(a) for a in args)].entry_point


def _vector(z: Any, m: int, batch: tuple[int, ...], k: int) -> np.ndarray:
    """``z`` as a writable float64 C vector ``(m,)``, through the NumPy step's checks (shape, infinities)."""
    z = measurement_for_step(z, batch, m, k)
    return np.array(z.reshape(m), dtype=float)


class _Lane:
    """What both lanes share: the run's arrays from the state, the packed model per dt, the gate."""

    def __init__(self, filt, specs):
        self.filt = filt
        self.ms, self.hs = specs
        self.m = self.hs.dim
        self.lam = float(filt.fading.lam)
        self.gate = filt.gate
        self.last: tuple | None = None  # (state returned by the last step, its x, its P) as the kernel takes them
        self.models: dict[float | None, Any] = {}

    def model(self, dt: float | None) -> Any:
        packed = self.models.get(dt)
        if packed is None:
            if len(self.models) >= _MAX_DT_CACHE:
                self.models.clear()
            F, _, _ = self.ms.arrays(1, dt)
            packed = self.models[dt] = self.pack(np.ascontiguousarray(F), np.ascontiguousarray(self.ms.cov(1, dt)))
        return packed

    def start(self, state: GaussianState) -> tuple | None:
        """``(x, P, batch)`` of a state this lane did not return, or None for a batch other than () and (1,)."""
        mean, cov = state.mean, state.cov
        n = self.n
        if mean.shape == (n,):
            batch = ()
        elif mean.shape == (1, n):
            batch = (1,)
        else:
            return None
        if cov.shape[-2:] != (n, n) or cov.size != n * n:
            return None
        return self.own(np.array(mean.reshape(n), dtype=float), np.array(cov.reshape(n, n), dtype=float)), batch

    def gated(self, nis: float, dof: int, xp, Pp, mean, cov, batch):
        """The χ² gate of the batched step (:func:`pursuit.filters.gating.apply_gate`) on one run."""
        mask = gate_exceeded(self.gate, np.array([nis]), np.array([dof], dtype=np.int64), self.m)
        if not mask[0]:
            return mean, cov, False
        n = self.n
        new_mean, new_cov = keep_prediction(mask, xp.reshape(1, n), Pp.reshape(1, n, n), mean.reshape(1, n), cov.reshape(1, n, n))
        return new_mean.reshape(batch + (n,)), new_cov.reshape(batch + (n, n)), True


class _LinearLane(_Lane):
    """KF/EKF with a linear measurement: the generated kernel ``one`` (the body of the batched ``step`` kernel)."""

    def __init__(self, filt, specs, F, Q):
        super().__init__(filt, specs)
        hs = self.hs
        self.A, self.R = np.ascontiguousarray(hs.A), np.ascontiguousarray(hs.R)
        self.key = kf_codegen.structure_key(F, Q, self.A, self.R)
        self.gen = generated.linear_kf_kernels(F, Q, self.A, self.R)
        n, m = F.shape[0], self.m
        self.n = n
        rows = kf_codegen.step_rows(n, m)
        self.rows = rows
        self.size = sum(c for _, c in rows.values())
        self.px = rows["P"][0]
        self.nis_row, self.dof_row, self.ok_row, self.ll_row = rows["nis"][0], rows["dof"][0], rows["ok"][0], rows["loglik"][0]
        self.call = None

    def pack(self, F, Q):
        if kf_codegen.structure_key(F, Q, self.A, self.R) != self.key:
            return None  # another zero pattern at this dt: the batched step picks its kernel
        return kf_codegen.one_constants(F, Q, self.A, self.R, self.lam)

    def own(self, x, P):
        return x, P

    def __call__(self, state: GaussianState, z: Any, k: int | None, dt: Any):
        k = state.k + 1 if k is None else int(k)
        last = self.last
        if last is not None and last[0] is state:
            x, P, batch = last[1], last[2], last[3]
        else:
            got = self.start(state)
            if got is None:
                return None
            (x, P), batch = got
        if dt is None:
            c = self.models.get(None)
            if c is None:
                c = self.model(None)
        else:
            c = self.model(time_step(dt, k))
        if c is None:
            return None
        m = self.m
        if not (type(z) is np.ndarray and z.dtype is _F64 and z.flags.carray and (z.shape == (m,) or (batch and z.shape == (1, m)))):
            z = _vector(z, m, batch, k)
        elif z.ndim == 2:
            z = z[0]
        n = self.n
        out = np.empty(self.size)
        call = self.call
        if call is None:
            call = self.call = _entry_point(self.gen.one, (x, P, z, c, out))
        if call(x, P, z, c, out):
            no_infinite_measurement(z, k)  # raises, naming the step
        if out[self.ok_row] == 0.0:
            return None  # S does not factor: the batched step repairs it with NumPy
        x_new = out[:n]
        P_new = out[self.px:self.px + n * n].reshape(n, n)
        gated = False
        if self.gate is not None:
            xp0 = self.rows["xp"][0]
            pp0 = self.rows["Pp"][0]
            mean, cov, gated = self.gated(out[self.nis_row], int(out[self.dof_row]), out[xp0:xp0 + n],
                                          out[pp0:pp0 + n * n], x_new, P_new, batch)
            if gated:
                x_new, P_new = np.ascontiguousarray(mean.reshape(n)), np.ascontiguousarray(cov.reshape(n, n))
        if batch:
            new = _new_state(x_new.reshape(1, n), P_new.reshape(1, n, n), k)
        else:
            new = _new_state(x_new, P_new, k)
        self.last = (new, x_new, P_new, batch)
        return new, StepInfo(self, out, batch, gated)

    def info_value(self, key: str, out: np.ndarray, batch: tuple[int, ...], gated: bool) -> np.ndarray:
        n, m = self.n, self.m
        core = {"innovation": (m,), "S": (m, m), "pred_mean": (n,), "pred_cov": (n, n), "cross_cov": (n, n)}
        name = {"innovation": "innov", "S": "S", "pred_mean": "xp", "pred_cov": "Pp", "cross_cov": "cross"}.get(key)
        if name is not None:
            first, count = self.rows[name]
            return out[first:first + count].reshape(batch + core[key])
        if key in ("nis", "loglik"):
            first = self.rows[key][0]
            return out[first:first + 1].reshape(batch)
        if key == "dof":
            return out[self.dof_row:self.dof_row + 1].astype(np.int64).reshape(batch)
        return _constant_info(key, self.lam, batch, gated)


def _constant_info(key: str, lam: float, batch: tuple[int, ...], gated: bool) -> np.ndarray:
    """The info values that do not come from the kernel's output."""
    if key == "fading":
        return np.full(batch, lam)
    if key == "faded":
        return np.full(batch, lam > 1.0)
    if key == "repaired":
        return np.zeros(batch, dtype=bool)
    if key == "gated":
        return np.full(batch, gated)
    raise KeyError(key)


class _BlockLane(_Lane):
    """Nonlinear EKF and UKF/CKF: the serial block kernel of the batched step on one lane."""

    def __init__(self, filt, specs, kind: str, n: int):
        super().__init__(filt, specs)
        self.n = n
        self.sensor = self.hs.kernel_args(1)
        if kind == "ekf":
            self.kernel, self.extra = GK.ekf_step_serial, ()
        else:
            cscale, wm, wc = filt.sigma_weights(n)
            sigma = SigmaPoints(float(cscale), np.ascontiguousarray(wm), np.ascontiguousarray(wc), wm.shape[0] % 2 == 1)
            self.kernel, self.extra = GK.sigma_step_serial, (sigma,)
        self.call = None

    def pack(self, F, Q):
        return Prediction(F, Q, self.lam)

    def own(self, x, P):
        n = self.n
        return x.reshape(n, 1), P.reshape(n, n, 1)

    def __call__(self, state: GaussianState, z: Any, k: int | None, dt: Any):
        k = state.k + 1 if k is None else int(k)
        last = self.last
        if last is not None and last[0] is state:
            x, P, batch = last[1], last[2], last[3]
        else:
            got = self.start(state)
            if got is None:
                return None
            (x, P), batch = got
        pred = self.model(None if dt is None else time_step(dt, k))
        m, n = self.m, self.n
        if not (type(z) is np.ndarray and z.dtype is _F64 and z.flags.carray and (z.shape == (m,) or (batch and z.shape == (1, m)))):
            z = _vector(z, m, batch, k)
        else:
            for v in z.tolist() if z.ndim == 1 else z[0].tolist():
                if abs(v) > MAX_MEASUREMENT:  # an infinity too; NaN (missing) compares False
                    no_infinite_measurement(z, k)  # raises, naming the step
        zl = z.reshape(m, 1)
        outs = GaussOutputs(np.empty((n, 1)), np.empty((n, n, 1)), np.empty((n, 1)), np.empty((n, n, 1)), np.empty((n, n, 1)),
                            np.empty((m, 1)), np.empty((m, m, 1)), np.empty(1), np.empty(1, dtype=np.int64), np.empty(1),
                            np.ones(1, dtype=np.bool_))
        args = ((x, P), (zl, zl == zl), pred, self.sensor) + self.extra + (outs,)
        call = self.call
        if call is None:
            call = self.call = _entry_point(self.kernel, args)
        else:
            call(*args)
        if not outs.ok[0]:
            return None
        x_new, P_new = outs.x, outs.P
        gated = False
        if self.gate is not None:
            mean, cov, gated = self.gated(outs.nis[0], int(outs.dof[0]), outs.xp, outs.Pp, x_new, P_new, batch)
            if gated:
                x_new, P_new = np.ascontiguousarray(mean.reshape(n, 1)), np.ascontiguousarray(cov.reshape(n, n, 1))
        shape = batch + (n,)
        new = _new_state(x_new.reshape(shape), P_new.reshape(shape + (n,)), k)
        self.last = (new, x_new, P_new, batch)
        return new, StepInfo(self, outs, batch, gated)

    def info_value(self, key: str, outs: GaussOutputs, batch: tuple[int, ...], gated: bool) -> np.ndarray:
        n, m = self.n, self.m
        arrays = {"innovation": (outs.innov, (m,)), "S": (outs.S, (m, m)), "pred_mean": (outs.xp, (n,)),
                  "pred_cov": (outs.Pp, (n, n)), "cross_cov": (outs.cross, (n, n)), "nis": (outs.nis, ()),
                  "dof": (outs.dof, ()), "loglik": (outs.loglik, ())}
        if key in arrays:
            a, core = arrays[key]
            return a.reshape(batch + core)
        return _constant_info(key, self.lam, batch, gated)


def online_lane(filt, specs, kind: str) -> Callable | None:
    """The online lane of a compiled KF/EKF (``kind="ekf"``) or UKF/CKF (``"sigma"``), or None where it does not apply.

    ``lane(state, z, k, dt) -> (state, info) | None``: one step of one run
    (batch ``()`` or ``(1,)``), or None when that call needs the batched
    step.  It applies to a motion model whose matrices depend on ``dt``
    alone (the built-in linear models) and a sensor that does not move.
    """
    ms, hs = specs
    if ms.kind != LINEAR or hs.moving:
        return None
    F, _, _ = ms.arrays(1, None)
    F2, _, _ = ms.arrays(2, None)
    Q = np.ascontiguousarray(ms.cov(1, None))
    if not (np.array_equal(F, F2) and np.array_equal(Q, ms.cov(2, None))):
        return None
    F = np.ascontiguousarray(F)
    if kind == "ekf" and hs.kind == M_LINEAR:
        return _LinearLane(filt, specs, F, Q)
    return _BlockLane(filt, specs, kind, F.shape[0])
