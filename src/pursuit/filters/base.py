"""What every filter shares: its name and compute backend, the model checks, the batch, the compiled dispatch.

:class:`FilterBase` is the base of every filter family (the Gaussian filters,
the particle filters, the CS-model axis filters and the IMM).  It owns

* ``name`` and ``backend``, both keyword-only, so a constructor reads
  *models first, then the filter's parameters, then* ``name=``, ``backend=``;
* the model checks (the methods a family needs of its motion and measurement
  models, :attr:`FilterBase.motion_needs` / :attr:`FilterBase.measurement_needs`);
* the batch shape inferred from the prior (:func:`prior_batch`);
* the compute backend: resolving it, finding the compiled form of the models
  and warning (:class:`pursuit.compute.CompiledBackendWarning`) where there is
  none, the ``compiled`` property, and the dispatch to the compiled step;
* the default :meth:`FilterBase.run_sequence` (all steps in one compiled call
  where the compiled implementation has one).

A filter names its compiled implementation in one place, the class attribute
:attr:`FilterBase.compiled_path` (``"module:attribute"`` inside
:mod:`pursuit._compiled`, loaded lazily by
:func:`pursuit.compute.compiled_implementation`); the implementation is a
:class:`CompiledPath`.  Nothing in the filter layer imports the compiled side.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from types import MethodType
from typing import Any, Callable, ClassVar

import numpy as np

from .._validation import model_dim, no_infinite_measurements, state_of_size
from ..compute import compiled_implementation, compiled_specs, fallback_warning, resolve_backend
from ..gaussian import Gaussian

__all__ = ["FilterBase", "CompiledPath", "prior_batch", "as_gaussian"]

_UNSET = object()


@dataclass(frozen=True)
class CompiledPath:
    """A filter's compiled implementation: what :attr:`FilterBase.compiled_path` names.

    Attributes
    ----------
    step
        ``step(filt, specs, state, z, k, dt) -> (state, info)``: one compiled
        step, with the result layout of the filter's NumPy step; ``z`` is
        already checked and broadcast to ``(*batch, m)``.
    sequence
        ``sequence(filt, specs, state, zs, keep_cov) -> (means, covs, info) | None``:
        every step of ``zs (K, *batch, m)`` in one call (the layout of
        :func:`pursuit.run`), or ``None`` (no whole-sequence path).
    online
        ``online(filt, specs) -> lane | None``: the fast lane for one run
        stepped from Python, made once per filter, or ``None`` (none).
        ``lane(state, z, k, dt) -> (state, info) | None`` takes ``z``, ``k``
        and ``dt`` as the user passed them (it validates them itself) and
        returns None where that call needs :attr:`step` (then nothing was
        changed); its results are those of :attr:`step` for the same run,
        bit for bit, and its info may be a lazily filled mapping with the
        same keys.
    """

    step: Callable[..., tuple[Any, dict[str, np.ndarray]]]
    sequence: Callable[..., Any] | None = None
    online: Callable[..., Any] | None = None


def as_gaussian(prior: Any) -> Gaussian:
    """``prior`` as a :class:`pursuit.Gaussian` (a ``(mean, cov)`` pair is accepted)."""
    return prior if isinstance(prior, Gaussian) else Gaussian(*prior)


def prior_batch(prior: Any, batch: tuple[int, ...] = ()) -> tuple[int, ...]:
    """The batch shape of a filter's ``init``: ``batch`` if given, else the leading axes of a Gaussian prior's mean."""
    batch = tuple(batch)
    if not batch and isinstance(prior, Gaussian) and prior.mean.ndim > 1:
        batch = prior.mean.shape[:-1]
    return batch


@dataclass(frozen=True)
class FilterBase:
    """Base of every filter: ``name`` and ``backend`` (keyword-only), model checks and the compiled dispatch.

    Parameters
    ----------
    name
        Label used in results and reports (keyword only; default the
        family's short name, e.g. ``"EKF"``).
    backend
        Compute backend (keyword only): ``"numpy"``, ``"numba"`` (compiled,
        where the filter and its models have a compiled path; see
        :mod:`pursuit.compute`) or ``None`` for the process default.  Not the
        Monte Carlo engine's execution backend.

    Notes
    -----
    A subclass sets the class attributes below and may override the hooks
    :meth:`_default_name`, :meth:`_compiled_unsupported` and
    :meth:`_sequence_applies`; its ``__post_init__`` calls ``super().__post_init__()``.
    """

    name: str = field(default="", kw_only=True)
    backend: str | None = field(default=None, kw_only=True)
    _specs: Any = field(init=False, repr=False, compare=False, default=None)

    compiled_path: ClassVar[str | None] = None
    """``"module:attribute"`` of the :class:`CompiledPath` in :mod:`pursuit._compiled`; None: NumPy only."""
    motion_needs: ClassVar[tuple[str, ...]] = ()
    """Methods the motion model (attribute ``motion``) must have."""
    measurement_needs: ClassVar[tuple[str, ...]] = ()
    """Methods the measurement model (attribute ``measurement``) must have."""
    need_diagonal_noise: ClassVar[bool] = False
    """Whether the compiled path needs a diagonal measurement covariance."""
    need_linear_motion: ClassVar[bool] = False
    """Whether the compiled path needs a linear motion model."""
    compiled_step_sensor: ClassVar[bool] = False
    """Whether the compiled path packs the measurement model per step, so a moving observer (``ObserverBearings``) compiles."""
    warn_on_default_backend: ClassVar[bool] = True
    """False for families that never compile (CS, IMM): they warn only when ``backend="numba"`` is asked explicitly."""

    def __post_init__(self) -> None:
        self._check_models()
        if not self.name:
            object.__setattr__(self, "name", self._default_name())
        self._select_backend()

    # -- hooks ------------------------------------------------------------------
    def _default_name(self) -> str:
        """The label when ``name`` is not given."""
        return type(self).__name__

    def _compiled_unsupported(self) -> str | None:
        """Why this filter (not its models) has no compiled path; None when it has one."""
        return None if self.compiled_path else type(self).__name__

    def _model_specs(self) -> Any:
        """The compiled form of the models (:func:`pursuit.compute.compiled_specs`), or the reason there is none."""
        return compiled_specs(
            self.motion,
            self.measurement,
            need_diagonal=self.need_diagonal_noise,
            linear_motion=self.need_linear_motion,
            step_sensor=self.compiled_step_sensor,
        )

    def _sequence_applies(self, state: Any) -> bool:
        """Whether :meth:`run_sequence` may run from ``state`` (beyond the checks of the base)."""
        return state.k == 0

    # -- model checks -------------------------------------------------------------
    def _check_models(self) -> None:
        """TypeError naming the first method a model lacks (see :attr:`motion_needs`)."""
        for role, needs in (("motion", self.motion_needs), ("measurement", self.measurement_needs)):
            model = getattr(self, role, None) if needs else None
            for attr in needs:
                if not callable(getattr(model, attr, None)):
                    raise TypeError(f"{role} model {type(model).__name__} has no method {attr}()")

    # -- compute backend ------------------------------------------------------------
    def _select_backend(self) -> None:
        """Resolve ``backend``; for ``"numba"`` find the compiled form of the models, or warn and use NumPy."""
        explicit = self.backend is not None
        object.__setattr__(self, "_specs", None)
        if not explicit and not self.warn_on_default_backend:
            # A family with no compiled path at all computes with NumPy whatever the process default
            # says: the default (even "numba" without numba installed) is not a request to it.
            object.__setattr__(self, "backend", "numpy")
            return
        object.__setattr__(self, "backend", resolve_backend(self.backend))
        if self.backend != "numba":
            return
        reason = self._compiled_unsupported()
        if reason is None:
            specs = self._model_specs()
            if isinstance(specs, str):
                reason = specs
            else:
                object.__setattr__(self, "_specs", specs)
        if reason is not None and (explicit or self.warn_on_default_backend):
            fallback_warning(self, reason)

    @property
    def compiled(self) -> bool:
        """Whether steps run compiled (``backend="numba"`` with a supported filter and models)."""
        return self._specs is not None

    def _implementation(self) -> CompiledPath:
        """The compiled implementation (imports numba on first use); only while :attr:`compiled`."""
        return compiled_implementation(self.compiled_path)

    def _compiled_step(self, state: Any, z: np.ndarray, k: int, dt: float | None) -> tuple[Any, dict[str, np.ndarray]]:
        """One step by the compiled implementation (``z`` checked and broadcast; the state's size checked here).

        Raises
        ------
        ValueError
            A state whose size is not the motion model's (the kernels would
            read past its arrays and step silently).
        """
        state_of_size(state, self._state_dim())
        return self._implementation().step(self, self._specs, state, z, k, dt)

    def _state_dim(self) -> int | None:
        """The number of state components this filter's state holds (None: not known).

        The motion model's ``dim``; a filter whose state is not a motion
        model's (the nonlinear CS filter's, ``3 * axes``) says its own.
        """
        return model_dim(getattr(self, "motion", None))

    def _online_step(self, state: Any, z: Any, k: Any, dt: Any) -> tuple[Any, Any] | None:
        """One step of one run by the compiled implementation's online lane, or None where it does not apply.

        Called by a filter's ``step`` before any validation (the lane checks
        ``z``, ``k`` and ``dt`` itself); only while :attr:`compiled`.  The lane
        is made on the first call and kept with the filter (not pickled).
        """
        lane = self.__dict__.get("_online_lane", _UNSET)
        if lane is _UNSET:
            factory = self._implementation().online if self._step_is_own() else None
            lane = None if factory is None else factory(self, self._specs)
            object.__setattr__(self, "_online_lane", lane)
            if lane is not None:
                self._take_lane_step(lane)
        return None if lane is None else lane(state, z, k, dt)

    def _take_lane_step(self, lane: Any) -> None:
        """Bind the lane's step (falling back on :meth:`_step_without_lane`) to this filter as its own ``step``.

        An instance attribute, a bound method found before the class's: a
        tracking loop's ``filt.step(state, z)`` then runs the lane's Python
        frame only, not the class step's too (about a tenth of a compiled KF
        step).  It has the class step's name, docstring and signature, and
        pickles as the class step does (by name: the unpickled filter makes
        its own lane); copies and pickles of the filter leave it out
        (:meth:`__getstate__`).  A patch of the class's ``step`` (``mock``)
        does not reach a filter that has stepped; the bound method refers to
        its filter, a cycle that Python's cyclic garbage collector frees.
        """
        rest = getattr(type(self), "_step_without_lane", None)
        if rest is None or not hasattr(lane, "filter_step"):
            return  # a filter without the split of its step keeps calling the lane from its class step
        cls_step = type(self).step
        step = lane.filter_step(rest)
        step.__name__, step.__qualname__, step.__doc__ = cls_step.__name__, cls_step.__qualname__, cls_step.__doc__
        step.__signature__ = inspect.signature(cls_step)
        object.__setattr__(self, "step", MethodType(step, self))

    def __getstate__(self) -> dict[str, Any]:
        # the online lane holds compiled entry points and the last state, made again where unpickled
        state = dict(self.__dict__)
        state.pop("_online_lane", None)
        state.pop("step", None)  # the lane's step (_take_lane_step): made again with the lane
        for name in [name for name in state if name.startswith("_one_run_")]:
            del state[name]  # the one-run step's caches of model matrices: read again from the unpickled models
        return state

    def _step_is_own(self) -> bool:
        """False when a subclass overrides ``step`` of the class that names the compiled path (it runs from Python)."""
        owner = next((c for c in type(self).__mro__ if "compiled_path" in vars(c)), None)
        return owner is not None and type(self).step is owner.step

    # -- whole sequences -------------------------------------------------------------
    def run_sequence(
        self, state: Any, zs: np.ndarray, *, keep_cov: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None, dict[str, np.ndarray]] | None:
        """All steps of ``zs (K, *batch, m)`` in one compiled call, or ``None`` where that does not apply.

        :func:`pursuit.run` asks this first.  It applies to a compiled filter
        whose implementation has a whole-sequence path (the KF/EKF/UKF/CKF
        with a time-invariant linear motion model and no gate; the bootstrap PF with
        a :class:`pursuit.RunStreams` of PCG64 streams), one batch axis (the
        UKF/CKF also batch ``()``), from
        a state at step 0; it gives the same bits as calling ``step`` K
        times.  Returns ``(means, covs, info)`` with time first (``covs`` is
        ``None`` unless ``keep_cov``).  A subclass that overrides ``step`` is
        stepped from Python.
        """
        if self._specs is None or not self._step_is_own():
            return None
        sequence = self._implementation().sequence
        if sequence is None or not self._sequence_applies(state):
            return None
        zs = np.asarray(zs, dtype=float)
        if zs.ndim != 2 + len(state.batch) or zs.shape[1:-1] != state.batch or zs.shape[-1] != self._specs[1].dim:
            return None  # the step path broadcasts or reports the shape; the implementation checks the batch
        no_infinite_measurements(zs)
        return sequence(self, self._specs, state, zs, keep_cov)
