"""Compiled (numba) kernels for the ``backend="numba"`` compute backend.

Nothing here is imported unless a filter computes with numba: pursuit works
without numba installed.  :mod:`.specs` (no numba) says which models have a
compiled form and packs them into the named tuples of :mod:`.kernel_args`;
:mod:`.model_math` evaluates the models (once, for every kernel);
:mod:`.common`, :mod:`.pf_kernels`, :mod:`.cuckoo_kernels` and
:mod:`.gauss_kernels` hold the rest of the ``@njit(cache=True)`` code;
:mod:`.particle` and :mod:`.gaussian` connect them to the filters.  See
``docs/compiled-backend.md`` ("How the compiled code is laid out",
"Adding a compiled sensor").
"""
