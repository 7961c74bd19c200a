"""Compile and cache the generated kernels of :mod:`pursuit._compiled.kf_codegen` (imports numba).

A generated module is written once to a kernel directory and imported
from there, so numba's ``cache=True`` works for it as for the package's own
kernels: the second process that needs the same model structure loads the
machine code instead of compiling it (a few seconds per structure).

The directory is ``$PURSUIT_KERNEL_DIR`` if set, else
``$XDG_CACHE_HOME/pursuit/kernels`` (``~/.cache/pursuit/kernels``), else a
per-user folder under the system's temporary directory when the home
cache cannot be written.  File names carry a hash of the source, which
names the compiled helpers it inlines by a hash of theirs
(:func:`.kf_codegen.depends_digest`), so a pursuit upgrade that changes the
generator or those helpers never loads a stale module or stale machine code.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import ModuleType

import numpy as np

from . import kf_codegen

__all__ = ["kernel_dir", "load_module", "linear_kf_kernels", "run_blocks"]

ENV_VAR = "PURSUIT_KERNEL_DIR"
_modules: dict[tuple, ModuleType] = {}
_lock = threading.Lock()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
        return True
    except OSError:
        return False


def kernel_dir() -> Path:
    """The folder generated kernel modules (and numba's cache of them) are written to."""
    if os.environ.get(ENV_VAR):
        path = Path(os.environ[ENV_VAR]).expanduser()
        if not _writable(path):
            raise OSError(f"{ENV_VAR}={path}: cannot create or write to this folder")
        return path
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    path = base / "pursuit" / "kernels"
    if _writable(path):
        return path
    path = Path(tempfile.gettempdir()) / f"pursuit-kernels-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    if not _writable(path):
        raise OSError(f"no writable folder for pursuit's generated kernels (set {ENV_VAR})")
    return path


def load_module(stem: str, source: str) -> ModuleType:
    """Import ``source`` as a module from the kernel folder (written there first unless already identical)."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    name = f"{stem}_{digest}"
    path = kernel_dir() / f"{name}.py"
    if not path.is_file() or path.read_text() != source:
        # write-then-rename: a concurrent process never imports half a file; an unchanged
        # file keeps its time stamp, which numba's cache index is keyed on
        tmp = path.with_name(f".{name}.{os.getpid()}.{threading.get_ident()}.tmp")
        tmp.write_text(source)
        os.replace(tmp, path)
    modname = f"pursuit_generated_kernels.{name}"
    spec = importlib.util.spec_from_file_location(modname, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[modname] = module
    spec.loader.exec_module(module)
    return module


def linear_kf_kernels(F: np.ndarray, Q: np.ndarray, H: np.ndarray, R: np.ndarray) -> ModuleType:
    """The generated linear-KF kernels for the structure (dimensions and zero patterns) of these matrices."""
    key = kf_codegen.structure_key(F, Q, H, R)
    module = _modules.get(key)
    if module is None:
        with _lock:
            module = _modules.get(key)
            if module is None:
                n, m, pats = key
                module = load_module(f"linear_kf_n{n}_m{m}", kf_codegen.linear_kf_source(n, m, pats))
                _modules[key] = module
    return module


def run_blocks(kernel, args: tuple, runs: int, block: int, parallel: bool) -> None:
    """``kernel(*args, b0, b1)`` over the blocks of ``block`` runs, split across numba's thread count.

    The generated kernels are serial and release the GIL (``nogil=True``);
    threads of one pool run disjoint ranges of blocks.  (A ``prange`` build
    would not vectorise its body, and serial and parallel builds of one
    function would share numba's cache entry.)  Each run's result is the
    same whichever thread computes it.
    """
    global _pool, _pool_size
    import numba

    nblocks = -(-runs // block)
    threads = min(numba.get_num_threads(), nblocks) if parallel else 1
    if threads <= 1:
        kernel(*args, 0, nblocks)
        return
    with _lock:
        if _pool is None or _pool_size < threads:
            _pool_size = max(threads, numba.config.NUMBA_NUM_THREADS)
            _pool = ThreadPoolExecutor(max_workers=_pool_size, thread_name_prefix="pursuit-kernel")
        pool = _pool
    bounds = np.linspace(0, nblocks, threads + 1).round().astype(np.int64)
    futures = [pool.submit(kernel, *args, int(bounds[i]), int(bounds[i + 1])) for i in range(threads)]
    for f in futures:
        f.result()
