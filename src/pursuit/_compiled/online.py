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
  NumPy validation runs only for a ``z`` that is not already a float vector
  (a read-only one, such as ``np.broadcast_to``'s view, is taken as it is:
  no kernel writes ``z``);
* the kernel is called through the entry point of its compiled overload
  (numba's dispatcher resolves the argument types on every call, about a
  tenth of a microsecond per argument), with arguments whose types the lane
  fixes itself;
* the returned state is a :class:`pursuit.filters.GaussianState` whose mean
  and covariance are views of one freshly allocated output (so a state is
  never overwritten by a later step), built without its ``__init__``
  (:func:`_new_state`: the kernel's arrays need no check), and the info a
  :class:`StepInfo`, a mapping with the keys of the NumPy step that slices
  each value on first access;
* a state the lane did not return is taken only where its shapes are the
  model's (``(n,)`` and ``(n, n)``, or with a batch axis of 1); any other
  goes back to the filter's compiled step, which refuses a wrong size
  (:meth:`pursuit.filters.base.FilterBase._compiled_step`): user input is
  never trusted, only the lane's own output.

The step of a tracking loop (the state the lane returned last, no ``k`` or
``dt``, ``z`` a float64 vector of the run's shape) takes a fast path in the
step :meth:`_Lane.filter_step` makes, which skips every branch of the
general path (:meth:`_Lane.general`); both give the same bits.  That step is
also the filter's own ``step`` once the lane is made (a method bound to the
filter as an attribute, falling back on its batched step where the lane does not apply:
:meth:`pursuit.filters.base.FilterBase._take_lane_step`), so the loop's
``filt.step(state, z)`` is one Python frame; the kernel says by its return
code whether the step needs the batched path (a covariance that does not
factor), so the fast path reads nothing of the output before making the
state.

A KF/EKF with a linear measurement runs the generated kernel ``one``
(:mod:`pursuit._compiled.kf_codegen`), written from the same body as the
batched ``step`` kernel, so both give the same bits; other measurements and
the UKF/CKF run the scalar one-run kernels of
:mod:`pursuit._compiled.one_run_kernels` (``ekf_one_scalar`` /
``sigma_one_scalar``), the block kernels' arithmetic for one run in the same
order, again the same bits.  Where the lane does not apply (a moving observer, a motion
model that changes with the step, a run whose covariance needs the NumPy
repair, a batch other than ``()`` or ``(1,)``) it returns ``None`` and the
filter takes its batched compiled step.
"""

from __future__ import annotations

from collections.abc import MutableMapping
from typing import Any, Callable, Iterator

import numpy as np

from .._validation import measurement_for_step, no_infinite_measurement, time_step
from ..filters.gating import gate_exceeded, keep_prediction
from ..filters.gaussian import GaussianState
from . import one_run_kernels as OS
from . import generated, kf_codegen
from .kernel_args import Prediction, SigmaPoints
from .specs import LINEAR, M_LINEAR

__all__ = ["StepInfo", "online_lane", "INFO_KEYS"]

INFO_KEYS = ("innovation", "S", "nis", "dof", "loglik", "fading", "faded", "repaired", "gated",
             "pred_mean", "pred_cov", "cross_cov")
"""The info keys of a compiled step, in the order of the NumPy step's info."""

_F64 = np.dtype(np.float64)
_MAX_DT_CACHE = 64  # distinct dt values whose packed model is kept
_new = object.__new__


def _new_state(mean: np.ndarray, cov: np.ndarray, k: int) -> GaussianState:
    """A :class:`GaussianState` of arrays the kernel made (trusted: no validation, none is needed).

    GaussianState is a frozen dataclass without ``__post_init__``: filling its
    ``__dict__`` in field order is what its ``__init__`` does (through
    ``object.__setattr__``, field by field), at a fraction of the cost; item
    assignment also saves the keyword dict that ``update`` would build.
    """
    s = _new(GaussianState)
    d = s.__dict__
    d["mean"] = mean
    d["cov"] = cov
    d["k"] = k
    d["memory"] = None
    return s


class StepInfo(MutableMapping):
    """The info of one compiled step of one run: the keys of the NumPy step, each value made on first access.

    The values are views of the step's output (or small arrays made from
    it) with the shapes of the batched step for the batch ``()`` or ``(1,)``;
    each is made once and then returned again.  Setting or deleting a key
    first makes every value, after which it is an ordinary mapping.
    """

    __slots__ = ("_lane", "_out", "_batch", "_gated", "_made")

    def __init__(self, lane: Any, out: Any, batch: tuple[int, ...], gated: bool):
        self._lane = lane  # None once every value is made (an ordinary mapping from then on)
        self._out = out
        self._batch = batch
        self._gated = gated
        self._made: dict[str, Any] | None = None

    def __getitem__(self, key: str) -> Any:
        made = self._made
        if made is None:
            made = self._made = {}
        elif key in made:
            return made[key]
        if self._lane is None or key not in INFO_KEYS:
            raise KeyError(key)
        value = self._lane.info_value(key, self._out, self._batch, self._gated)
        made[key] = value
        return value

    def _fill(self) -> dict[str, Any]:
        if self._lane is not None:
            for key in INFO_KEYS:
                self[key]
            self._lane = None
        return self._made

    def __setitem__(self, key: str, value: Any) -> None:
        self._fill()[key] = value

    def __delitem__(self, key: str) -> None:
        del self._fill()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(INFO_KEYS) if self._lane is not None else iter(self._made)

    def __len__(self) -> int:
        return len(INFO_KEYS) if self._lane is not None else len(self._made)

    def __contains__(self, key: object) -> bool:
        return key in INFO_KEYS if self._lane is not None else key in self._made

    def __repr__(self) -> str:
        return f"StepInfo({dict(self)!r})"

    def __reduce__(self):
        # pickles as the plain dict the NumPy step returns (the lane it reads from holds compiled code)
        return (dict, (dict(self._fill()),))


def _vector(z: Any, m: int, batch: tuple[int, ...], k: int) -> np.ndarray:
    """``z`` as a writable float64 C vector ``(m,)``, through the NumPy step's checks (shape, infinities)."""
    z = measurement_for_step(z, batch, m, k)
    return np.array(z.reshape(m), dtype=float)


class _Lane:
    """One run's step: the kernel ``kernel(x (n,), P (n, n), z (m,), *model, out) -> 0 | 1 | 2`` and the Python around it.

    ``out`` is one fresh vector per step with the rows of
    :func:`pursuit._compiled.kf_codegen.step_rows`; the returned state and
    the info are views of it.  ``model`` is packed once per distinct ``dt``.
    """

    def __init__(self, filt, specs, n: int, kernel, pack: Callable):
        self.ms, self.hs = specs
        self.n, self.m = n, self.hs.dim
        self.lam = float(filt.fading.lam)
        self.gate = filt.gate
        self.kernel, self.pack = kernel, pack
        self.call: Callable | None = None
        # what the next step needs of the last one, in one tuple that a step reads and replaces as a whole (so
        # two threads stepping one filter each read a consistent one, never one run's state with another's
        # arrays): the state the last step returned, its x and P as the kernel takes them, its batch, the
        # packed model at the default dt (None: not known, or the lane does not apply at it; the fast path
        # then does not apply either), and the shapes of z, x and P with that batch
        self.chain: tuple = (None,) * 8
        self.nn = (n, n)
        self.models: dict[float | None, tuple | None] = {}
        rows = kf_codegen.step_rows(n, self.m)
        self.rows = rows
        self.size = sum(c for _, c in rows.values())
        self.px = rows["P"][0]
        self.pn = self.px + n * n
        # the fast path allocates out as rows of n (x is row 0, P rows px/n onward: step_rows puts both on a
        # multiple of n) and hands the kernel its flat view: an index and a slice then give x (n,) and P (n, n),
        # cheaper than slicing a flat vector and reshaping (a third of a microsecond of a two-microsecond step)
        assert self.px % n == 0
        self.grid = (-(-self.size // n), n)
        self.prow = slice(self.px // n, self.px // n + n)

    def model(self, dt: float | None) -> tuple | None:
        """The kernel's model arguments at ``dt`` (None: the motion model's own), or None where the lane does not apply."""
        packed = self.models.get(dt, _MISSING)
        if packed is _MISSING:
            if len(self.models) >= _MAX_DT_CACHE:
                self.models.clear()
            F, _, _ = self.ms.arrays(1, dt)
            packed = self.models[dt] = self.pack(np.ascontiguousarray(F), np.ascontiguousarray(self.ms.cov(1, dt)))
        return packed

    def start(self, state: GaussianState) -> tuple | None:
        """``(x, P, batch)`` of a state this lane did not return, or None for a batch other than () and (1,).

        None too for shapes that are not the model's: the filter's compiled
        step then refuses the state with its size named (the kernels trust
        their shapes, so a wrong size must never reach them from here).
        """
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
        return np.array(mean.reshape(n), dtype=float), np.array(cov.reshape(n, n), dtype=float), batch

    def filter_step(self, rest: Callable) -> Callable:
        """``step(filt, state, z, k=None, dt=None)``: one step by this lane, else ``rest(filt, state, z, k, dt)``.

        A function over the lane (a cell read costs what an attribute of
        ``self`` does) that the filter binds to itself as its own ``step``
        (:meth:`pursuit.filters.base.FilterBase._take_lane_step`), so a
        tracking loop's ``filt.step(state, z)`` is this one Python frame.
        ``rest`` is the filter class's step without the lane (a function,
        not bound: this holds no reference to the filter, the bound method does).
        """
        lane = self
        general, finish = self.general, self.finish

        def step(filt, state: GaussianState, z: Any, k: int | None = None, dt: Any = None):
            # the tracking loop's step first (the state this lane returned last, the model's own k and dt, z a
            # float vector whose elements are adjacent): no branch of the general path is needed
            last, x0, P0, batch, packed, zshape, bx, bP = lane.chain
            if state is last and packed is not None and k is None and dt is None and type(z) is np.ndarray \
                    and z.shape == zshape and z.dtype is _F64 and z.strides[-1] == 8:
                grid = np.empty(lane.grid)
                out = grid.ravel()  # a view: grid is C-contiguous
                if batch:
                    z = z[0]
                code = lane.call(x0, P0, z, *packed, out)  # 0; 1: z unusable; 2: a covariance does not factor
                if not code and lane.gate is None:
                    x, P = grid[0], grid[lane.prow]
                    new = _new(GaussianState)
                    d = new.__dict__  # as _new_state, inlined: a call is a tenth of this step
                    if batch:
                        d["mean"] = x.reshape(bx)
                        d["cov"] = P.reshape(bP)
                    else:
                        d["mean"] = x
                        d["cov"] = P
                    d["k"] = state.k + 1
                    d["memory"] = None
                    lane.chain = (new, x, P, batch, packed, zshape, bx, bP)
                    return new, StepInfo(lane, out, batch, False)
                if code == 1:
                    no_infinite_measurement(z, state.k + 1)  # raises, naming the step (as the general path)
                got = finish(out, code, state.k + 1, batch)
            else:
                got = general(state, z, k, dt)
            return rest(filt, state, z, k, dt) if got is None else got

        return step

    def __call__(self, state: GaussianState, z: Any, k: int | None, dt: Any):
        """One step of one run (the general path), or None where the lane does not apply (the batched step then takes it)."""
        return self.general(state, z, k, dt)

    step = __call__  # what the filter's class step calls (a method call costs less than calling the object)

    def general(self, state: GaussianState, z: Any, k: int | None, dt: Any):
        """Any step the lane takes: a state it did not return, a given ``k`` or ``dt``, any ``z``."""
        k = state.k + 1 if k is None else int(k)
        last, x, P, batch = self.chain[:4]
        if state is not last:
            got = self.start(state)
            if got is None:
                return None
            x, P, batch = got
        model = self.models.get(None) if dt is None else None
        if model is None:
            model = self.model(None if dt is None else time_step(dt, k))
            if model is None:
                return None
        m = self.m
        if not (type(z) is np.ndarray and z.dtype is _F64 and z.flags.c_contiguous
                and (z.shape == (m,) or (batch and z.shape == (1, m)))):
            z = _vector(z, m, batch, k)
        elif z.ndim == 2:
            z = z[0]
        # a read-only z (np.broadcast_to's view, a memory map) goes in as it is: no kernel writes z
        out = np.empty(self.size)
        call = self.call
        if call is None:  # the first step: through the dispatcher (compiles or loads), then its entry point
            zw = z if z.flags.writeable else z.copy()  # the overload the lane calls is the one for writable arrays
            self.kernel(x, P, zw, *model, out)
            call = self.call = self.kernel.overloads[tuple(self.kernel.typeof_pyval(a) for a in (x, P, zw, *model, out))].entry_point
        code = call(x, P, z, *model, out)
        if code == 1:
            no_infinite_measurement(z, k)  # raises, naming the step
        return self.finish(out, code, k, batch)

    def finish(self, out: np.ndarray, code: int, k: int, batch: tuple[int, ...]):
        """The state and info of a step whose kernel wrote ``out`` and returned ``code``, or None where the batched step must repair."""
        if code == 2:
            return None  # a covariance does not factor: the batched step repairs it with NumPy
        n = self.n
        x_new = out[:n]
        P_new = out[self.px:self.pn].reshape(n, n)
        gated = False
        if self.gate is not None:
            x_new, P_new, gated = self.gated(out, x_new, P_new)
        if batch:
            new = _new_state(x_new.reshape(1, n), P_new.reshape(1, n, n), k)
        else:
            new = _new_state(x_new, P_new, k)
        self.remember(new, x_new, P_new, batch)
        return new, StepInfo(self, out, batch, gated)

    def remember(self, state: GaussianState, x: np.ndarray, P: np.ndarray, batch: tuple[int, ...]) -> None:
        """Keep the state a step returned (and its arrays as the kernel takes them) for the next step's fast path."""
        # the fast path steps with the model's own dt: only once its packed model is known (and applies)
        shapes = (batch + (self.m,), batch + (self.n,), batch + self.nn)
        self.chain = (state, x, P, batch, self.models.get(None), *shapes)

    def gated(self, out: np.ndarray, x_new: np.ndarray, P_new: np.ndarray):
        """The χ² gate of the batched step (:func:`pursuit.filters.gating.apply_gate`) on one run."""
        rows, n = self.rows, self.n
        nis, dof = out[rows["nis"][0]], int(out[rows["dof"][0]])
        mask = gate_exceeded(self.gate, np.array([nis]), np.array([dof], dtype=np.int64), self.m)
        if not mask[0]:
            return x_new, P_new, False
        xp0, pp0 = rows["xp"][0], rows["Pp"][0]
        mean, cov = keep_prediction(mask, out[xp0:xp0 + n].reshape(1, n), out[pp0:pp0 + n * n].reshape(1, n, n),
                                    x_new.reshape(1, n), P_new.reshape(1, n, n))
        return np.ascontiguousarray(mean.reshape(n)), np.ascontiguousarray(cov.reshape(n, n)), True

    def info_value(self, key: str, out: np.ndarray, batch: tuple[int, ...], gated: bool) -> np.ndarray:
        """One info value of a step whose output is ``out``, shaped as the batched step's for ``batch``."""
        n, m = self.n, self.m
        name, core = _INFO_ROWS.get(key, (None, None))
        if name is not None:
            first, count = self.rows[name]
            shape = tuple(n if c == "n" else m for c in core)
            value = out[first:first + count].reshape(batch + shape)
            return value.astype(np.int64) if key == "dof" else value
        if key == "fading":
            return np.full(batch, self.lam)
        if key == "faded":
            return np.full(batch, self.lam > 1.0)
        if key == "repaired":
            return np.zeros(batch, dtype=bool)
        if key == "gated":
            return np.full(batch, gated)
        raise KeyError(key)


_MISSING = object()
#: info key -> (row name in step_rows, core shape in n and m)
_INFO_ROWS = {"innovation": ("innov", "m"), "S": ("S", "mm"), "nis": ("nis", ""), "dof": ("dof", ""),
              "loglik": ("loglik", ""), "pred_mean": ("xp", "n"), "pred_cov": ("Pp", "nn"), "cross_cov": ("cross", "nn")}


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
    n = F.shape[0]
    lam = float(filt.fading.lam)
    if kind == "ekf" and hs.kind == M_LINEAR:
        A, R = np.ascontiguousarray(hs.A), np.ascontiguousarray(hs.R)
        key = kf_codegen.structure_key(F, Q, A, R)

        def pack(F, Q):
            if kf_codegen.structure_key(F, Q, A, R) != key:
                return None  # another zero pattern at this dt: the batched step picks its kernel
            return (kf_codegen.one_constants(F, Q, A, R, lam),)

        return _Lane(filt, specs, n, generated.linear_kf_kernels(F, Q, A, R).one, pack)
    sensor = hs.kernel_args(1)
    if kind == "ekf":
        return _Lane(filt, specs, n, OS.ekf_one_scalar, lambda F, Q: (Prediction(F, Q, lam), sensor))
    cscale, wm, wc = filt.sigma_weights(n)
    sigma = SigmaPoints(float(cscale), np.ascontiguousarray(wm), np.ascontiguousarray(wc), wm.shape[0] % 2 == 1)
    return _Lane(filt, specs, n, OS.sigma_one_scalar, lambda F, Q: (Prediction(F, Q, lam), sensor, sigma))
