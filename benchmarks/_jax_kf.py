"""A JAX Kalman filter for ``bench_kf``'s KF table: ``jax.vmap`` over runs of a ``lax.scan`` filter.

Written as a competent JAX user would write it, not tuned for pursuit's
sake: one run's predict and update in ``jnp`` (the gain through
``jnp.linalg.solve``, or with ``inverse="2x2"`` the closed-form inverse of
the 2 x 2 innovation covariance), ``lax.scan`` over the steps, ``jax.vmap``
over the runs and ``jax.jit`` around the whole.  The covariance update is
the Joseph form, as pursuit's, so both do the same arithmetic work; the
filter returns the filtered means and each step's log-likelihood (pursuit
returns more: innovations, their covariances, NIS and degrees of freedom).
No missing measurements (the benchmark has none), so nothing is masked.

JAX compiles with XLA; :func:`jax_rate` compiles once on the full-size
input before timing (pursuit's numba compile is excluded likewise).  One
core: XLA's CPU thread pools are limited by ``XLA_FLAGS`` (set here before
``jax`` is imported, as :func:`configure` does) and the process is expected
to run under ``taskset -c 1``; :func:`jax_rate` reports the process CPU time
over the wall time of the timed calls, about 1 on one core.  JAX is
installed only in the benchmark environment: every function returns None
when it is not importable.
"""

from __future__ import annotations

import os
import time

import numpy as np

#: XLA's CPU backend on one thread: no Eigen thread pool, one intra-op thread.
XLA_ONE_CORE = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def configure(x64: bool = True):
    """Import JAX on one core with 64-bit floats (``x64``); the ``jax`` module, or None if not installed.

    ``XLA_FLAGS`` is read when JAX's backend starts, so it is set before the
    first import; a process that already started JAX keeps its flags.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = (flags + " " + XLA_ONE_CORE).strip()
    try:
        import jax
    except ImportError:
        return None
    jax.config.update("jax_enable_x64", x64)
    return jax


def make_filter(F, Q, H, R, inverse: str = "solve", full: bool = False):
    """Jitted ``filt(zs (T, M, m), x0 (n,), P0 (n, n)) -> (means (T, M, n), loglik (T, M), ...)``.

    ``inverse`` is ``"solve"`` (``jnp.linalg.solve``) or ``"2x2"`` (the
    closed-form inverse, m = 2 only).  ``full`` adds the other outputs of
    ``pursuit.run`` without covariances: innovations ``(T, M, m)``, their
    covariances ``(T, M, m, m)`` and the NIS ``(T, M)``.  The arrays take
    JAX's default float type (64-bit when :func:`configure` enabled it).
    """
    if inverse not in ("solve", "2x2"):
        raise ValueError(f"make_filter: inverse must be 'solve' or '2x2', got {inverse!r}")
    import jax
    import jax.numpy as jnp
    from jax import lax

    F, Q, H, R = (jnp.asarray(np.asarray(a, dtype=float)) for a in (F, Q, H, R))
    n, m = F.shape[0], H.shape[0]
    if inverse == "2x2" and m != 2:
        raise ValueError(f"make_filter: inverse='2x2' needs m = 2, got m={m}")
    eye = jnp.eye(n, dtype=F.dtype)
    log2pi = float(np.log(2.0 * np.pi))

    def step(carry, z):
        x, P = carry
        x = F @ x
        P = F @ P @ F.T + Q
        y = z - H @ x
        S = H @ P @ H.T + R
        PHt = P @ H.T
        if inverse == "solve":
            K = jnp.linalg.solve(S, PHt.T).T  # S symmetric: K = P Hᵀ S⁻¹
            q = y @ jnp.linalg.solve(S, y)
            det = jnp.linalg.det(S)
        else:
            det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
            Si = jnp.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det
            K = PHt @ Si
            q = y @ Si @ y
        x = x + K @ y
        A = eye - K @ H
        P = A @ P @ A.T + K @ R @ K.T  # Joseph form, as pursuit's
        ll = -0.5 * (q + jnp.log(det) + m * log2pi)
        return (x, P), ((x, ll, y, S, q) if full else (x, ll))

    def one_run(zs, x0, P0):
        return lax.scan(step, (x0, P0), zs)[1]

    # runs on axis 1 of the measurements and of every output: the track layout (T, M, ...)
    outs = 5 if full else 2
    return jax.jit(jax.vmap(one_run, in_axes=(1, None, None), out_axes=(1,) * outs))


def jax_rate(F, Q, H, R, zs: np.ndarray, x0: np.ndarray, P0: np.ndarray, repeats: int,
             inverse: str = "solve", x64: bool = True, full: bool = False):
    """Filter-steps per second, CPU seconds per wall second, and the means ``(T, M, n)``; None if JAX is missing.

    The first call compiles (XLA) and is not timed; each timed call ends
    with ``block_until_ready`` (JAX dispatches asynchronously).
    """
    jax = configure(x64)
    if jax is None:
        return None
    import jax.numpy as jnp
    from _timing import median_time

    dtype = np.float64 if x64 else np.float32
    filt = make_filter(*(np.asarray(a, dtype=dtype) for a in (F, Q, H, R)), inverse=inverse, full=full)
    zj, x0j, P0j = (jnp.asarray(np.asarray(a, dtype=dtype)) for a in (zs, x0, P0))
    means = filt(zj, x0j, P0j)[0]  # compile (XLA), not timed
    means.block_until_ready()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    seconds = median_time(lambda: jax.block_until_ready(filt(zj, x0j, P0j)), repeats)
    cpu_per_wall = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    steps, runs = zs.shape[0], zs.shape[1]
    return runs * steps / seconds, cpu_per_wall, np.asarray(means)
